// LiDAR board detector: finds a planar calibration board in any 3D LiDAR cloud (organized or
// not, with or without a ring field, NaN or zero for no return) without a hand-set ROI, and
// returns its plane, inlier points, per-scan-line edge points, four edge lines and corners.
//
// Pipeline: valid points (optional ROI box, optional background subtraction) -> voxel grid with
// per-voxel plane statistics -> planar region growing -> candidates scored by size and shape
// against the target (min-area rectangle vs width x height), fill, flatness -> RANSAC plane on
// the winner, refined by least squares -> scan lines (ring, row, or elevation clustering) ->
// extreme points per scan line -> assigned to UL/UR/LR/LL -> robust line fits -> corners.
#pragma once

#include <board_calib/core/common/static_memory.h>
#include <board_calib/core/features.h>
#include <board_calib/core/lidar_detection/lidar_cloud.h>
#include <board_calib/core/target.h>

#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace board_calib {

/// Axis-aligned box in the LiDAR frame.
struct RoiBox {
  Eigen::Vector3d min = Eigen::Vector3d::Constant(-1e9);  ///< m
  Eigen::Vector3d max = Eigen::Vector3d::Constant(1e9);   ///< m
  bool contains(const Eigen::Vector3d& p) const {
    return (p.array() >= min.array()).all() && (p.array() <= max.array()).all();
  }
};

struct LidarBoardDetectorOptions {
  // Input.
  double min_range_m = 0.3;   ///< returns closer than this are ignored (also drops (0,0,0)), m
  double max_range_m = 30.0;  ///< returns farther than this are ignored, m
  bool use_roi = false;       ///< keep only points inside `roi`
  RoiBox roi;                 ///< m, LiDAR frame

  // Planar segmentation.
  double voxel_size_m =
      0.2;  ///< voxel edge for plane statistics; > the scan-line gap on the board, m
  int min_voxel_points = 4;  ///< voxels with fewer points do not seed or join regions
  double max_voxel_thickness_m =
      0.03;                          ///< RMS spread of a voxel's points along the region normal, m
  double max_voxel_offset_m = 0.05;  ///< distance of a voxel's centroid from the region plane, m
  double min_seed_spread_m =
      0.02;  ///< second-largest RMS spread of a seed voxel (2D, not a line), m
  double max_voxel_normal_angle_deg = 15.0;  ///< a 2D voxel's own normal vs the region's, deg

  // Candidate scoring against the target.
  int min_board_points = 30;     ///< fewer points on a candidate: not a board
  double min_size_ratio = 0.6;   ///< measured side / declared side, lower bound
  double max_size_ratio = 1.35;  ///< measured side / declared side, upper bound
  double min_fill_ratio = 0.45;  ///< hull area / declared area, lower bound (partly seen boards)
  double max_candidate_rms_m = 0.03;  ///< RMS distance of candidate points to their plane, m
  double ambiguity_ratio =
      0.7;  ///< a second candidate with at least this fraction of the best's support: ambiguous
  bool reject_ambiguous =
      true;  ///< report two board-like planes as "ambiguous" instead of picking one

  // Far, sparse boards: candidates from scan-line segments (runs of returns in front of their
  // surroundings, linked across adjacent lines), judged with tolerances from the sampling.
  bool sparse_candidates = true;  ///< also grow candidates from scan-line segments
  int min_scan_lines = 3;         ///< scan lines a sparse candidate needs
  double range_noise_m =
      0.02;  ///< 1 sigma range noise of the LiDAR: segment splitting and size tolerances, m
  double sparse_size_slack = 0.1;  ///< sparse candidates fit in the declared board enlarged by this
                                   ///< fraction plus the sampling

  // Plane refinement.
  double plane_distance_threshold_m =
      0.05;                     ///< RANSAC inlier distance, m (3 RMS of a noisy OS1-64 board)
  int ransac_iterations = 100;  ///< RANSAC hypotheses for the plane and each edge line
  unsigned random_seed = 42;    ///< fixed seed: deterministic results

  // Scan lines and edges.
  double elevation_gap_deg =
      0.15;  ///< without ring/rows: a gap larger than this starts a new beam, deg
  int min_points_per_scan_line = 2;  ///< scan lines with fewer board points give no edge points
  int min_edge_points = 3;           ///< fewer inliers: the edge is invalid
  double edge_inlier_threshold_m =
      0.03;  ///< distance of an edge point from its line (in-plane; at least the sample spacing), m
  double max_edge_rms_m = 0.02;  ///< RMS of the edge-line fit above this: invalid, m
  bool correct_edge_sampling_bias =
      true;  ///< move edge lines out by the extremes' mean inset (edge_points stay raw)
  double beam_divergence_deg =
      0.15;  ///< edges bloom out by half of it, which offsets the inset, deg
  double max_corner_angle_error_deg = 15.0;  ///< adjacent edges must meet at 90 deg +- this, deg
  double size_doubt_ratio =
      0.02;  ///< measured size differs from declared by more: say so in `reason`

  /// Reason the options are inconsistent, empty when they are valid.
  std::string validate() const;
};

/// Why the detector stopped (kFound: a board plane was found; edges may still be invalid).
enum class LidarDetectionCode {
  kFound,
  kInvalidOptions,
  kInvalidTarget,
  kEmptyCloud,
  kNoValidPoints,  ///< all NaN / zero / out of range / outside the ROI / background
  kNoPlane,        ///< no planar region of enough points
  kWrongSize,      ///< planar regions exist but none matches the target's size and shape
  kAmbiguous,      ///< several board-like planes
  kTooFewPoints,   ///< the board candidate has too few points after refinement
};
const char* lidarDetectionCodeName(LidarDetectionCode code);

/// A planar region that was considered as the board (for debugging and tuning).
struct LidarBoardCandidate {
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();  ///< m
  Plane plane;
  int num_points = 0;
  Eigen::Vector2d rectangle_m =
      Eigen::Vector2d::Zero();  ///< sides from second moments (sqrt(12 lambda)), larger first, m
  double fill_ratio = 0.0;      ///< convex hull area / declared board area
  double rms_m = 0.0;           ///< RMS distance to the plane, m
  double score =
      0.0;  ///< support: points * exp(-4 * shape error), higher is better; < 0 when rejected
  int scan_lines = 0;            ///< sparse candidates: scan lines on it (0: a voxel region)
  std::string rejected_because;  ///< empty when it passed every check
};

struct LidarBoardDetection {
  LidarBoardFeatures features;  ///< `found`, `reason` and geometry (the message's content)
  LidarDetectionCode code = LidarDetectionCode::kNoPlane;
  int num_valid_points = 0;                     ///< after range / ROI / background filtering
  int num_scan_lines = 0;                       ///< scan lines that crossed the board
  std::string scan_line_source;                 ///< "ring", "row" or "elevation"
  std::vector<LidarBoardCandidate> candidates;  ///< best first
};

/// Model of the empty scene (MSG-Cal): capture a few clouds without the board, then the
/// detector keeps only what is new. Organized clouds use a per-(row, column) range image,
/// unorganized clouds with a ring field a per-(ring, azimuth bin) range image, the others a
/// voxel occupancy grid.
struct BackgroundModelOptions {
  double range_margin_m = 0.15;  ///< a point must be this much closer than the background, m
  double azimuth_bin_deg = 0.4;  ///< azimuth bin for unorganized clouds with rings, deg
  double voxel_size_m = 0.1;     ///< occupancy voxel for clouds without rings, m
  double min_range_m = 0.3;      ///< returns closer than this are no returns, m
  std::string validate() const;
};

class BackgroundModel {
 public:
  explicit BackgroundModel(BackgroundModelOptions options = {});
  ~BackgroundModel();
  BackgroundModel(BackgroundModel&&) noexcept;
  BackgroundModel& operator=(BackgroundModel&&) noexcept;

  /// Adds one cloud of the empty scene. Fails when its layout differs from earlier frames.
  Status addFrame(const LidarCloud& cloud);
  void clear();
  int numFrames() const;
  bool empty() const { return numFrames() == 0; }
  /// Per point of `cloud`: 1 when it is new (foreground), 0 when it belongs to the background
  /// or is no return. Everything is foreground when the model is empty.
  std::vector<uint8_t> foregroundMask(const LidarCloud& cloud) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// Finds the board. `background` may be null. Never throws on bad data; the reason is in
/// `features.reason` and `code`.
LidarBoardDetection detectLidarBoard(const LidarCloud& cloud, const Target& target,
                                     const LidarBoardDetectorOptions& options = {},
                                     const BackgroundModel* background = nullptr);

/// Where a prior extrinsic puts the board the camera saw (its four outer corners in the LiDAR
/// frame): the region a second-chance search is restricted to.
struct ExpectedLidarBoard {
  std::array<Eigen::Vector3d, kNumEdges> corners{};  ///< m, LiDAR frame, in cyclic order
  double tolerance_m = 0.0;  ///< m, how far the board may lie from this quadrilateral (prior error
                             ///< and sampling)
};

/// Second chance inside the back-projected image board (issue 14, 3b): the same stages and
/// size/shape checks as detectLidarBoard, but only candidates whose centroid lies within
/// expected.tolerance_m of the expected quadrilateral (in its plane and off it) compete, so
/// board-like planes elsewhere neither win nor make the frame ambiguous.
LidarBoardDetection detectLidarBoardNear(const LidarCloud& cloud, const Target& target,
                                         const LidarBoardDetectorOptions& options,
                                         const ExpectedLidarBoard& expected);

/// Stateful detector: one per LiDAR (not thread-safe). Each cloud goes through
/// detectLidarBoard's stages; board-like candidates at static places are dropped as
/// background, and frames the single-frame rules would call ambiguous are decided by that
/// history. Clouds must come in time order; a stamp going back resets the memory.
class LidarBoardTracker {
 public:
  explicit LidarBoardTracker(Target target, LidarBoardDetectorOptions detector = {},
                             StaticMemoryOptions memory = {});
  LidarBoardDetection detect(const LidarCloud& cloud, const BackgroundModel* background = nullptr);
  void reset();
  int numPlaces() const { return static_cast<int>(places_.size()); }
  int numStaticPlaces() const;
  const LidarBoardDetectorOptions& detectorOptions() const { return detector_; }
  /// New detector options (e.g. reconfigured); the memory is kept.
  void setDetectorOptions(const LidarBoardDetectorOptions& options) { detector_ = options; }

 private:
  struct Place {
    Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
    Eigen::Vector3d normal = Eigen::Vector3d::UnitX();
    PlaceSightings sightings;
  };
  bool isStatic(const Place& p) const;
  int match(const LidarBoardCandidate& c) const;
  Target target_;
  LidarBoardDetectorOptions detector_;
  StaticMemoryOptions memory_;
  std::vector<Place> places_;
  long frames_ = 0;
  double last_stamp_ = -1e300;
};

}  // namespace board_calib
