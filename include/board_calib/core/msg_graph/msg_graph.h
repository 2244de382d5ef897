// MSG-Cal multi-sensor graph: calibrates any number of cameras and
// LiDARs jointly from board poses seen by several sensors. ROS-free.
//
// Nodes: every sensor's pose reference_T_sensor (one sensor fixed, the reference). Edges:
//  * plane to plane, for every pair of sensors that saw the same board pose:
//      r_n = (R_a n_a - R_b n_b) / sigma_n_ab                        (3, whitened)
//      r_d = gap between the two mapped planes at the midpoint of the sensors' board points
//            (LiDAR: board points' centroid; camera: PnP data centre) / sigma_d_ab
//    (both planes mapped into the reference frame must coincide; the offsets are compared at
//    the board, not at the origin, where each plane's normal error would be multiplied by the
//    board distance; sigma_ab^2 = sigma_a^2 + sigma_b^2 from the per-sensor confidences);
//  * camera <-> camera on individual pattern corners (AprilTag / checkerboard): every board pose
//    seen with corners by two or more cameras gets a free board pose reference_T_board, and each
//    camera's corners are reprojected through it (a bundle adjustment; triangulation-free and
//    statistically sound, unlike transferring one camera's noisy PnP pose into the other). For
//    such poses the camera<->camera plane terms are dropped (they come from the same corners);
//  * optional PBPC line terms for LiDAR <-> camera pairs: LiDAR edge points against the plane
//    back-projected from the matching image line (edges re-associated by projection).
// Initialisation: pairwise plane-to-plane solutions (as solvePlaneToPlane, with the offsets
// compared at the boards and the views weighted by distance) with per-pair gating,
// then a maximum spanning tree over the sensor graph (most shared views first) from the
// reference sensor; a disconnected graph is refused with the sensors that cannot be reached.
// Robustness: squared-loss plane stage first (wide basin), then a robust loss on every whitened
// term, per-sensor noise sigmas (given, or estimated from the pairwise residuals: a noisy
// sensor is down-weighted instead of pulling every pair), and outlier-observation rejection.
//
// Covariance convention: as solvers.h (rotation x y z [rad] as a left perturbation expressed in
// the reference frame, then translation [m]).
#pragma once

#include <board_calib/core/features.h>
#include <board_calib/core/result_io.h>
#include <board_calib/core/solvers/solvers.h>
#include <board_calib/core/types.h>

#include <map>
#include <optional>
#include <string>
#include <vector>

namespace board_calib {
namespace multi_sensor {

enum class SensorKind { kCamera, kLidar };
const char* sensorKindName(SensorKind kind);  // "camera", "lidar"

/// One sensor of the rig and its confidence. Sigmas <= 0 take the defaults of MsgGraphOptions
/// for the sensor's kind.
struct SensorSpec {
  std::string frame;
  SensorKind kind = SensorKind::kCamera;
  double normal_sigma_deg = 0.0;  ///< deg, RMS angle of this sensor's board-plane normal error
  double offset_sigma_m = 0.0;    ///< m, 1 sigma of its board-plane offset at the board
  double pixel_sigma_px = 0.0;    ///< px, cameras: 1 sigma of a pattern corner
  double edge_sigma_m = 0.0;      ///< m, LiDARs: 1 sigma of an edge point across the edge
};

/// One board pose as seen by the sensors that saw it, keyed by sensor index. Features whose
/// `found` is false are ignored (with a note).
struct BoardPoseObservation {
  int id = 0;
  std::map<int, LidarBoardFeatures> lidars;
  std::map<int, CameraBoardFeatures> cameras;
};

struct MsgProblem {
  std::vector<SensorSpec> sensors;
  int reference_sensor = 0;  ///< its pose is the identity
  std::vector<BoardPoseObservation> poses;
};

struct MsgGraphOptions {
  // Default confidences per sensor kind (SensorSpec values <= 0 take these).
  double camera_normal_sigma_deg = 0.3;  ///< deg
  double camera_offset_sigma_m = 0.005;  ///< m
  double camera_pixel_sigma_px = 0.5;    ///< px
  double lidar_normal_sigma_deg = 0.5;   ///< deg
  double lidar_offset_sigma_m = 0.005;   ///< m
  double lidar_edge_sigma_m = 0.02;      ///< m (edge points lie up to one step inside the edge)
  /// Re-estimate every sensor's plane sigmas from the pairwise residuals (three-cornered hat:
  /// var_ab = var_a + var_b, least squares over all pairs). Needs a cycle in the graph.
  bool estimate_sensor_noise = true;
  /// Estimated sigmas are kept within [given / ratio, given * ratio].
  double noise_estimate_max_ratio = 10.0;

  /// Inflate each plane-pair sigma by sqrt(K / 2) on a board pose seen by K sensors, so the
  /// K(K-1)/2 pair terms carry no more weight than K - 1 independent ones would. On: neutral
  /// on the clean rig, -12% worst-pair max translation with a noisy sensor (BENCHMARKS.md).
  bool balance_plane_pairs = true;
  bool use_corner_terms = true;  ///< camera<->camera terms on shared pattern corners
  int min_shared_corners = 6;    ///< per camera and board pose, to add corner terms
  /// PBPC line terms for LiDAR<->camera pairs (the paper's proposed future work). On by
  /// default: on the simulated rig they cut the worst-pair translation error by 17-38% (mean and
  /// max, with and without a noisy sensor) for about twice the solve time (docs/BENCHMARKS.md).
  bool use_line_terms = true;
  int min_edge_points = 3;  ///< per edge, for a line term

  RobustLoss loss = RobustLoss::kHuber;
  double loss_scale_sigma = 2.0;  ///< robust loss scale, in whitened units (sigmas)
  int min_shared_views = 3;       ///< board poses a pair needs to form a graph edge
  /// Observations (sensor, pose) whose median whitened residual exceeds this are rejected;
  /// pairwise correspondences likewise before the pairwise re-solve.
  double outlier_gate_sigma = 5.0;
  int outlier_rounds = 2;  ///< reject-and-resolve rounds (0 disables rejection)

  int max_iterations = 100;  ///< per Ceres solve
  double function_tolerance = 1e-10;
  double gradient_tolerance = 1e-12;
  double parameter_tolerance = 1e-10;
  int num_threads = 1;
  double min_normal_spread_deg = 2.0;  ///< degeneracy guard of the pairwise solves
  bool compute_covariance = true;

  std::string validate() const;
};

/// A pairwise plane-to-plane solution between sensors a < b.
struct PairLink {
  int a = 0, b = 0;
  int shared_views = 0;  ///< board poses both saw with a valid plane
  int views_used = 0;    ///< after gating
  bool success = false;
  std::string reason;
  Eigen::Isometry3d a_T_b = Eigen::Isometry3d::Identity();
  double normal_rms_deg = 0.0;  ///< pairwise residuals
  double offset_rms_mm = 0.0;
  bool in_spanning_tree = false;
  /// Pairwise estimate against the graph's a_T_b (filled after the global solve).
  double graph_rotation_diff_deg = 0.0;
  double graph_translation_diff_mm = 0.0;
};

/// Error around one cycle of pairwise estimates: T_ab * T_bc * T_ca should be the identity.
struct LoopError {
  std::vector<int> cycle;  ///< sensor indices
  double rotation_deg = 0.0;
  double translation_mm = 0.0;
};

struct SensorEstimate {
  std::string frame;
  SensorKind kind = SensorKind::kCamera;
  Eigen::Isometry3d reference_T_sensor = Eigen::Isometry3d::Identity();
  Eigen::Isometry3d initial_reference_T_sensor = Eigen::Isometry3d::Identity();
  Matrix6d covariance = Matrix6d::Zero();  ///< zero for the reference sensor
  PoseStddev stddev;
  double normal_sigma_deg = 0.0;  ///< used in the graph (given or estimated)
  double offset_sigma_m = 0.0;
  double pixel_sigma_px = 0.0;
  double edge_sigma_m = 0.0;
  int observations = 0;           ///< board poses with a usable observation
  int observations_rejected = 0;  ///< by outlier rejection
};

struct RejectedObservation {
  int pose_id = 0;
  int sensor = 0;
  double median_whitened = 0.0;  ///< sigmas
};

/// Residual statistics of the final graph (raw units).
struct GraphResiduals {
  int plane_terms = 0;
  double normal_rms_deg = 0.0;
  double offset_rms_mm = 0.0;
  int corner_terms = 0;
  double corner_rms_px = 0.0;
  int line_terms = 0;
  double line_rms_mm = 0.0;
};

/// One camera <- LiDAR pair of the graph: camera_T_lidar = reference_T_camera^-1 *
/// reference_T_lidar.
struct PairEstimate {
  int camera = 0;  ///< sensor indices
  int lidar = 0;
  Eigen::Isometry3d camera_T_lidar = Eigen::Isometry3d::Identity();
  /// solvers.h convention (left rotation perturbation expressed in the camera frame, then the
  /// translation), propagated to first order from both sensors' poses including their
  /// cross-covariance. Valid only when has_covariance.
  Matrix6d covariance = Matrix6d::Zero();
  PoseStddev stddev;
  bool has_covariance = false;
};

/// A sensor the graph could not place: cut off from the reference, or left with too few poses.
struct UnplacedSensor {
  int sensor = 0;
  std::string reason;  ///< its own links' or poses' shortfall
};

struct MsgSolution {
  bool success = false;
  std::string reason;
  /// When the solve failed for want of some sensors' data: those sensors (the others may be
  /// solvable without them).
  std::vector<UnplacedSensor> unplaced;
  int reference_sensor = 0;
  std::vector<SensorEstimate> sensors;
  /// Joint covariance of every sensor pose (6n x 6n, sensor s at rows/columns 6s..6s+5, header
  /// convention; zero for the reference); empty when not computed or not available.
  Eigen::MatrixXd pose_covariance;
  std::vector<PairEstimate> pairs;  ///< every camera <- LiDAR pair (camera-major order)
  std::vector<PairLink> links;      ///< every sensor pair (a < b); unusable ones carry a reason
  std::vector<LoopError> loops;     ///< every triangle of successful pairwise links
  double loop_rotation_max_deg = 0.0;
  double loop_translation_max_mm = 0.0;
  std::vector<RejectedObservation> rejected;
  GraphResiduals residuals;
  int poses_used = 0;
  double final_cost = 0.0;
  int iterations = 0;  ///< summed over the solves
  std::string termination;
  bool used_pairwise_init = true;
  std::vector<std::string> notes;
  double solve_time_ms = 0.0;  ///< whole call (init, solves, covariance)
  double graph_time_ms = 0.0;  ///< the global Ceres solves only
};

/// Solves the graph. Without `initial_reference_T_sensor` (one pose per sensor) the pairwise +
/// spanning-tree initialisation is used. Never throws on bad input: success = false + reason.
MsgSolution solveMsgGraph(
    const MsgProblem& problem, const MsgGraphOptions& options,
    const std::optional<std::vector<Eigen::Isometry3d>>& initial_reference_T_sensor = std::nullopt);

/// a_T_b from a solution (p_a = a_T_b * p_b).
Expected<Eigen::Isometry3d> sensorTSensor(const MsgSolution& solution, int a, int b);

/// Covariance of a_T_b (solvers.h convention: left rotation perturbation expressed in frame a,
/// then the translation) from the joint pose covariance, to first order and with the cross
/// terms; fails when the solution carries no covariance.
Expected<Matrix6d> relativeCovariance(const MsgSolution& solution, int a, int b);

/// The reference paper's factory-stereo check: T_c1_c2 from the graph against a known one.
struct StereoConsistency {
  double rotation_deg = 0.0;
  double translation_mm = 0.0;
};
Expected<StereoConsistency> stereoConsistency(const MsgSolution& solution, int camera1, int camera2,
                                              const Eigen::Isometry3d& known_camera1_T_camera2);

/// The views of one camera <- LiDAR pair: the board poses where both found the board, view id =
/// pose id (what the pair solvers, the verdict and the report judge the pair on).
std::vector<View> pairViews(const MsgProblem& problem, int camera, int lidar);

/// Mean line reprojection error (px) of one camera<->LiDAR pair over the board poses both saw
/// with edges (edges paired as by the solvers: core/common/edge_association.h); nullopt when
/// none is usable.
std::optional<double> pairMlrePx(const MsgProblem& problem, int camera, int lidar,
                                 const Eigen::Isometry3d& camera_T_lidar);

/// The result file: `sensors` (every pose in the reference frame), `pairs`
/// (solution.pairs in the same order, each with its 1 sigma when the covariance is available),
/// the single-pair block from the first pair, quality figures
/// (loop consistency, residuals) and notes.
ResultFile msgResultFile(const MsgProblem& problem, const MsgSolution& solution);

}  // namespace multi_sensor
}  // namespace board_calib
