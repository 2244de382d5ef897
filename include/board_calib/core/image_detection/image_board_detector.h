// Camera board detector: finds the calibration board in one raw (distorted) image and returns
// its features in undistorted pixels (core/features.h). Three board types:
//  * plain        (PBPC-Cal): segmentation + sub-pixel edge fitting, corners = line
//                  intersections (may lie outside the image), pose by PnP on the four corners;
//  * checkerboard (PPC-Cal):  OpenCV corners + cornerSubPix, pose by PnP, outer edges from pose;
//  * apriltag_grid (MSG-Cal): libapriltag tag36h11 corners mapped to the grid, pose from all
//  corners.
//
// Edge naming (features.h): edges are named by the direction of their outward normal in the image
// (UL ~ up-left, UR, LR, LL), choosing the cyclic assignment closest to a diamond. For the plain
// board the PnP correspondence is: image corner 0 (top, UL ∩ UR) = board top-left outer corner
// (board origin), corner 1 (right) = top-right, corner 2 (bottom) = bottom-right, corner 3 (left) =
// bottom-left; a square plain board's 4-fold symmetry is resolved by this choice.
// Checkerboard 180° ambiguity: the pattern is oriented so that the board x axis points as close to
// image +u as possible (board held upright or as a diamond, never upside down).
#pragma once

#include <board_calib/core/camera_model.h>
#include <board_calib/core/features.h>
#include <board_calib/core/target.h>

#include <opencv2/core.hpp>

#include <memory>
#include <string>
#include <vector>

namespace board_calib {

struct ImageBoardDetectorOptions {
  // --- plain board ---
  int segmentation_width_px = 480;  ///< px, width of the downscaled image used for segmentation
  double min_board_area_fraction = 0.01;  ///< smallest board area, fraction of the image area
  double min_solidity = 0.90;  ///< board region area / convex hull area (a board is convex)
  double max_flat_gradient =
      10.0;  ///< grey levels (3x3 max - min, downscaled): below it a pixel is in a flat area
  double max_interior_texture =
      0.35;  ///< interior grey stddev / board-background contrast (a board is uniform)
  int max_board_candidates =
      4;  ///< board-like regions tried, best score first, until one gives a complete board
  double border_margin_px =
      3.0;  ///< px; edge pixels closer than this to the image border are not board edges
  double coarse_search_px =
      10.0;  ///< px, half width of the first edge search around the coarse outline (a line
             ///< quadrilateral in an image no wider than line_detection_width_px: fine_search_px)
  double fine_search_px = 3.0;  ///< px, half width of the refinement search around the fitted line
  double sample_step_px = 2.0;  ///< px, spacing of edge samples along each edge
  double corner_exclusion_px =
      12.0;                        ///< px, edge samples this close to a coarse corner are skipped
  double min_edge_contrast = 4.0;  ///< grey levels per px, weakest accepted edge gradient (floor of
                                   ///< the noise-based threshold)
  double edge_snr = 3.0;  ///< an edge gradient peak must exceed this many sigmas of the gradient
                          ///< noise (measured per image)
  /// px, shortest span of edge pixels accepted as a board edge (line direction from >= this); a
  /// visible side shorter than twice this needs its min_side_coverage share
  double min_edge_length_px = 24.0;
  int min_edge_points = 8;         ///< inlier edge samples needed for a valid edge
  double min_side_coverage = 0.5;  ///< fraction of a side's visible length that must show its edge
                                   ///< (the rest may be occluded: hands, legs)
  double edge_inlier_px = 3.0;   ///< px, edge samples farther than this from the line are outliers
                                 ///< (a held board bows ~3 px)
  double max_edge_rms_px = 1.5;  ///< px, an edge fit worse than this is marked invalid
  double max_edge_bow_fraction =
      0.015;  ///< an edge whose samples bow by more than this fraction of their span beyond 3
              ///< standard errors is bent, not a board side (a printed disc, a side pulled along
              ///< a leg or a hand); held boards measured <= 1.1 %
  int line_detection_width_px = 640;  ///< px, width of the downscaled image the line segment
                                      ///< detector (LSD) runs on; 0 = no line hypotheses
  int max_line_hypotheses =
      6;  ///< quadrilaterals of long straight edges refined at full resolution, best first
  int max_lines = 80;  ///< best-supported merged straight lines that quadrilaterals are built from
  int max_lines_static_scene =
      200;  ///< the same once a session knows the static scene (ImageBoardTracker): its
            ///< quadrilaterals are then skipped and the rest ranked by support per px of perimeter;
            ///< alone, the lines past max_lines up to this many (those ending at a corner
            ///< first) give quadrilaterals only where the lines end at the corners, tried when
            ///< nothing else was the board
  double max_board_tilt_deg = 70.0;    ///< deg, a plain board turned further from the camera is
                                       ///< rejected (no calibration view)
  double max_board_distance_m = 20.0;  ///< m, a plain board farther away is rejected: a 16-ring
                                       ///< LiDAR (2 deg) puts < 2 lines on a 1 m board there
  // --- checkerboard ---
  int fast_check_width_px = 800;  ///< px, images wider than this are searched downscaled first
  int subpix_window_px = 5;       ///< px, half window of cornerSubPix (clamped to the square size)
  // --- AprilTag grid ---
  double tag_decimate = 2.0;  ///< libapriltag quad_decimate (1 = full resolution)
  double tag_sigma = 0.8;  ///< px, libapriltag quad_sigma: blur before quads (its decimation only
                           ///< subsamples: noise makes false quads); decoding uses the sharp image
  int tag_threads = 1;     ///< libapriltag worker threads
  bool tag_refine_edges = true;  ///< libapriltag refine_edges
  int tag_max_hamming = 1;       ///< bits corrected per tag (0..2; more = more false ids)
  int min_tags = 1;              ///< tags needed for a pose
  // --- all ---
  double min_board_size_px = 30.0;       ///< px, smallest board side in the image
  double max_reprojection_rms_px = 3.0;  ///< px, a pattern pose fitting worse than this is rejected
  double max_plain_corner_rms_px = 10.0;  ///< px, plain board: corners are extrapolated (often far
                                          ///< outside the image) and the board flexes
  double max_plain_corner_rms_fraction =
      0.01;  ///< plain board: corner PnP RMS above this fraction of the mean side length is
             ///< rejected (a quadrilateral that is no board of the declared width and height)
  double pixel_sigma_px = 0.2;  ///< px, assumed corner noise floor for the pose covariance

  /// Reason the options are inconsistent, empty when valid.
  std::string validate() const;
};

/// Plain board: where the detection time went, ms of CPU time of the calling thread per stage
/// (the stages run one after another on it; OpenCV worker threads, if any, are not counted), for
/// profiling (bench_image_detector --stages).
struct PlainStageTimes {
  double noise_ms = 0.0;        ///< ms, image noise estimate
  double regions_ms = 0.0;      ///< ms, region proposals (segmentation, openings)
  double line_resize_ms = 0.0;  ///< ms, downscale for the line segment detector
  double lsd_ms = 0.0;          ///< ms, line segment detector (LSD)
  double undistort_ms = 0.0;    ///< ms, segment ends to undistorted px
  double merge_ms = 0.0;        ///< ms, segments merged into straight lines
  double quads_ms = 0.0;        ///< ms, corner graph, 4-cycles, kept quadrilaterals
  double trace_ms = 0.0;        ///< ms, fourth sides traced from three lines
  double edges_ms = 0.0;        ///< ms, sub-pixel edge refinement of the hypotheses' sides
  double fits_ms = 0.0;         ///< ms, rest of the hypotheses' fits (corners, PnP, checks)

  PlainStageTimes& operator+=(const PlainStageTimes& other);
  PlainStageTimes scaled(double factor) const;  ///< every stage times factor (a mean)
  double total() const;                         ///< ms, the sum of the stages
  /// "noise 1.2 | regions 3.4 | ... = total 9.9" in ms, the stages in the order they run.
  std::string text() const;
};

/// What the detector saw beyond the features (for debug drawing and quality checks).
struct ImageDetectionDetails {
  std::array<Points2, kNumEdges> edge_points_raw;  ///< plain: inlier edge samples per edge, raw px
  std::array<double, kNumEdges> edge_rms_px{};     ///< plain: line fit RMS per edge, px
  std::array<double, kNumEdges> edge_bow_px{};     ///< plain: sagitta of a parabola through each
                                                   ///< edge's samples over their span, px
  std::array<double, kNumEdges> edge_bow_sigma_px{};  ///< plain: standard error of that sagitta, px
  std::array<double, kNumEdges> edge_span_px{};       ///< plain: length each edge is seen along, px
  std::array<std::string, kNumEdges> edge_reason;     ///< why an edge is invalid (empty when valid)
  Points2 outline_raw;                                ///< plain: coarse board outline, raw px
  std::vector<std::array<Eigen::Vector2d, 4>>
      hypotheses_px;  ///< plain: quadrilaterals tried (undistorted px corners)
  std::vector<std::string>
      hypothesis_reasons;  ///< plain: per hypothesis, "found" or why it is not the board
  int best_attempt = -1;   ///< plain, no board: the hypothesis (index into hypotheses_px) whose
                           ///< rejection the reason gives; -1 when none got that far
  std::vector<std::array<Eigen::Vector2d, 4>>
      boards_px;  ///< plain: corners (undistorted px) of every hypothesis that passed the board
                  ///< checks, the accepted one and those dropped as static rectangles included
  std::vector<std::array<Eigen::Vector2d, 2>>
      lines_px;  ///< plain: merged straight lines of the line stage (support ends, undistorted px)
  std::vector<std::array<Eigen::Vector2d, 2>> segments_raw;  ///< plain: line segments (LSD), raw px
  double noise_sigma = 0.0;  ///< plain: image noise estimate, grey levels
  /// plain: the kind of hypothesis the board came from ("region", "lines", "weak lines",
  /// "traced side", "projected board"; "colour part" and the like for the colour search)
  std::string board_source;
  /// plain: the board's edge support (px of its sides that show their edge), weighed by the
  /// cosine of its turn from the line of sight; what ranks two boards found in one image (of two
  /// whose outlines cross, the one whose corners fit the declared size better is kept)
  double board_support_px = 0.0;
  int line_segments = 0, straight_lines = 0,
      line_quads = 0;        ///< plain: LSD segments, merged lines, quadrilaterals
  std::vector<int> tag_ids;  ///< AprilTag: detected ids on the grid
  std::vector<std::array<Eigen::Vector2d, 4>>
      tag_corners_raw;    ///< AprilTag: corners, raw px (OpenCV convention)
  int rejected_tags = 0;  ///< AprilTag: detections whose id is not on the grid
  Points2 pattern_raw;    ///< pattern points (checkerboard/tag corners), raw px
  std::vector<double>
      pattern_errors_px;  ///< reprojection error per pattern point (features.pattern order)
  /// Pose covariance, order (rotation vector rad, translation m), from the PnP Jacobian with
  /// sigma = max(residual RMS, pixel_sigma_px). Zero when no pose.
  Eigen::Matrix<double, 6, 6> pose_covariance = Eigen::Matrix<double, 6, 6>::Zero();
  double time_ms = 0.0;         ///< detection time
  PlainStageTimes stage_times;  ///< plain: detection time per stage
};

struct ImageDetection {
  CameraBoardFeatures features;
  ImageDetectionDetails details;
};

/// Detector for one target; not thread-safe (holds a libapriltag detector), one per camera.
/// Where a prior extrinsic (initial guess or an earlier solve) puts the board seen by the other
/// sensor: its four outer corners projected into the image (undistorted px, any cyclic order).
struct ExpectedBoard {
  std::array<Eigen::Vector2d, kNumEdges> corners_px{};
  double tolerance_px =
      0.0;  ///< px, how far the true corners may lie from these (the prior's projection error)
  /// A board anywhere inside the quadrilateral (within the tolerance) fits, not only one whose
  /// corners lie near these: the part of a frame that moved, the holder included.
  bool inside = false;
};

/// A rectangle of the static scene (window, door, poster) that a session saw at one place
/// (issue 14, 3a): a board that coincides with it is that rectangle, not the board.
struct StaticRectangle {
  std::array<Eigen::Vector2d, kNumEdges> corners_px{};  ///< undistorted px, any cyclic order
  double tolerance_px = 0.0;  ///< px, a board whose every corner is this close is the rectangle
  double seen_for_s = 0.0;    ///< s, how long the session has seen it there (for the reason)
};

/// What a session knows of the static scene in one camera (ImageBoardTracker): rectangles that
/// passed the board checks at one place, and straight lines seen at one place. A line
/// quadrilateral with two or more sides on static lines is not tried as a board, and the line
/// search widens (ImageBoardDetectorOptions::max_lines_static_scene).
struct StaticScene {
  std::vector<StaticRectangle> rectangles;
  std::vector<std::array<Eigen::Vector2d, 2>> lines_px;  ///< support ends, undistorted px
  /// bgr, the image downscaled to segmentation_width_px: per pixel the median of frames spread
  /// over the session, where the moving board and its holder are rarely twice at one place.
  /// Empty until the session has seen enough of the scene. A board the whole-image search
  /// misses is searched again, in its own colour contrast, where a frame departs from it.
  cv::Mat background;
  bool empty() const { return rectangles.empty() && lines_px.empty() && background.empty(); }
};

/// A quadrilateral an image search tried (the board or not), placed as the declared board by PnP
/// on its corners: what a session without a calibration yet compares with the LiDAR's boards.
struct BoardCandidate {
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();  ///< m, board centre in the camera frame
  double depth_sigma_m = 0.0;    ///< m, 1 sigma of the centre along its viewing ray
  double lateral_sigma_m = 0.0;  ///< m, 1 sigma across it
};

/// Plain board: the board found and every quadrilateral tried (ImageDetectionDetails), as
/// candidates. Their 1 sigmas follow the corners' misfit to the declared board (at least
/// `corner_sigma_px`); a quadrilateral that misfits by a quarter of its size is no view of it.
std::vector<BoardCandidate> boardCandidates(const ImageDetection& detection,
                                            const CameraModel& camera, const Target& target,
                                            double corner_sigma_px);

class ImageBoardDetector {
 public:
  static Expected<ImageBoardDetector> create(const Target& target,
                                             const ImageBoardDetectorOptions& options);
  ImageBoardDetector(ImageBoardDetector&&) noexcept;
  ImageBoardDetector& operator=(ImageBoardDetector&&) noexcept;
  ~ImageBoardDetector();

  /// Detects the board in a raw bgr8 or mono8 image. The image size must match the camera
  /// model; otherwise (or on any other failure) features.found is false with a reason.
  ImageDetection detect(const cv::Mat& image, const CameraModel& camera);

  /// The same, but a plain board coinciding with a static rectangle is not accepted (reason
  /// names it) and the search goes on to the next hypothesis; quadrilaterals of static lines
  /// are not tried. Pattern boards (checkerboard, AprilTag grid) are unambiguous and
  /// ignore the static scene.
  ImageDetection detect(const cv::Mat& image, const CameraModel& camera,
                        const StaticScene& excluded);

  /// Second chance inside the projected board (issue 14, 3b): the same detector and checks, but
  /// only hypotheses near `expected` are tried, and a board is accepted only when each of its
  /// corners lies within expected.tolerance_px of an expected corner. Plain boards only (the
  /// pattern boards are found alone); others give "not found" with the reason.
  ImageDetection detectNear(const cv::Mat& image, const CameraModel& camera,
                            const ExpectedBoard& expected);

  const Target& target() const;
  const ImageBoardDetectorOptions& options() const;

 private:
  ImageBoardDetector() = default;
  ImageDetection run(const cv::Mat& image, const CameraModel& camera, const ExpectedBoard* expected,
                     const StaticScene* excluded);
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// Debug drawing on a copy of the raw image (bgr8): board outline, edge samples, fitted lines
/// (drawn curved, through the distortion), corners, tag ids, pattern points, board axes.
cv::Mat drawImageDetection(const cv::Mat& image, const CameraModel& camera,
                           const ImageDetection& detection);

/// Line through two undistorted points with the outward normal pointing away from `inside`
/// (a u + b v + c = 0, a^2 + b^2 = 1, inside < 0).
Eigen::Vector3d lineThrough(const Eigen::Vector2d& p, const Eigen::Vector2d& q,
                            const Eigen::Vector2d& inside);

}  // namespace board_calib
