// LiDAR <-> camera extrinsic solvers of the reference paper, ROS-free:
//  * PPC-Cal  (point to plane):  r = n_i . (R P_im + t) - d_i, view weight 1/p_i.
//  * PBPC-Cal (point to back-projected plane): r = N_ij . (R Q_ijn + t), N_ij = K^T l_ij
//    normalised so r is in metres, edge weight 1/q_ij; combined with the PPC terms.
//  * MSG-Cal pairwise (plane to plane): n_a - R_ab n_b = 0 and n_a . t_ab + d_b - d_a = 0 for
//    any two sensors that saw the same board pose (camera-camera, LiDAR-LiDAR, LiDAR-camera).
// A closed-form initialiser (normals by SVD, offsets and lines by linear least squares) is used
// when no guess is given. Every result carries quality figures and, on failure, a reason.
//
// Covariance convention (everywhere in this header): 6x6, order (rotation x y z [rad],
// translation x y z [m]); the rotation is a LEFT perturbation of the estimate,
// R = Exp(delta) * R_hat, expressed in the target frame (camera for camera_T_lidar, a for a_T_b);
// the translation perturbation is additive, t = t_hat + delta_t.
#pragma once

#include <board_calib/core/features.h>
#include <board_calib/core/result_io.h>
#include <board_calib/core/types.h>

#include <optional>
#include <string>
#include <vector>

namespace board_calib {

using Matrix6d = Eigen::Matrix<double, 6, 6>;
using Vector6d = Eigen::Matrix<double, 6, 1>;

enum class Method { kPpc, kPbpc, kMsgPair };
/// "ppc", "pbpc", "msg".
const char* methodName(Method method);
/// Accepts "ppc", "pbpc", "msg" (also "msg_pair"), case-insensitive.
Expected<Method> parseMethod(const std::string& name);

enum class RobustLoss { kNone, kHuber, kCauchy, kTukey };
/// "none", "huber", "cauchy", "tukey".
const char* robustLossName(RobustLoss loss);
Expected<RobustLoss> parseRobustLoss(const std::string& name);

/// How PBPC is run: as the paper does (PPC, then the line terms alone, then jointly), or as one
/// joint solve of plane and line terms from the initial guess. Measured (docs/BENCHMARKS.md):
/// equal accuracy from the closed-form start, but from random starts (90 deg, 50 cm) the joint
/// solve converged in 58 % and the sequential one in 100 %, so sequential is the default.
enum class PbpcSchedule { kJoint, kSequential };
const char* pbpcScheduleName(PbpcSchedule schedule);
Expected<PbpcSchedule> parsePbpcSchedule(const std::string& name);

struct SolverOptions {
  RobustLoss loss = RobustLoss::kHuber;
  double loss_scale_m = 0.05;         ///< m, scale of the robust loss on point residuals
  int max_iterations = 100;           ///< per Ceres solve
  double function_tolerance = 1e-10;  ///< relative cost change to stop
  double gradient_tolerance = 1e-12;
  double parameter_tolerance = 1e-10;
  int num_threads = 1;
  /// Solve first with a squared loss, then with the robust loss from there: widens the basin
  /// of convergence of redescending losses (Cauchy, Tukey) from far-off guesses.
  bool warm_start_unrobust = true;

  /// PPC: after the paper's solve (every point weighted 1/p_i), weight each view's plane offset
  /// and its two tilts by the camera plane error estimated from the residuals (variance
  /// components; generalised least squares), either the same for every view or growing as a
  /// PnP's with the distance, whichever is more likely. The points of a view share its camera
  /// plane error, which the per-point weighting treats as independent noise, so it under-weights
  /// the tilts and the near views (measured over 10 seeds, PnP planes: worst error 0.372 deg /
  /// 10.6 mm -> 0.196 deg / 5.2 mm; docs/BENCHMARKS.md). false: the paper's weighting only.
  bool ppc_plane_error_model = true;

  PbpcSchedule pbpc_schedule = PbpcSchedule::kSequential;
  /// PBPC: relative weight of the line (edge) terms against the plane terms.
  double pbpc_line_weight = 1.0;
  /// PBPC: include the point-to-plane terms in the final solve (the paper does).
  bool pbpc_use_plane_terms = true;
  /// PBPC: estimate one global factor s on the camera plane offsets (d_i -> s d_i) jointly, to
  /// absorb a board-size mismatch (the camera plane from PnP of the corners scales with the
  /// declared board size; the edge terms do not). Reported in the notes when it differs from 1.
  bool estimate_plane_scale = true;
  double plane_scale_note_threshold = 0.01;  ///< note the scale when |s - 1| exceeds this
  /// Re-assign LiDAR edge point sets to image lines by projection with the current estimate
  /// (fixes views where the two sensors name the edges differently).
  bool edge_reassociation = true;
  /// LiDAR horizontal step (deg) for the edge-bias correction below; 0 estimates it from the
  /// azimuth gaps of the board points along each scan line.
  double lidar_horizontal_resolution_deg = 0.0;
  /// PBPC: shift each LiDAR edge point outward along its scan line by this many horizontal
  /// steps (per-scan-line extremes lie up to one step inside the true edge: 0.5 removes the
  /// mean bias); 0 disables it.
  double edge_outward_shift_steps = 0.5;
  /// PBPC: the edge points' net sampling bias is known only to within this many horizontal
  /// steps (how far a beam's footprint blooms past the half-step inset depends on the beam and
  /// the board): the result is solved again with the shift moved by this much and the change
  /// enters its 1 sigma (CalibrationSolution::edge_bias_covariance); 0: not included.
  double edge_bias_range_steps = 0.0;
  /// PPC: solve the views once more with one free scale on the camera plane offsets (as PBPC
  /// does) to measure whether the LiDAR agrees with the declared board size
  /// (CalibrationSolution::declared_scale); the verdict judges it. Needs compute_covariance.
  bool check_declared_scale = true;
  /// With compute_covariance off, still solve that scale (without its 1 sigma): the
  /// cross-validation's folds measure its spread (DeclaredScaleCheck::estimated).
  bool declared_scale_without_covariance = false;

  /// MSG pairwise: 1-sigma of a plane normal (deg) and of a plane offset (m); the normal
  /// residual is whitened into metres-equivalent so one loss scale applies to both.
  double msg_normal_sigma_deg = 0.5;
  double msg_offset_sigma_m = 0.01;

  /// Degeneracy: the smallest singular value of the stacked unit normals, divided by
  /// sqrt(views), must exceed sin(this angle). Guards "all normals parallel / coplanar".
  double min_normal_spread_deg = 2.0;
  bool compute_covariance = true;
  /// Observability: well conditioned when the weakest direction's 1 sigma is below this
  /// (m for translation, rad at a 1 m lever arm for rotation).
  double observability_max_stddev = 0.02;

  std::string validate() const;
};

/// Settings for features from real spinning LiDARs (and from the simulator, which models beam
/// divergence), used by calibrate_bag and the calibrator nodelet. Two differences from the
/// defaults, which suit the idealised synthetic features: no edge shift, because per-scan-line
/// extremes bloom outward by about half the beam divergence, which cancels their half-step
/// inset (measured: simulator 1.4 mm vs 11 mm translation error with a 0.5-step shift; the real
/// OS1-64 board measures 3 % larger than declared); and a redescending Tukey loss at 2 cm,
/// because real edge and board points carry gross outliers (hands, mixed returns) that a Huber
/// loss only down-weights (real basler_os1_plain: independent MLRE 5.9 px vs 6.6 px).
SolverOptions realLidarSolverOptions();

/// 1 sigma per axis of a covariance in the convention above (rotation in deg, translation in m).
PoseStddev stddevFromCovariance(const Matrix6d& covariance);

/// `a` relative to `reference` in the covariance convention above (left rotation vector in the
/// target frame, translation difference).
Vector6d poseDelta(const Eigen::Isometry3d& a, const Eigen::Isometry3d& reference);

/// Residual statistics of one group of residuals (metres).
struct ResidualStats {
  int count = 0;
  double rms_m = 0.0;
  double mean_abs_m = 0.0;
  double max_abs_m = 0.0;
};
/// Count, RMS, mean and max magnitude of signed distances (m); zeros for none.
ResidualStats residualStats(const std::vector<double>& residuals);

struct EdgeResidual {
  bool used = false;              ///< both sides valid and the edge contributed line terms
  int lidar_edge = -1;            ///< LiDAR edge index matched to this image edge (re-association)
  ResidualStats distance;         ///< point to back-projected plane, m
  std::optional<double> mlre_px;  ///< mean perpendicular pixel distance to the image line
};

struct ViewResidual {
  int view_id = 0;
  bool used = false;
  std::string reason;                         ///< why the view was skipped, or empty
  ResidualStats plane;                        ///< LiDAR board points to the camera plane, m
  std::array<EdgeResidual, kNumEdges> edges;  ///< indexed by the image edge
  std::optional<double> mlre_px;              ///< over all edges of the view
};

struct Observability {
  double min_eigenvalue = 0.0;  ///< of the information matrix (inverse covariance), SI units
  double max_eigenvalue = 0.0;
  double condition_number = 0.0;
  Vector6d weakest_direction = Vector6d::Zero();  ///< unit eigenvector, covariance order
  std::string weakest_description;                ///< e.g. "translation along camera z"
  bool well_conditioned = false;
};

/// PPC: the camera planes' depth comes from the declared board size. The same views solved with
/// one free scale s on the camera plane offsets (d -> s d) say what the LiDAR measures.
struct DeclaredScaleCheck {
  bool checked = false;    ///< scale, stddev and shift solved
  bool estimated = false;  ///< the scale solved (checked, or a fold's scale alone)
  double scale = 1.0;      ///< LiDAR distance / camera distance of the boards
  double stddev = 0.0;     ///< 1 sigma of scale (cluster-robust)
  /// How far the result moves with the scale applied (poseDelta: rotation vector rad, m).
  Vector6d shift = Vector6d::Zero();
};

/// What the depth scale's 1 sigma adds to a result that takes the declared board size as exact
/// (PPC, MSG pairwise, the MSG graph): its move per unit of scale, shift / (s - 1), times the
/// scale's 1 sigma. A size off by less than the verdict names then stays inside the 1 sigma.
/// Zero unless checked, and when the scale is too close to 1 (within 0.1 sigma) to give the slope.
Matrix6d declaredScaleUncertainty(const DeclaredScaleCheck& check);

struct CalibrationSolution {
  bool success = false;
  std::string reason;  ///< why it failed, empty on success
  Method method = Method::kPbpc;
  Eigen::Isometry3d camera_T_lidar = Eigen::Isometry3d::Identity();  ///< p_camera = T * p_lidar
  Eigen::Isometry3d initial_guess = Eigen::Isometry3d::Identity();   ///< where Ceres started
  bool used_closed_form_init = false;
  int views_used = 0;
  double final_cost = 0.0;        ///< Ceres cost of the last solve
  int iterations = 0;             ///< summed over the solves
  std::string termination;        ///< Ceres termination of the last solve
  std::optional<double> mlre_px;  ///< over every used edge, undistorted px
  double plane_rms_mm = 0.0;      ///< RMS point-to-camera-plane distance of every used board point
  double line_rms_mm = 0.0;  ///< RMS LiDAR edge point to back-projected image line plane distance
  double plane_scale = 1.0;  ///< estimated camera plane offset factor (1 when not estimated)
  Matrix6d covariance = Matrix6d::Zero();  ///< see the convention at the top
  /// PBPC: what the LiDAR edge sampling bias may add (half the change over the bias range, as a
  /// 1 sigma along it); not in `covariance`, the verdict adds it after any inflation.
  Matrix6d edge_bias_covariance = Matrix6d::Zero();
  DeclaredScaleCheck declared_scale;  ///< PPC only (check_declared_scale)
  PoseStddev stddev;                  ///< 1 sigma, mm is translation_m * 1000
  Observability observability;
  std::vector<ViewResidual> views;  ///< one entry per input view, in input order
  std::vector<std::string> notes;
  double solve_time_ms = 0.0;
};

/// Calibrates camera_T_lidar from views of one camera and one LiDAR. Without a guess the
/// closed-form initialiser is used. Never throws on bad input: success = false with a reason.
CalibrationSolution calibrate(const std::vector<View>& views, Method method,
                              const SolverOptions& options,
                              const std::optional<Eigen::Isometry3d>& initial_guess = std::nullopt);

/// Closed-form camera_T_lidar: rotation from the plane normals (SVD), translation from the plane
/// offsets (and for PBPC the back-projected line planes, which are board-size free) by linear
/// least squares.
Expected<Eigen::Isometry3d> closedFormInitialGuess(const std::vector<View>& views, Method method,
                                                   const SolverOptions& options);

/// Mean perpendicular distance (undistorted px) between each image edge line and the LiDAR edge
/// points paired with it (core/common/edge_association.h, as the solver and the overlay pair
/// them) projected with camera_T_lidar and the view's K. Uses edges valid on both sides;
/// nullopt when none is usable.
std::optional<double> meanLineReprojectionErrorPx(const std::vector<View>& views,
                                                  const Eigen::Isometry3d& camera_T_lidar);
/// The same for one view (over its valid edges).
std::optional<double> viewLineReprojectionErrorPx(const View& view,
                                                  const Eigen::Isometry3d& camera_T_lidar);
/// The same for one image edge of one view.
std::optional<double> edgeLineReprojectionErrorPx(const View& view, int edge,
                                                  const Eigen::Isometry3d& camera_T_lidar);
/// RMS distance (m) of the LiDAR board points, mapped with camera_T_lidar, to the camera planes.
std::optional<double> planeRmsM(const std::vector<View>& views,
                                const Eigen::Isometry3d& camera_T_lidar);

// ------------------------------------------------------------------------------------------
// Generic plane-to-plane (MSG pairwise) solver, reusable for any two sensors.
// ------------------------------------------------------------------------------------------

/// The same board pose seen by sensors a and b (planes in each sensor's frame).
struct PlaneCorrespondence {
  Plane in_a;
  Plane in_b;
  double weight = 1.0;  ///< multiplies both residuals (e.g. per-sensor confidence)
  int view_id = 0;
};

struct PairwiseSolution {
  bool success = false;
  std::string reason;
  Eigen::Isometry3d a_T_b = Eigen::Isometry3d::Identity();  ///< p_a = a_T_b * p_b
  Eigen::Isometry3d initial_guess = Eigen::Isometry3d::Identity();
  bool used_closed_form_init = false;
  int correspondences_used = 0;
  double final_cost = 0.0;
  int iterations = 0;
  std::string termination;
  double normal_rms_deg = 0.0;  ///< angle between n_a and R n_b
  double offset_rms_mm =
      0.0;  ///< plane gap: at the sensor origin (n_a . t + d_b - d_a) for
            ///< solvePlaneToPlane, at the boards for calibrate(kMsgPair) and the graph
  Matrix6d covariance = Matrix6d::Zero();  ///< see the convention at the top (frame a)
  PoseStddev stddev;
  Observability observability;
  std::vector<std::string> notes;
};

/// Closed-form a_T_b from plane correspondences (Kabsch on normals, least squares on offsets).
Expected<Eigen::Isometry3d> closedFormPlaneToPlane(
    const std::vector<PlaneCorrespondence>& correspondences, const SolverOptions& options);

/// Plane-to-plane solve (Ceres, quaternion manifold). Needs >= 3 correspondences whose normals
/// span 3D. Uses loss, msg_* sigmas, iteration and tolerance options of SolverOptions. Planes
/// alone carry no board position, so offsets are compared at the sensor origin (the normal error
/// times the board distance enters them); calibrate(..., kMsgPair) and the MSG graph, which have
/// the board points, compare them at the boards instead and are more accurate.
PairwiseSolution solvePlaneToPlane(
    const std::vector<PlaneCorrespondence>& correspondences, const SolverOptions& options,
    const std::optional<Eigen::Isometry3d>& initial_guess = std::nullopt);

/// Board points of one plane correspondence (core/common/board_geometry.h boardPoint, in a and
/// in b); zero = the sensor origin.
struct BoardPointPair {
  Eigen::Vector3d in_a = Eigen::Vector3d::Zero();
  Eigen::Vector3d in_b = Eigen::Vector3d::Zero();
};

/// solvePlaneToPlane with the offset residual measured at the boards (the MSG graph's pairwise
/// links); `points` is empty (offsets compared at the origins, as the overload above) or
/// parallel to `correspondences`.
PairwiseSolution solvePlaneToPlane(
    const std::vector<PlaneCorrespondence>& correspondences,
    const std::vector<BoardPointPair>& points, const SolverOptions& options,
    const std::optional<Eigen::Isometry3d>& initial_guess = std::nullopt);

/// Camera plane (a) and LiDAR plane (b) of every view where both were found.
std::vector<PlaneCorrespondence> planeCorrespondences(const std::vector<View>& views);

// ------------------------------------------------------------------------------------------
// Robustness to random initialisation (the paper's experiment).
// ------------------------------------------------------------------------------------------

struct RobustnessOptions {
  int trials = 100;
  double rotation_sigma_deg = 90.0;  ///< deg, per axis of the rotation vector
  double translation_sigma_m = 0.5;  ///< m, per axis
  /// false: guesses drawn around the identity (zero-mean, as the paper); true: around the
  /// reference (perturbations of it).
  bool around_reference = false;
  unsigned seed = 1;
  double converged_rotation_deg = 0.5;    ///< a trial converged if within this of the reference
  double converged_translation_m = 0.02;  ///< m
  std::string validate() const;
};

struct RobustnessReport {
  bool success = false;  ///< false if the routine could not run (reason)
  std::string reason;
  int trials = 0;
  int converged = 0;
  double convergence_rate = 0.0;  ///< converged / trials
  /// Reference the trials are compared with: the caller's, or the closed-form-initialised solve.
  Eigen::Isometry3d reference = Eigen::Isometry3d::Identity();
  /// Spread of the converged results around their mean (max and RMS deviation).
  double rotation_spread_max_deg = 0.0;
  double rotation_spread_rms_deg = 0.0;
  double translation_spread_max_m = 0.0;
  double translation_spread_rms_m = 0.0;
  std::vector<double> rotation_error_deg;   ///< per trial, against the reference
  std::vector<double> translation_error_m;  ///< per trial
  double mean_solve_time_ms = 0.0;
};

/// Starts Ceres from `trials` random guesses (not from the closed-form initialiser) and reports
/// how often it reaches the reference.
RobustnessReport evaluateRandomInitialisation(
    const std::vector<View>& views, Method method, const SolverOptions& options,
    const RobustnessOptions& robustness,
    const std::optional<Eigen::Isometry3d>& reference = std::nullopt);

}  // namespace board_calib
