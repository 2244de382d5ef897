// Private helpers shared by the three board detectors (not installed, not public API).
#pragma once

#include <board_calib/core/image_detection/image_board_detector.h>

#include <opencv2/core.hpp>

#include <deque>

#include <ctime>
#include <type_traits>

namespace board_calib {
namespace image_detection {

/// CPU time of the calling thread, ms (PlainStageTimes): on a shared machine it varies far less
/// than wall time; the detector is single-threaded unless OpenCV is given worker threads.
inline double threadCpuMs() {
  timespec t{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
  return static_cast<double>(t.tv_sec) * 1e3 + static_cast<double>(t.tv_nsec) * 1e-6;
}

/// ms of CPU time of the calling thread since `start` (a threadCpuMs() reading).
inline double msSince(double start) { return threadCpuMs() - start; }

/// f(), with the calling thread's CPU time it took added to *ms.
template <typename F>
auto timed(double* ms, F&& f) {
  const double start = threadCpuMs();
  if constexpr (std::is_void_v<decltype(f())>) {
    f();
    *ms += msSince(start);
  } else {
    auto result = f();
    *ms += msSince(start);
    return result;
  }
}

/// Result of a PnP fit on undistorted pixels (zero distortion, camera K).
struct PoseFit {
  bool ok = false;
  std::string reason;
  Eigen::Isometry3d camera_T_board = Eigen::Isometry3d::Identity();
  double rms_px = 0.0;
  std::vector<double> errors_px;
  Eigen::Matrix<double, 6, 6> covariance = Eigen::Matrix<double, 6, 6>::Zero();
};

/// PnP on coplanar board points (z = 0) seen at undistorted pixels: IPPE, then Levenberg-Marquardt
/// when there are more than four points; covariance from the projection Jacobian.
PoseFit fitPose(const Points3& board_points, const Points2& pixels, const Eigen::Matrix3d& K,
                double sigma_floor_px);

/// Board plane in the camera frame from the pose: normal = board +z (away from the camera).
Plane planeFromPose(const Eigen::Isometry3d& camera_T_board);

/// Cosine of the board's turn from the line of sight to its origin (1 facing the camera, 0
/// edge-on); 0 for a degenerate pose.
double facingCosine(const Eigen::Isometry3d& camera_T_board);

/// ImageDetectionDetails::board_source of a board outlined as a uniform region.
constexpr const char kRegionSource[] = "region";
/// Source of a board found by the quadrilaterals of the lines past max_lines (no prior of being
/// the board).
constexpr const char kWeakLinesSource[] = "weak lines";
/// Source of a board found by the faint-line search (faintLineQuantization), judged as weak lines.
constexpr const char kFaintLinesSource[] = "faint lines";
/// Source of a board found by the line search at a finer width (far boards), judged as weak lines.
constexpr const char kFineLinesSource[] = "fine lines";
/// Source of a board outlined by a stable region's quadrilateral, judged as weak lines.
constexpr const char kStableRegionsSource[] = "stable regions";

/// Names edges by their outward normal angle (atan2(b, a), image v down). `angles` are in
/// clockwise image order when `cyclic` (then a cyclic shift is chosen); otherwise each edge gets
/// the nearest name and ties keep the edge with the larger weight. Returns the name per input, -1
/// if dropped.
std::vector<int> nameEdges(const std::vector<double>& angles, const std::vector<double>& weights,
                           bool cyclic);

/// For named edges (UL, UR, LR, LL), the cyclic shift by one name (1 or 3) that stays closer to a
/// diamond: renaming edge (k + shift) % 4 as k is the other way a rectangular board may be held.
int rotatedNamingShift(const std::array<Eigen::Vector3d, kNumEdges>& lines);

/// Outer edges, corners and validity derived from the pose and the target's outer size.
void outerEdgesFromPose(const Target& target, CameraBoardFeatures* features);

/// Grey conversion of a bgr8/mono8 image (shares data for mono8).
cv::Mat toGray(const cv::Mat& image);

/// Intersection of two lines (homogeneous), false when (nearly) parallel.
bool intersectLines(const Eigen::Vector3d& l1, const Eigen::Vector3d& l2, Eigen::Vector2d* point);

/// LSD misses weak stretches the gradient search still finds: a side's segments need only cover
/// this share of the side coverage required of the refined edge.
constexpr double kLineCoverageShare = 0.5;

/// Four lines in cyclic order (undistorted px): corner s ends side s and starts side s+1.
struct QuadHypothesis {
  std::array<Eigen::Vector2d, 4> corners;
  std::array<double, 4> support{};  ///< px of line segments along each side
  std::array<double, 4> visible{};  ///< px of each side inside the image
  double score = 0;     ///< segment support along the sides minus support past the corners
  double size_px = 0;   ///< mean side length
  int corner_ends = 0;  ///< line ends at the corners (of 8; counted for the weaker lines only)
};

/// What the line stage saw (counts for reasons, segments for the debug image).
struct LineEvidence {
  std::vector<std::array<Eigen::Vector2d, 2>>
      segments_raw;  ///< LSD segments, raw full-resolution px
  std::vector<std::array<Eigen::Vector2d, 2>>
      segments_u;  ///< the same segments, undistorted px (for the traced sides' segment rule)
  std::vector<std::array<Eigen::Vector2d, 2>>
      line_ends;  ///< merged lines' support ends, undistorted px
  int segments = 0, lines = 0, quads = 0;
  PlainStageTimes times;  ///< the line stage's share (resize, LSD, undistort, merge)
};

/// Three lines of a board whose fourth side has no line (faint, or covered by hands or legs): two
/// roughly parallel open sides joined by a base, each base corner where the lines end.
struct ThreeSides {
  std::array<Eigen::Vector3d, 3> lines;    ///< open side a, base, open side b (undistorted px)
  std::array<Eigen::Vector2d, 2> corners;  ///< a x base, base x b (undistorted px)
  std::array<Eigen::Vector2d, 2> inward;   ///< unit direction of each open side from its corner
  std::array<double, 2> reach{};  ///< px from each corner that the open side reaches at least (its
                                  ///< segments' end less the corner tolerance)
  double score = 0;               ///< px of segments along the three sides
  int corner_ends = 0;            ///< line ends at the two corners (of 4)
};

/// Quadrilateral board hypotheses from LSD segments merged into long lines (either polarity),
/// each list best first, at most options.max_line_hypotheses, every side partly inside the image.
struct LineQuads {
  std::vector<QuadHypothesis> best;  ///< of the options.max_lines best-supported lines
  /// of the further lines (up to options.max_lines_static_scene) with at least one side among
  /// them, where the lines end at the corners: to try when nothing else was the board
  std::vector<QuadHypothesis> ending_at_corners;
  /// the other quadrilaterals of those lines, whose segment score (support less the gaps) is below
  /// the best quadrilaterals' (a far or faint board's may be): to rank by their sides' gradient
  /// (at most a few dozen, unranked)
  std::vector<QuadHypothesis> faint;
  /// three sides ending at their two corners, the fourth to be traced in the image (best first)
  std::vector<ThreeSides> three_sides;
};

/// LSD's q for raw 8-bit pixels (its default): the bound of the error on a 2x2 gradient
/// component, twice what the rounding of integer grey levels makes.
constexpr double kLsdRawQuantization = 2.0;

/// With `expected`, only quadrilaterals whose corners all lie near the expected ones compete;
/// quadrilaterals of four `static_lines` (undistorted px) are not proposed. `lsd_quantization`:
/// LSD's q on the downscaled image (faintLineQuantization for a second, fainter search).
LineQuads lineQuadHypotheses(
    const cv::Mat& gray, const CameraModel& camera, const ImageBoardDetectorOptions& options,
    LineEvidence* evidence, const ExpectedBoard* expected = nullptr,
    const std::vector<std::array<Eigen::Vector2d, 2>>* static_lines = nullptr,
    double lsd_quantization = kLsdRawQuantization);

/// LSD's q for the faint-line search of an image of this noise (full-resolution grey levels), or
/// 0 when it would be no lower than the raw one (a noisy image: no fainter line is meaningful).
double faintLineQuantization(const ImageBoardDetectorOptions& options, int image_width,
                             double noise_sigma);

/// The line stage alone (an offline pre-pass of the static scene): every merged straight line a
/// session may learn from this image, support ends in undistorted px.
std::vector<std::array<Eigen::Vector2d, 2>> sceneLines(const cv::Mat& gray,
                                                       const CameraModel& camera,
                                                       const ImageBoardDetectorOptions& options);

/// Full-resolution px per px of the line stage's image (1: lines found at full resolution; also
/// when line detection is off).
double lineDetectionScale(const ImageBoardDetectorOptions& options, int image_width);

/// px: two straight lines of the line stage are one line when the ends of the shorter lie this
/// close to the longer (the merge band: a held board's bow, or the segment ends' noise at the
/// line detector's scale for this image width).
double sameLineTolerancePx(const ImageBoardDetectorOptions& options, int image_width);

/// One line (ends a, b) lies on the other within tolerance_px and their supports overlap.
bool sameLine(const std::array<Eigen::Vector2d, 2>& x, const std::array<Eigen::Vector2d, 2>& y,
              double tolerance_px);

/// Mean side length of a quadrilateral (px; corners in cyclic order).
double meanSidePx(const std::array<Eigen::Vector2d, kNumEdges>& corners);

/// Share of the quadrilateral `inner`'s area that lies inside `outer` (both convex, corners in
/// cyclic order; 0 for a degenerate inner).
double shareInside(const std::array<Eigen::Vector2d, kNumEdges>& inner,
                   const std::array<Eigen::Vector2d, kNumEdges>& outer);

/// Largest distance from a corner to its nearest reference corner (undistorted px).
double worstCornerOffset(const std::array<Eigen::Vector2d, kNumEdges>& corners,
                         const std::array<Eigen::Vector2d, kNumEdges>& reference);

/// How far a board's corners lie from what `expected` allows: from the nearest expected corner,
/// or (expected.inside) outside the expected quadrilateral. They fit within its tolerance.
double expectedOffset(const std::array<Eigen::Vector2d, kNumEdges>& corners,
                      const ExpectedBoard& expected);

/// Bounding box of the image border in undistorted px.
cv::Rect2d undistortedBounds(const CameraModel& camera);

/// Length of the segment p-q inside a box (Liang-Barsky clipping): a quick upper bound of the
/// visible length of a side.
double clippedLength(const Eigen::Vector2d& p, const Eigen::Vector2d& q, const cv::Rect2d& box);

/// True if an undistorted pixel lies inside the image (culled by its ray first: no fold-back).
/// `raw`, when given, receives the raw pixel the check projects (CameraModel::isVisible).
bool visibleUndistorted(const CameraModel& camera, const Eigen::Vector2d& u, double margin,
                        Eigen::Vector2d* raw = nullptr);

/// Part of the undistorted segment p-q inside the image (sampled), false if none.
bool visibleSideInterval(const CameraModel& camera, const Eigen::Vector2d& p,
                         const Eigen::Vector2d& q, double margin, Eigen::Vector2d* a,
                         Eigen::Vector2d* b);

/// Standard deviation of the image noise (grey levels), robust to edges and texture: median
/// absolute response of the Laplacian-difference mask of Immerkaer (1996), on every other row.
double estimateNoiseSigma(const cv::Mat& gray);

/// With `expected`, a second chance inside the projected board (ImageBoardDetector::detectNear);
/// with `excluded`, boards on static scene rectangles are not accepted. `grey_frame`: `gray` is
/// the frame's own grey image (not a colour contrast image, which stretches the board's, nor a
/// colour part's window); when nothing else is the board, it is also searched with a lower
/// line gradient bound (faintLineQuantization), and with `colour_challenge` (the frame's colour
/// can challenge a board found in grey: ImageBoardDetector searches it in colour) for the stable
/// regions' quadrilaterals (stableRegionQuads). `expected_is_prior`: `expected` comes from outside
/// this frame (the other sensor, the session), so its own quadrilateral is also tried as the
/// board, its sides searched as wide as it is uncertain; a single frame's colour part is not such
/// a prior (detectPlainInColourWindow).
void detectPlain(const cv::Mat& gray, const CameraModel& camera, const Target& target,
                 const ImageBoardDetectorOptions& options, ImageDetection* out,
                 const ExpectedBoard* expected = nullptr, const StaticScene* excluded = nullptr,
                 bool grey_frame = false, bool colour_challenge = false,
                 bool expected_is_prior = true);
/// Weakest edge gradient (grey levels per px) a board edge sample needs in an image of this noise.
double minEdgeGradient(const ImageBoardDetectorOptions& options, double noise_sigma);
/// A board found in another channel, its sides tested in the grey image: a coloured tile of a
/// scene grid ends at its corners in its colour but its grid lines run on in grey. False (reason
/// set, found cleared) for a scene rectangle.
bool sidesEndInGray(const cv::Mat& gray, const CameraModel& camera,
                    const ImageBoardDetectorOptions& options, double noise_sigma,
                    CameraBoardFeatures* features);
/// One channel in which the expected board stands out most of the ring around it: the bgr image
/// projected on Fisher's colour axis between the two (the board and ring means 100 grey levels
/// apart). Empty for a mono image or when the two do not differ.
cv::Mat boardContrastImage(const cv::Mat& bgr, const CameraModel& camera,
                           const ExpectedBoard& expected);
/// Per pixel and channel, the median of same-sized 8-bit images.
cv::Mat medianImage(const std::deque<cv::Mat>& frames);
/// Where a bgr frame departs from the scene's background (StaticScene::background, downscaled
/// bgr): a pixel whose largest channel difference exceeds 4 times the frame's median one (noise
/// and lighting drift). Empty mask when there is no background of this image's size.
struct Foreground {
  cv::Mat mask;        ///< 8-bit, the background's size
  double scale = 1.0;  ///< background px per image px
};
Foreground foregroundMask(const cv::Mat& bgr, const cv::Mat& background);
/// Board-sized, nearly convex parts of the foreground (openings cut the holder off, up to a
/// person's width for `target`'s size) as expected boards (ExpectedBoard::inside) that a board
/// may exceed by a quarter of its size. Largest first.
std::vector<ExpectedBoard> foregroundBoards(const Foreground& foreground, const CameraModel& camera,
                                            const Target& target,
                                            const ImageBoardDetectorOptions& options);
/// Where a bgr frame's colour (its two Lab chroma channels, downscaled to width_px) departs from
/// the frame's median colour by more than 4 times the median departure: a board of another colour
/// than most of the scene.
Foreground chromaDeparture(const cv::Mat& bgr, int width_px);
/// A single frame's board-sized, nearly convex parts of one colour (chromaDeparture) as expected
/// boards (ExpectedBoard::inside), largest first, parts cut by the image border last: a board of
/// the scene's grey but another colour.
std::vector<ExpectedBoard> colourPartBoards(const cv::Mat& bgr, const CameraModel& camera,
                                            const Target& target,
                                            const ImageBoardDetectorOptions& options);
/// A plain board searched in `place`'s colour contrast, only in the part of the frame around it
/// (the ring the contrast is measured against, 2 board sizes about its centre, grown by the
/// place's tolerance), at the whole frame's scale: the principal point moves with the window and
/// the downscaled widths shrink with it, so the window's pixels are processed as in the whole
/// frame. A board found must also pass sidesPartColours. `out` is in whole-frame pixels.
void detectPlainInColourWindow(const cv::Mat& bgr, const CameraModel& camera, const Target& target,
                               const ImageBoardDetectorOptions& options, const ExpectedBoard& place,
                               const StaticScene* excluded, ImageDetection* out);
/// In a colour contrast image (boardContrastImage: the board's mean and its ring's 100 levels
/// apart), every side must show a share of that contrast between a band just inside it and one
/// just outside: a quadrilateral of lines inside the board (printed marks, a holder's legs) has
/// board on both sides of one of them. Medians over the middle of each side, so an occluder over
/// part of it does not decide. False (reason set, found cleared) otherwise.
bool sidesPartColours(const cv::Mat& contrast, const CameraModel& camera,
                      CameraBoardFeatures* features);
void detectCheckerboard(const cv::Mat& gray, const CameraModel& camera, const Target& target,
                        const ImageBoardDetectorOptions& options, ImageDetection* out);

}  // namespace image_detection
}  // namespace board_calib
