// Plain board, judging one hypothesis: its sides refined at full resolution, named, the corners
// a convex quadrilateral, and the four corners the image of a board of the declared size
// (PnP) at a plausible distance and tilt.
#include "plain_internal.h"

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>

namespace board_calib {
namespace image_detection {
namespace {

constexpr double kCornerMatchPx =
    1e-6;  // a clipped side end this close to its corner is the corner
constexpr double kSquareTolerance = 0.01;  // boards whose width and height differ less are square
// A board side ends at its corners; a window frame, door or floor line runs on. The stretch past
// each corner is searched over this fraction of the side, and over as many samples as an edge
// needs at least (continuationStretchPx).
constexpr double kContinuationFraction = 0.25;
// Measured on the augmented real frames (173 accepted true boards): with 5 or more testable ends
// a true board ran on at <= 2 (<= 1 of 8 with all eight testable), the office rectangles taken
// instead at 3-6 of 8. Far boards cut by the image border (4 testable ends) showed up to 4 of 4
// (clutter as close as the board is small), so fewer testable ends are not judged.
constexpr int kMinContinuingEnds = 3;
constexpr int kMinTestedEnds = 6;
constexpr double kWeakLinesRmsShare = 0.5;  // of the corner misfit (fromQuad)

// Names and refines the sides; returns the number of valid edges (support filled).
int refineSides(const cv::Mat& gray, const CameraModel& camera, const ImageBoardDetectorOptions& o,
                const Hypothesis& h, double min_gradient, ImageDetection* out,
                CandidateSupport* support, RefinedSides* refined) {
  CameraBoardFeatures& f = out->features;
  ImageDetectionDetails& d = out->details;
  const std::vector<CoarseEdge>& sides = h.sides;
  std::vector<double> angles, weights;
  for (const auto& s : sides) {
    angles.push_back(s.angle);
    weights.push_back(s.length);
  }
  const std::vector<int> names =
      nameEdges(angles, weights, sides.size() == static_cast<size_t>(kNumEdges));
  for (int j = 0; j < kNumEdges; ++j)
    d.edge_reason[j] = "not in the outline (outside the image or along its border)";
  for (size_t k = 0; k < sides.size(); ++k) {
    const int j = names[k];
    if (j < 0) continue;
    const EdgeFit fit = refineEdge(gray, camera, sides[k], h.inside_u, o, min_gradient, refined);
    f.edge_lines[j] = fit.line;
    f.edge_valid[j] = fit.valid;
    d.edge_points_raw[j] = fit.raw_inliers;
    d.edge_rms_px[j] = fit.rms;
    d.edge_bow_px[j] = fit.bow;
    d.edge_bow_sigma_px[j] = fit.bow_sigma;
    d.edge_span_px[j] = fit.span;
    d.edge_reason[j] = fit.reason;
    if (fit.valid) support->score += fit.coverage * sides[k].length;
    support->min_coverage = k == 0 ? fit.coverage : std::min(support->min_coverage, fit.coverage);
  }
  int valid = 0;
  for (int j = 0; j < kNumEdges; ++j) valid += f.edge_valid[j];
  return valid;
}

// The four corners must form a convex quadrilateral in clockwise image order with sides of a
// usable length; otherwise the edges were mislabelled or belong to something else.
bool convexCorners(const ImageBoardDetectorOptions& o, CameraBoardFeatures* f, double* perimeter) {
  *perimeter = 0;
  for (int j = 0; j < kNumEdges; ++j) {
    const Eigen::Vector2d e1 = f->corners_px[(j + 1) % 4] - f->corners_px[j];
    *perimeter += e1.norm();
    const Eigen::Vector2d e2 = f->corners_px[(j + 2) % 4] - f->corners_px[(j + 1) % 4];
    if (e1.x() * e2.y() - e1.y() * e2.x() <= 0) {
      f->reason = "board not found: edge lines do not form a convex quadrilateral";
      return false;
    }
    if (e1.norm() < o.min_board_size_px) {
      f->reason = cv::format("board too small: side %.0f px", e1.norm());
      return false;
    }
  }
  return true;
}

// PnP of the four corners; for a rectangular board also the naming one step round.
PoseFit boardPose(const Target& target, const ImageBoardDetectorOptions& o, ImageDetection* out) {
  CameraBoardFeatures& f = out->features;
  ImageDetectionDetails& d = out->details;
  const auto outer = target.outerCorners();
  const Points3 obj(outer.begin(), outer.end());
  const Points2 img(f.corners_px.begin(), f.corners_px.end());
  PoseFit pose = fitPose(obj, img, f.K, o.pixel_sigma_px);
  if (std::abs(target.width - target.height) <=
      kSquareTolerance * std::max(target.width, target.height))
    return pose;
  // A rectangular board held near upright (or turned by ~45 deg) is as close to a diamond with
  // its width on the upper right side as on the upper left: the naming one step round that
  // fits the declared width and height better decides (names shift cyclically, the image
  // order stays).
  const int shift = rotatedNamingShift(f.edge_lines);
  Points2 rotated(kNumEdges);
  for (int k = 0; k < kNumEdges; ++k) rotated[k] = f.corners_px[(k + shift) % kNumEdges];
  const PoseFit alternative = fitPose(obj, rotated, f.K, o.pixel_sigma_px);
  if (alternative.ok && (!pose.ok || alternative.rms_px < pose.rms_px)) {
    pose = alternative;
    auto rotate = [shift](auto& array) {
      auto copy = array;
      for (int k = 0; k < kNumEdges; ++k) array[k] = copy[(k + shift) % kNumEdges];
    };
    rotate(f.edge_lines);
    rotate(f.edge_valid);
    rotate(f.corners_px);
    rotate(d.edge_points_raw);
    rotate(d.edge_rms_px);
    rotate(d.edge_bow_px);
    rotate(d.edge_bow_sigma_px);
    rotate(d.edge_span_px);
    rotate(d.edge_reason);
  }
  return pose;
}

// The pose must fit the declared size and put the board at a plausible distance and tilt.
bool plausiblePose(const Target& target, const ImageBoardDetectorOptions& o, const PoseFit& pose,
                   double perimeter, double rms_share, ImageDetection* out) {
  CameraBoardFeatures& f = out->features;
  ImageDetectionDetails& d = out->details;
  if (!pose.ok) {
    f.reason = pose.reason;
    return false;
  }
  f.camera_T_board = pose.camera_T_board;
  f.plane = planeFromPose(pose.camera_T_board);
  f.reprojection_rms_px = pose.rms_px;
  d.pattern_errors_px = pose.errors_px;
  d.pose_covariance = pose.covariance;
  // Corner misfit grows with the board in the image (flex, a slightly wrong declared size).
  const double max_rms =
      rms_share *
      std::min(o.max_plain_corner_rms_px, o.max_plain_corner_rms_fraction * perimeter / kNumEdges);
  if (pose.rms_px > max_rms) {
    f.reason = cv::format("corners do not fit a %.3f x %.3f m board (rms %.2f px > %.2f)",
                          target.width, target.height, pose.rms_px, max_rms);
    return false;
  }
  f.reason = implausiblePlace(target, o, pose.camera_T_board);
  return f.reason.empty();
}

// px searched past a corner of a side `side` px long: a short side's ends are tested too, with
// one sample to spare for rounding. Without the floor a 47 px face of a ceiling beam escaped the
// test (ends of its short sides untested, fewer than kMinTestedEnds) while its 170 px sides ran
// on past 3 of their 4 ends (augmented real frames, a far rs16 case: taken for a board 14.7 m
// away once the search ranked more far lines).
double continuationStretchPx(double side, const ImageBoardDetectorOptions& o) {
  return std::max(kContinuationFraction * side, o.min_edge_points * o.sample_step_px);
}

}  // namespace

std::string implausiblePlace(const Target& target, const ImageBoardDetectorOptions& o,
                             const Eigen::Isometry3d& camera_T_board) {
  const Eigen::Vector3d centre = camera_T_board * target.center();
  const double tilt_deg =
      std::acos(
          std::min(1.0, std::abs(planeFromPose(camera_T_board).normal.dot(centre.normalized())))) *
      180.0 / M_PI;
  if (centre.norm() > o.max_board_distance_m)
    return cv::format("a %.3f x %.3f m board would be %.1f m away (max %.1f m): another rectangle",
                      target.width, target.height, centre.norm(), o.max_board_distance_m);
  if (tilt_deg > o.max_board_tilt_deg)
    return cv::format("board turned %.0f deg from the line of sight (max %.0f)", tilt_deg,
                      o.max_board_tilt_deg);
  return {};
}

bool sidesEndAtCorners(const cv::Mat& gray, const CameraModel& camera,
                       const ImageBoardDetectorOptions& o, double min_gradient,
                       CameraBoardFeatures* f) {
  int continuing = 0, tested = 0;
  for (int j = 0; j < kNumEdges; ++j) {
    const Eigen::Vector2d& start = f->corners_px[(j + 3) % 4];
    const Eigen::Vector2d& end = f->corners_px[j];
    const double side = (end - start).norm();
    const Eigen::Vector2d dir = (end - start) / side;
    for (int e = 0; e < 2; ++e) {
      int positions = 0;
      double run_on_px = 0;
      const double run_on =
          edgeContinuation(gray, camera, f->edge_lines[j], e ? start : end,
                           e ? Eigen::Vector2d(-dir) : dir, o.corner_exclusion_px,
                           continuationStretchPx(side, o), o, min_gradient, &positions, &run_on_px);
      if (positions < o.min_edge_points) continue;
      ++tested;
      // Running on as far as a side needs to count as seen, and as long as the shortest edge.
      continuing += run_on >= o.min_side_coverage && run_on_px >= o.min_edge_length_px;
    }
  }
  if (continuing < kMinContinuingEnds || tested < kMinTestedEnds) return true;
  f->reason =
      cv::format("a scene rectangle, not a board: its sides run on past %d of %d corner ends",
                 continuing, tested);
  return false;
}

double leastSpanShare(const CameraModel& camera, const ImageBoardDetectorOptions& o,
                      const ImageDetection& d) {
  const CameraBoardFeatures& f = d.features;
  double least = 1.0;
  for (int j = 0; j < kNumEdges; ++j) {
    const Eigen::Vector2d& p = f.corners_px[(j + 3) % 4];
    const Eigen::Vector2d& r = f.corners_px[j];
    Eigen::Vector2d a, b;
    if (!visibleSideInterval(camera, p, r, o.border_margin_px, &a, &b)) continue;
    const double visible = (b - a).norm(), exclusion = cornerExclusionPx(o, visible);
    const double sampled = visible - exclusion * (((a - p).norm() < kCornerMatchPx) +
                                                  ((b - r).norm() < kCornerMatchPx));
    if (sampled > 0) least = std::min(least, d.details.edge_span_px[j] / sampled);
  }
  return least;
}

namespace {

// Half width (px) of a quadrilateral's first edge search (lines, a traced side, stable regions:
// every fromQuad). In an image no wider than line_detection_width_px its lines are found at full
// resolution, as close to the edge as the fine passes search; searched coarse_search_px wide, a
// far board's side with grain along it meets the stripes inside as rivals (augmented real
// frames: far + low contrast + wood 5 -> 8 of 21 found). In wider images the lines come from a
// downscaled copy, and their quadrilaterals' sides from lines merged and extended to corners: in
// 960 px simulated frames a 5 px search found 23 more boards of 672 but took 4 scene squares (2
// others no longer).
double quadSearchPx(const CameraModel& camera, const ImageBoardDetectorOptions& o) {
  const bool full_resolution =
      o.line_detection_width_px > 0 && lineDetectionScale(o, camera.width()) == 1.0;
  return full_resolution ? std::min(o.fine_search_px, o.coarse_search_px) : o.coarse_search_px;
}

}  // namespace

Hypothesis fromQuad(const QuadHypothesis& q, const CameraModel& camera,
                    const ImageBoardDetectorOptions& o, bool weak) {
  Hypothesis h;
  h.source = weak ? kWeakLinesSource : "lines";
  // Lines past the best-supported ones carry no prior of being the board: a scene rectangle of
  // about the board's shape (a glass pane of the office fits a 0.8 x 0.6 m board to 8.4 px of
  // 10) must not pass on the lenient fit a held board's flex needs.
  if (weak) h.max_rms_share = kWeakLinesRmsShare;
  h.inside_u = 0.25 * (q.corners[0] + q.corners[1] + q.corners[2] + q.corners[3]);
  const double search_px = quadSearchPx(camera, o);
  for (int s = 0; s < kNumEdges; ++s) {
    Eigen::Vector2d a, b;
    const Eigen::Vector2d& p = q.corners[(s + 3) % 4];
    const Eigen::Vector2d& r = q.corners[s];
    if (!visibleSideInterval(camera, p, r, o.border_margin_px, &a, &b)) continue;
    CoarseEdge e;
    e.a_corner = (a - p).norm() < kCornerMatchPx;
    e.b_corner = (b - r).norm() < kCornerMatchPx;
    e.a = camera.distortPixel(a);
    e.b = camera.distortPixel(b);
    e.length = (b - a).norm();
    e.search_px = search_px;
    const Eigen::Vector3d l = lineThrough(a, b, h.inside_u);
    e.angle = std::atan2(l.y(), l.x());
    h.sides.push_back(e);
    h.outline_raw.push_back(e.a);
    h.outline_raw.push_back(e.b);
  }
  // Clockwise image order (v down) for the cyclic edge naming.
  if (h.sides.size() == static_cast<size_t>(kNumEdges)) {
    const Eigen::Vector2d e1 = q.corners[1] - q.corners[0], e2 = q.corners[2] - q.corners[1];
    if (e1.x() * e2.y() - e1.y() * e2.x() < 0) {
      std::reverse(h.sides.begin(), h.sides.end());
      for (auto& e : h.sides) {
        std::swap(e.a, e.b);
        std::swap(e.a_corner, e.b_corner);
      }
    }
  }
  return h;
}

bool fitCandidate(const cv::Mat& gray, const CameraModel& camera, const Target& target,
                  const ImageBoardDetectorOptions& o, const Hypothesis& h, double min_gradient,
                  ImageDetection* out, CandidateSupport* support, RefinedSides* refined) {
  CameraBoardFeatures& f = out->features;
  ImageDetectionDetails& d = out->details;
  *support = CandidateSupport{};
  d.outline_raw = h.outline_raw;
  if (h.sides.size() < 2) {
    f.reason = "board not found: " + std::to_string(h.sides.size()) +
               " straight board edge(s) in the outline";
    return false;
  }
  const double start = threadCpuMs();
  const int valid = refineSides(gray, camera, o, h, min_gradient, out, support, refined);
  d.stage_times.edges_ms = msSince(start);
  for (int j = 0; j < kNumEdges; ++j)
    if (f.edge_valid[j] && f.edge_valid[(j + 1) % 4] &&
        !intersectLines(f.edge_lines[j], f.edge_lines[(j + 1) % 4], &f.corners_px[j])) {
      f.reason = std::string("board not found: edges ") + edgeName(j) + " and " +
                 edgeName((j + 1) % 4) + " are parallel";
      return false;
    }
  if (valid < kNumEdges) {
    std::string why;
    for (int j = 0; j < kNumEdges; ++j)
      if (!f.edge_valid[j])
        why += std::string(why.empty() ? "" : "; ") + edgeName(j) + ": " + d.edge_reason[j];
    f.reason = "board edges missing (" + std::to_string(valid) + " of 4 valid): " + why;
    return false;
  }
  double perimeter = 0;
  if (!convexCorners(o, &f, &perimeter)) return false;
  if (!sidesEndAtCorners(gray, camera, o, min_gradient, &f)) return false;
  const PoseFit pose = boardPose(target, o, out);
  if (!plausiblePose(target, o, pose, perimeter, h.max_rms_share, out)) return false;
  f.found = true;
  return true;
}

}  // namespace image_detection
}  // namespace board_calib
