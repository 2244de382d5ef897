// Private pieces of the plain-board detector (not installed): the hypotheses (regions of the
// downscaled image, line quadrilaterals), the sub-pixel edge refinement and the board checks.
#pragma once

#include "detection_internal.h"

#include <opencv2/core.hpp>

#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace board_calib {
namespace image_detection {

/// One proposed board region on the downscaled image.
struct RegionCandidate {
  std::vector<cv::Point> contour;
  double score = 0;
};

/// Board region proposals on the downscaled image.
struct Segmentation {
  cv::Mat blurred;
  std::vector<RegionCandidate> candidates;       ///< board-like regions, best first
  std::vector<std::vector<cv::Point>> rejected;  ///< large regions that are not board-like
  int proposals = 0;
  std::string last_rejection = "no region large enough";
  double min_area = 0;

  std::string reason() const {
    return proposals == 0 ? "board not found: no region large enough"
                          : "board not found: " + last_rejection;
  }
  void add(const std::vector<cv::Point>& contour, const ImageBoardDetectorOptions& o,
           bool keep_rejected);
  void sort();
};

/// Proposes board regions from brightness (Otsu, both polarities) and uniformity, of at least
/// `min_area` downscaled px (0: the options' fraction of the image).
Segmentation segmentBoard(const cv::Mat& small, const ImageBoardDetectorOptions& o,
                          double min_area = 0);

/// The parts of a region (a contour in an image of `size`) left by openings at fractions of its
/// inradius: a board with a thinner neighbour attached (a ceiling band, the holder's legs), and
/// with `holder_fraction` (holderOpeningFraction) the person holding it.
std::vector<std::vector<cv::Point>> openedParts(const std::vector<cv::Point>& contour,
                                                cv::Size size, double min_area,
                                                double holder_fraction = 0.0);
/// The opening, as a fraction of a board's inradius, that cuts the person holding `target` off
/// a part holding both (in [0.5, 0.9]; 0 for a board without a size).
double holderOpeningFraction(const Target& target);

/// Why a board at this pose is no calibration view: farther than max_board_distance_m or turned
/// past max_board_tilt_deg from the line of sight; empty when it is plausible.
std::string implausiblePlace(const Target& target, const ImageBoardDetectorOptions& o,
                             const Eigen::Isometry3d& camera_T_board);

/// Quadrilaterals of the maximally stable extremal regions of the downscaled image (`sx`: full px
/// per downscaled px) smaller than `max_area` downscaled px: small boards in clutter. Corners in
/// undistorted full-resolution px, best first. `seg`: the segmentation of the same image (its
/// blurred copy judges uniformity).
std::vector<QuadHypothesis> stableRegionQuads(const cv::Mat& small, const Segmentation& seg,
                                              double sx, const CameraModel& camera,
                                              const ImageBoardDetectorOptions& o, double max_area);

/// Second chance: openings of the rejected regions replace the candidates.
void proposeOpenedRegions(cv::Size size, const ImageBoardDetectorOptions& o, Segmentation* seg);

/// floor for in-image coordinates, without a libm call per sample.
inline int floorInt(double v) {
  const int i = static_cast<int>(v);
  return i > v ? i - 1 : i;
}

/// Bilinear grey value at (x, y) (pixel centres at integers); the caller keeps (x, y) at least
/// one pixel inside the image.
inline double sampleBilinear(const cv::Mat& gray, double x, double y) {
  const int x0 = floorInt(x), y0 = floorInt(y);
  const double fx = x - x0, fy = y - y0;
  const uchar* r0 = gray.ptr<uchar>(y0);
  const uchar* r1 = gray.ptr<uchar>(y0 + 1);
  return (1 - fy) * ((1 - fx) * r0[x0] + fx * r0[x0 + 1]) +
         fy * ((1 - fx) * r1[x0] + fx * r1[x0 + 1]);
}

/// One straight side of a hypothesis.
struct CoarseEdge {
  Eigen::Vector2d a = Eigen::Vector2d::Zero(),
                  b = Eigen::Vector2d::Zero();  ///< raw full-resolution px
  double angle = 0;                             ///< outward normal angle, rad
  double length = 0;                            ///< px; 0 marks a stretch along the image border
  bool a_corner = true,
       b_corner = true;  ///< an end at a board corner (not where the image cuts the side)
  /// px, half width of the first edge search across the side; 0: the options' coarse_search_px.
  /// Wider for a side projected from the other sensor's board (its prior's uncertainty).
  double search_px = 0;
};

/// One board hypothesis: its straight sides (raw px; in cyclic order when there are four) and a
/// point inside it (undistorted px).
struct Hypothesis {
  std::vector<CoarseEdge> sides;
  Eigen::Vector2d inside_u = Eigen::Vector2d::Zero();
  Points2 outline_raw;
  const char* source = "";
  double max_rms_share = 1.0;  ///< of the corner misfit a board may have
};

Hypothesis fromRegion(const RegionCandidate& board, double sx, cv::Size small_size,
                      const CameraModel& camera, const ImageBoardDetectorOptions& o);
/// `weak`: a quadrilateral of lines that the line ranking passed over.
Hypothesis fromQuad(const QuadHypothesis& q, const CameraModel& camera,
                    const ImageBoardDetectorOptions& o, bool weak = false);

/// One side refined at full resolution.
struct EdgeFit {
  Eigen::Vector3d line = Eigen::Vector3d::Zero();
  Points2 raw_inliers;
  double rms = 0;
  double span = 0;
  double coverage = 0;         ///< inlier samples / sample positions inside the image
  double median_strength = 0;  ///< grey levels per px
  double bow = 0;              ///< px, sagitta of a parabola through the inliers over their span
  double bow_sigma = 0;        ///< px, its standard error (noise from neighbouring samples)
  /// px: in the first, widest pass, another line through the peaks as well supported lies this
  /// far from the fitted one at an end of the side (0: none)
  double rival_offset = 0;
  /// Positions along the side (px from its start) of a stretch left out of the fit (a hand's
  /// outline), if any.
  std::optional<std::pair<double, double>> dropped;
  /// px: refused as two edges along the side, how far the line moves when fitted on its longest
  /// stretch of inliers between steps (0: not refused so)
  double step_px = 0;
  std::string reason;
  bool valid = false;
};

/// A side refined once in a frame. Hypotheses share sides (line quadrilaterals with two corners
/// in common, the base of traced sides): the fit is the same, bit for bit, for another inside
/// point strictly on the inner side of every line the refinement oriented.
struct RefinedSide {
  CoarseEdge coarse;
  std::vector<Eigen::Vector3d> oriented;  ///< every line oriented by the inside point, in order
  EdgeFit fit;
};
using RefinedSides = std::vector<RefinedSide>;

/// Sub-pixel gradient peaks along the edge normal, a robust line through them (undistorted px).
/// `refined` (optional): the sides refined so far on this image with these options and
/// min_gradient, reused and extended.
EdgeFit refineEdge(const cv::Mat& gray, const CameraModel& camera, const CoarseEdge& coarse,
                   const Eigen::Vector2d& inside_u, const ImageBoardDetectorOptions& o,
                   double min_gradient, RefinedSides* refined = nullptr);

/// Fraction of the stretch [gap, gap + length] px past `corner` along `outward` (undistorted px)
/// where the side's line carries an edge of either polarity: a board side ends at its corners, a
/// scene line (window frame, floor) usually runs on, on the same line to 2 px. `positions`:
/// samples inside the image; `run_on_px`: px of the stretch that carry the edge.
double edgeContinuation(const cv::Mat& gray, const CameraModel& camera, const Eigen::Vector3d& line,
                        const Eigen::Vector2d& corner, const Eigen::Vector2d& outward,
                        double gap_px, double length_px, const ImageBoardDetectorOptions& o,
                        double min_gradient, int* positions, double* run_on_px);

/// Fraction of the side a-b (undistorted px, its corners' neighbourhoods skipped) whose normal
/// crosses an edge of either polarity within fine_search_px of it: a cheap look at the gradient
/// along a proposed side before its refinement. `refit`: within fine_search_px of the line that
/// the peaks of a coarse_search_px wide search fit (a side proposed a few px off its edge).
double edgeCoverage(const cv::Mat& gray, const CameraModel& camera, const Eigen::Vector2d& a,
                    const Eigen::Vector2d& b, const Eigen::Vector2d& inside,
                    const ImageBoardDetectorOptions& o, double min_gradient, bool refit = false);

/// px skipped at a corner end of a side `side_px` long: corners are rounded by the coarse stage
/// and crowded by the other side; at most a fraction of a short (far) side.
double cornerExclusionPx(const ImageBoardDetectorOptions& o, double side_px);

/// Least share of a found board's side, between its corners, that its edge's inliers span (less
/// the corner neighbourhoods the samples skip). The refinement measures coverage along the
/// hypothesis' side, which may be shorter (a region's outline cut by a hand): a board under
/// min_side_coverage here was seen only on part of a side, and its line there may follow
/// something beside the board.
double leastSpanShare(const CameraModel& camera, const ImageBoardDetectorOptions& options,
                      const ImageDetection& found);

/// Counts the corner ends past which a found board's side lines still carry an edge that would
/// itself count as a seen board edge; false (reason set) for a scene rectangle.
bool sidesEndAtCorners(const cv::Mat& gray, const CameraModel& camera,
                       const ImageBoardDetectorOptions& options, double min_gradient,
                       CameraBoardFeatures* features);

/// The fourth side of three board lines traced in the image (plain_trace.cpp): on the pencil of
/// lines the three give it (through the base's vanishing point), where gradient of either polarity
/// stands out of the band's own gradient noise along at least min_side_coverage of it, for board
/// aspects the declared size allows. Quadrilaterals (undistorted px), most covered first.
std::vector<QuadHypothesis> traceFourthSide(const cv::Mat& gray, const CameraModel& camera,
                                            const Target& target,
                                            const ImageBoardDetectorOptions& o,
                                            const ThreeSides& sides, double min_gradient);

/// Share of the segment p-q (undistorted px) that line segments (undistorted px, both ends within
/// tolerance_px of it) cover.
double segmentShareAlong(const std::vector<std::array<Eigen::Vector2d, 2>>& segments_u,
                         const Eigen::Vector2d& p, const Eigen::Vector2d& q, double tolerance_px);

/// Edge support of a fitted hypothesis: px of edge samples along the sides, and the lowest side
/// coverage.
struct CandidateSupport {
  double score = 0;
  double min_coverage = 0;
};

/// Fits edges, corners and pose to one hypothesis; false (reason in out) when it is not a board.
bool fitCandidate(const cv::Mat& gray, const CameraModel& camera, const Target& target,
                  const ImageBoardDetectorOptions& o, const Hypothesis& h, double min_gradient,
                  ImageDetection* out, CandidateSupport* support, RefinedSides* refined = nullptr);

}  // namespace image_detection
}  // namespace board_calib
