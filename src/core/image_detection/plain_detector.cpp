// Plain board (PBPC-Cal): board hypotheses from two sources, brightness/uniformity regions on a
// downscaled image (plain_regions.cpp) and quadrilaterals of long straight edges (LSD segments,
// line_hypotheses.cpp). Each hypothesis's sides are refined at full resolution by sub-pixel
// gradient peaks (plain_edges.cpp); a hypothesis is the board when every visible side shows its
// edge over most of its length, the lines form a convex quadrilateral and the four corners fit a
// board of the declared width and height (plain_candidate.cpp). The best-supported one wins.
#include "plain_internal.h"

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <limits>

namespace board_calib {
namespace image_detection {
namespace {

// Near an expected board, a region is tried down to this share of its area (a board partly
// hidden by a hand, or whose expected corners are a quarter of its size off).
constexpr double kExpectedAreaShare = 0.25;

constexpr double kCleanBoardCoverage =
    0.9;  // a region board this well evidenced on every side needs no line search
// The edge gradient is a difference of two samples 1 px apart: its noise is sqrt(2) x the pixel
// noise.
constexpr double kGradientNoiseGain = 1.41421356;
constexpr double kDuplicateHypothesisFraction =
    0.05;  // of the board size: hypotheses this close are one

// The last line search, for boards too small at line_detection_width_px, runs at this multiple of
// it (capped at the image width) and only where that is this much finer. Measured on the
// augmented real frames: 221 -> 225 of 252, none wrong (rs16 under legs 2 -> 5), rs16_plain's
// CPU per frame +12 ms on average; at 3x no more frames at 1.5x the time.
constexpr double kFineLineScale = 2.0;
constexpr double kMinFineLineGain = 1.25;

// Stable regions (stableRegionQuads) up to this multiple of the smallest region the segmentation
// proposes: the boards too small for it, and those it merges with a neighbour of their grey.
// Measured on the augmented real frames: 225 -> 227 of 252 (far rs16 boards), none wrong; MSER
// takes 7-10 ms of the 480 px image where it runs (rs16_plain's region stage +1.4 ms per frame on
// average).
constexpr double kStableRegionAreaFactor = 4.0;
// Downscaled px: how well a stable region's simplified outline places a corner.
constexpr double kCoarseCornerPx = 1.5;
// QuadHypothesis::corner_ends of a quadrilateral whose lines both end at three of its corners.
constexpr int kThreeCornersEnds = 2 * (kNumEdges - 1);
// Stable regions alike: mean sides and aspect (the ratio of opposite side pairs) within this
// share of each other, and the steps of a row of them equal to it of the side. A facade's
// windows are cut and spaced alike to well within it.
constexpr double kAlikeShare = 0.15;
constexpr double kAlikeTurnDeg = 5.0;
// Stable regions side by side share a side: its two corners within this share of the smaller
// region's mean side (plus kCoarseCornerPx) of the other's two. Tiles and wall panels lie apart
// by their grout or seam, 1-3 % of their side.
constexpr double kSharedCornerShare = 0.1;
// A scene's copies of one rectangle (tiles, panels, windows) are made alike to within this share
// of their size, beyond what their corners' placement leaves unknown.
constexpr double kCopyShare = 0.05;
// Two outlines cross where their shared area is more than this share of the smaller one and less
// than all but it: a touch at a corner or a side's blur is no crossing, nor is one inside the
// other.
constexpr double kCrossingShare = 0.05;

// Corners (undistorted px) of one board, to within kDuplicateHypothesisFraction of its size.
bool sameBoard(const std::array<Eigen::Vector2d, 4>& corners,
               const std::array<Eigen::Vector2d, 4>& board) {
  double worst = 0, size = 0;
  for (int s = 0; s < kNumEdges; ++s) {
    double nearest = std::numeric_limits<double>::infinity();
    for (int t = 0; t < kNumEdges; ++t) nearest = std::min(nearest, (corners[s] - board[t]).norm());
    worst = std::max(worst, nearest);
    size += (board[(s + 1) % 4] - board[s]).norm() / kNumEdges;
  }
  return worst < kDuplicateHypothesisFraction * size;
}

// Two convex outlines that overlap without one lying (nearly) inside the other.
bool outlinesCross(const std::array<Eigen::Vector2d, 4>& a,
                   const std::array<Eigen::Vector2d, 4>& b) {
  std::vector<cv::Point2f> pa, pb, shared;
  for (const auto& c : a) pa.emplace_back(static_cast<float>(c.x()), static_cast<float>(c.y()));
  for (const auto& c : b) pb.emplace_back(static_cast<float>(c.x()), static_cast<float>(c.y()));
  const double smaller = std::min(cv::contourArea(pa), cv::contourArea(pb));
  if (!(smaller > 0)) return false;
  const double share = cv::intersectConvexConvex(pa, pb, shared) / smaller;
  return share > kCrossingShare && share < 1.0 - kCrossingShare;
}

// Every hypothesis tried; the accepted one with the most edge support wins (of two that cross, the
// better fit). When none is a board, the attempt that got furthest (most valid edges, then the
// more edge support) gives the reason.
struct HypothesisSearch {
  ImageDetection best_found, best_miss;
  double best_score = -1, best_miss_score = -1, best_min_coverage = 0, best_span_share = 0;
  int best_valid = -1, best_miss_index = -1;
  std::vector<std::array<Eigen::Vector2d, 4>> tried;
  std::vector<std::string> reasons;
  std::vector<std::array<Eigen::Vector2d, 4>> boards;  // passed the board checks
  std::vector<ImageDetection> accepted;                // and were not excluded

  bool found() const { return best_score > 0; }
  bool cleanBoard() const { return found() && best_min_coverage >= kCleanBoardCoverage; }
  // A board whose edges span the share of each side between its corners that a side must show
  // (leastSpanShare): the weaker hypotheses, and those at its own place, need not be tried. A
  // board seen on part of a side only may have followed something beside it there (a far
  // board's side pulled onto the hand holding it, 9.2 px off at its end): those may refit it,
  // and the one with more edge support wins.
  bool settled(double min_side_coverage) const {
    return found() && best_span_share >= min_side_coverage;
  }

  // A line quadrilateral on the accepted board adds nothing.
  bool duplicatesBoard(const std::array<Eigen::Vector2d, 4>& corners) const {
    return found() && sameBoard(corners, best_found.features.corners_px);
  }

  // Two accepted boards whose outlines cross (each reaching out of the other) cannot both be the
  // board: the one whose corners fit the declared size better is kept, not the longer outline. A
  // scene rectangle through the board fits it by turning far (augmented real frames, fresh draw
  // 23: a wall and floor frame around the board at 4.39 px won over the board at 0.99 px).
  // Nested outlines keep the edge support's choice: a board's inset print is no board.
  void keepTheBetterFitWhereBoardsCross() {
    if (!found()) return;
    const ImageDetection* better = nullptr;
    double rms = best_found.features.reprojection_rms_px;
    for (const ImageDetection& other : accepted) {
      const auto& corners = other.features.corners_px;
      if (other.features.reprojection_rms_px >= rms ||
          sameBoard(corners, best_found.features.corners_px) ||
          !outlinesCross(corners, best_found.features.corners_px))
        continue;
      rms = other.features.reprojection_rms_px;
      better = &other;
    }
    if (better) best_found = *better;
  }

  void record(const Hypothesis& h, const std::array<Eigen::Vector2d, 4>& corners, bool is_board,
              const CandidateSupport& support, double span_share, ImageDetection&& attempt) {
    const CameraBoardFeatures& af = attempt.features;
    tried.push_back(corners);
    reasons.push_back(std::string(h.source) + ": " + (is_board ? "board" : af.reason));
    if (is_board) {
      // Of two boards, a steeply turned one is the likelier other rectangle (a door or the
      // holder's legs seen edge-on fit a board only near the largest turn): support is weighed
      // by the cosine of the turn from the line of sight.
      const double score = support.score * facingCosine(af.camera_T_board);
      attempt.details.board_source = h.source;
      attempt.details.board_support_px = score;
      accepted.push_back(attempt);
      if (score > best_score) {
        best_score = score;
        best_min_coverage = support.min_coverage;
        best_span_share = span_share;
        best_found = std::move(attempt);
      }
      return;
    }
    int valid = 0;
    for (int j = 0; j < kNumEdges; ++j) valid += af.edge_valid[j];
    if (valid > best_valid || (valid == best_valid && support.score > best_miss_score)) {
      best_valid = valid;
      best_miss_score = support.score;
      best_miss = std::move(attempt);
      best_miss_index = static_cast<int>(tried.size()) - 1;
    }
  }
};

cv::Mat downscale(const cv::Mat& gray, double width_px) {
  const double scale = std::max(1.0, static_cast<double>(gray.cols) / width_px);
  if (scale <= 1.0) return gray;
  cv::Mat small;
  cv::resize(gray, small,
             cv::Size(static_cast<int>(std::lround(gray.cols / scale)),
                      static_cast<int>(std::lround(gray.rows / scale))),
             0, 0, cv::INTER_AREA);
  return small;
}

// Inside the expected board (or within its tolerance of it): a region hypothesis's centre.
bool nearExpected(const Eigen::Vector2d& point, const ExpectedBoard& expected) {
  std::vector<cv::Point2f> polygon;
  for (const auto& c : expected.corners_px)
    polygon.emplace_back(static_cast<float>(c.x()), static_cast<float>(c.y()));
  std::vector<cv::Point2f> hull;
  cv::convexHull(polygon, hull);
  return cv::pointPolygonTest(
             hull, cv::Point2f(static_cast<float>(point.x()), static_cast<float>(point.y())),
             true) >= -expected.tolerance_px;
}

// A board that the prior does not put there is another rectangle.
void checkExpected(const ExpectedBoard& expected, ImageDetection* attempt) {
  CameraBoardFeatures& f = attempt->features;
  const double off = expectedOffset(f.corners_px, expected);
  if (off <= expected.tolerance_px) return;
  f.found = false;
  f.reason = expected.inside
                 ? cv::format(
                       "a board reaching %.0f px out of the part of the frame that moved "
                       "(tolerance %.0f px)",
                       off, expected.tolerance_px)
                 : cv::format(
                       "a board %.0f px from where the prior extrinsic puts it (tolerance "
                       "%.0f px)",
                       off, expected.tolerance_px);
}

// A board where the session has seen a static scene rectangle is that rectangle.
bool onStaticRectangle(const StaticScene& excluded, ImageDetection* attempt) {
  CameraBoardFeatures& f = attempt->features;
  for (const StaticRectangle& r : excluded.rectangles) {
    if (worstCornerOffset(f.corners_px, r.corners_px) > r.tolerance_px) continue;
    f.found = false;
    f.reason =
        cv::format("a static scene rectangle, seen at the same place for %.0f s", r.seen_for_s);
    return true;
  }
  return false;
}

// fitCandidate, its CPU time split between the edge refinement (timed inside it) and the rest.
bool timedFit(const cv::Mat& gray, const CameraModel& camera, const Target& target,
              const ImageBoardDetectorOptions& o, const Hypothesis& h, double min_gradient,
              ImageDetection* attempt, CandidateSupport* support, RefinedSides* refined,
              PlainStageTimes* times) {
  const bool fits = timed(&times->fits_ms, [&] {
    return fitCandidate(gray, camera, target, o, h, min_gradient, attempt, support, refined);
  });
  times->edges_ms += attempt->details.stage_times.edges_ms;
  times->fits_ms -= attempt->details.stage_times.edges_ms;
  return fits;
}

// A fitted board stays the board where the prior expects it and off the static rectangles; every
// fitted board is recorded (the static ones too).
bool keptBoard(const ExpectedBoard* expected, const StaticScene* excluded, ImageDetection* attempt,
               HypothesisSearch* search) {
  if (expected) {
    checkExpected(*expected, attempt);
    if (!attempt->features.found) return false;
  }
  search->boards.push_back(attempt->features.corners_px);
  return !(excluded && onStaticRectangle(*excluded, attempt));
}

// Hypotheses of three lines with the fourth side traced (weak: no prior of being the board). A
// traced side is for a side without line evidence: where the line detector's segments run along
// as much of it as a quadrilateral's side needs, the line quadrilaterals had their chance
// (measured: the simulated street's window frames, 4-12 wrong boards without this rule).
void addTracedSides(const cv::Mat& gray, const CameraModel& camera, const Target& target,
                    const ImageBoardDetectorOptions& o, const LineEvidence& evidence,
                    const ExpectedBoard* expected, double min_gradient,
                    std::vector<ThreeSides>* chains, std::vector<Hypothesis>* hypotheses,
                    std::vector<QuadHypothesis>* quads) {
  const double tolerance = sameLineTolerancePx(o, gray.cols);
  for (const ThreeSides& sides : *chains)
    for (QuadHypothesis& q : traceFourthSide(gray, camera, target, o, sides, min_gradient)) {
      if (segmentShareAlong(evidence.segments_u, q.corners[2], q.corners[3], tolerance) >=
          kLineCoverageShare * o.min_side_coverage)
        continue;
      if (expected && expectedOffset(q.corners, *expected) > expected->tolerance_px) continue;
      Hypothesis h = fromQuad(q, camera, o, true);
      h.source = "traced side";
      hypotheses->push_back(std::move(h));
      quads->push_back(std::move(q));
    }
  chains->clear();
}

// The weak lines' quadrilaterals whose every visible side shows its edge along most of its length,
// best covered first, at most max_line_hypotheses. Their segments may cover little of a far or
// faint board's sides, the gradient does not; but these lines carry no prior of being the board,
// so a side must show more than the refinement's min_side_coverage: halfway from it to the whole
// side. Measured (a look along each side, fine_search_px wide): sides of boards on the augmented
// real frames 0.81-0.97 at the least covered side; the simulated street's facade rectangles and
// the office's panes 0.67 at most. A hand or a leg over the board hides a stretch of one side,
// and that side's line stops short of the corner it hides: where the lines end at three corners
// (kThreeCornersEnds), one side need only show what the refinement asks of every side.
void rankByEdgeCoverage(const cv::Mat& gray, const CameraModel& camera,
                        const ImageBoardDetectorOptions& o, double min_gradient,
                        std::vector<QuadHypothesis>* quads) {
  const double min_coverage = 0.5 * (1.0 + o.min_side_coverage);
  std::vector<std::pair<double, QuadHypothesis>> ranked;
  for (QuadHypothesis& q : *quads) {
    const Eigen::Vector2d inside =
        0.25 * (q.corners[0] + q.corners[1] + q.corners[2] + q.corners[3]);
    const double least_needed =
        q.corner_ends >= kThreeCornersEnds ? o.min_side_coverage : min_coverage;
    double least = 1.0, second = 1.0, sum = 0.0;
    const auto covered = [&] { return least >= least_needed && second >= min_coverage; };
    for (int s = 0; s < kNumEdges && covered(); ++s) {
      Eigen::Vector2d a, b;
      if (!visibleSideInterval(camera, q.corners[(s + 3) % 4], q.corners[s], o.border_margin_px, &a,
                               &b))
        continue;
      double c = edgeCoverage(gray, camera, a, b, inside, o, min_gradient);
      // A merged line may leave its side several px off at a corner (the wide-angle lens'
      // residual bends a long edge): the side is looked at again around its own peaks' line.
      if (c < min_coverage)
        c = std::max(c, edgeCoverage(gray, camera, a, b, inside, o, min_gradient, true));
      second = std::min(second, std::max(least, c));
      least = std::min(least, c);
      sum += c;
    }
    if (covered()) ranked.emplace_back(sum, std::move(q));
  }
  std::stable_sort(ranked.begin(), ranked.end(),
                   [](const auto& x, const auto& y) { return x.first > y.first; });
  quads->clear();
  for (auto& r : ranked) {
    if (static_cast<int>(quads->size()) >= o.max_line_hypotheses) break;
    quads->push_back(std::move(r.second));
  }
}

struct ShapedQuad {
  double rms_share;  // corner fit rms per px of mean side
  Eigen::Isometry3d camera_T_board;
  QuadHypothesis quad;
};

// Whether `q`'s corners fit a board of the declared size, to `corner_px` (what the corners are
// known to) or the detector's own corner bound when that is larger, within max_board_distance_m
// and max_board_tilt_deg: the better fit of either naming (rms per px of mean side, and the pose)
// in `fit`.
bool fitsDeclaredBoard(const Target& target, const CameraModel& camera,
                       const ImageBoardDetectorOptions& o, double corner_px,
                       const QuadHypothesis& q, ShapedQuad* fit) {
  const auto outer = target.outerCorners();
  const Points3 obj(outer.begin(), outer.end());
  const double side = meanSidePx(q.corners);
  const double bound = std::max(corner_px, o.max_plain_corner_rms_fraction * side);
  fit->rms_share = std::numeric_limits<double>::infinity();
  // Clockwise in the image (v down), as the edge naming orders a board's corners; either
  // naming of a rectangular board (boardPose; a square one fits both alike).
  const Eigen::Vector2d e1 = q.corners[1] - q.corners[0], e2 = q.corners[2] - q.corners[1];
  const int step = e1.x() * e2.y() - e1.y() * e2.x() < 0 ? kNumEdges - 1 : 1;
  for (int shift = 0; shift < 2; ++shift) {
    Points2 img;
    for (int k = 0; k < kNumEdges; ++k) img.push_back(q.corners[(shift + k * step) % kNumEdges]);
    const PoseFit pose = fitPose(obj, img, camera.K(), o.pixel_sigma_px);
    if (!pose.ok || pose.rms_px > bound) continue;
    if (implausiblePlace(target, o, pose.camera_T_board).empty() &&
        pose.rms_px / side < fit->rms_share) {
      fit->rms_share = pose.rms_px / side;
      fit->camera_T_board = pose.camera_T_board;
    }
  }
  return std::isfinite(fit->rms_share);
}

// The stable regions' quadrilaterals that could be the declared board (to what a corner of the
// downscaled image is known, kCoarseCornerPx of it); best fit first, with the pose. A scene's
// stable regions are mostly cells of other shapes or sizes (windows, tiles, a gap between
// frames), and only the first max_line_hypotheses are refined.
std::vector<ShapedQuad> boardShaped(const Target& target, const CameraModel& camera,
                                    const ImageBoardDetectorOptions& o, double sx,
                                    std::vector<QuadHypothesis> quads) {
  std::vector<ShapedQuad> kept;
  for (QuadHypothesis& q : quads) {
    ShapedQuad fit;
    if (!fitsDeclaredBoard(target, camera, o, kCoarseCornerPx * sx, q, &fit)) continue;
    fit.quad = std::move(q);
    kept.push_back(std::move(fit));
  }
  std::stable_sort(kept.begin(), kept.end(), [](const ShapedQuad& a, const ShapedQuad& b) {
    return a.rms_share < b.rms_share;
  });
  return kept;
}

// The weak lines' quadrilaterals to try: those that could be the declared board, ranked by their
// sides' gradient (rankByEdgeCoverage). Only max_line_hypotheses are refined, and a scene's
// windows and doors of another shape, whose sides show their edges all along, took every place
// before a far board with a hand over one side. Their corners are known to kCoarseCornerPx of
// the line search's downscaled image (`line_scale` full-resolution px per px) or to the first
// edge search's half width (coarse_search_px), whichever is coarser: a quadrilateral further off
// a board than its sides are searched is not refined into it.
void rankWeakQuads(const cv::Mat& gray, const CameraModel& camera, const Target& target,
                   const ImageBoardDetectorOptions& o, double min_gradient, double line_scale,
                   std::vector<QuadHypothesis>* quads) {
  const double corner_px = std::max(kCoarseCornerPx * line_scale, o.coarse_search_px);
  ShapedQuad fit;
  quads->erase(std::remove_if(quads->begin(), quads->end(),
                              [&](const QuadHypothesis& q) {
                                return !fitsDeclaredBoard(target, camera, o, corner_px, q, &fit);
                              }),
               quads->end());
  rankByEdgeCoverage(gray, camera, o, min_gradient, quads);
}

// Where the ray through undistorted pixel u meets the board plane of camera_T_board, in board
// coordinates; false when it does not (parallel, or behind the camera). K_inv: the camera
// matrix's inverse.
bool onBoardPlane(const Eigen::Matrix3d& K_inv, const Eigen::Isometry3d& camera_T_board,
                  const Eigen::Vector2d& u, Eigen::Vector2d* board_xy) {
  const Eigen::Vector3d ray = K_inv * Eigen::Vector3d(u.x(), u.y(), 1.0);
  const Eigen::Vector3d n = camera_T_board.linear().col(2);
  const Eigen::Vector3d p = camera_T_board.translation();
  const double along = n.dot(ray);
  if (std::abs(along) < 1e-12) return false;
  const double t = n.dot(p) / along;
  if (!(t > 0)) return false;
  *board_xy = (camera_T_board.inverse() * (t * ray)).head<2>();
  return true;
}

// Drops the board-shaped stable regions that have copies in their own plane: other stable regions
// that, placed on the plane the board fit gives, are rectangles of the board's size turned alike,
// one in a row or column with it or two anywhere, as a grid's cells stand. A facade's windows, a
// wall's panels and a floor's tiles repeat in their plane however the perspective shrinks them
// (dropRepeated needs them alike in the image); a board held in the air has no copy in its plane.
// Measured (test_fuzz_detectors' view sets, rounds 0-5): square windows, tiles and panels taken
// for square and 4:3 boards, normals 25-88 deg off, in 21 frames, 7 after. A scene's rectangles
// of about the board's image size (the far board behind window frames) are seldom turned alike.
void dropCopiesInTheirPlane(const Target& target, const CameraModel& camera, double sx,
                            const std::vector<QuadHypothesis>& all,
                            std::vector<ShapedQuad>* shaped) {
  const double w = std::max(target.width, target.height);
  const double h = std::min(target.width, target.height);
  const Eigen::Vector2d middle = target.center().head<2>();
  const Eigen::Matrix3d K_inv = camera.K().inverse();
  std::vector<ShapedQuad> kept;
  for (ShapedQuad& s : *shaped) {
    int in_line = 0, aligned = 0;
    for (const QuadHypothesis& other : all) {
      std::array<Eigen::Vector2d, kNumEdges> xy;
      bool placed = true;
      for (int k = 0; k < kNumEdges && placed; ++k)
        placed = onBoardPlane(K_inv, s.camera_T_board, other.corners[k], &xy[k]);
      if (!placed) continue;
      const Eigen::Vector2d step = 0.25 * (xy[0] + xy[1] + xy[2] + xy[3]) - middle;
      if (step.norm() < h) continue;  // itself, or inside it
      // Each quadrilateral's corners, kCoarseCornerPx off, move its sides (and the plane) by
      // that share of them.
      const double tolerance =
          kCopyShare + kCoarseCornerPx * sx *
                           (1.0 / meanSidePx(other.corners) + 1.0 / meanSidePx(s.quad.corners));
      const auto near = [&](double x, double y) { return std::abs(x - y) <= tolerance * y; };
      const double a = 0.5 * ((xy[1] - xy[0]).norm() + (xy[3] - xy[2]).norm());
      const double b = 0.5 * ((xy[2] - xy[1]).norm() + (xy[0] - xy[3]).norm());
      const double d0 = (xy[2] - xy[0]).norm(), d1 = (xy[3] - xy[1]).norm();
      const Eigen::Vector2d first = xy[1] - xy[0];
      const double turn = std::fmod(std::atan2(first.y(), first.x()) * 180.0 / M_PI + 360.0, 90.0);
      if (!near(std::max(a, b), w) || !near(std::min(a, b), h) ||
          !near(std::max(d0, d1), std::min(d0, d1)) ||
          std::min(turn, 90.0 - turn) > kAlikeTurnDeg + tolerance * 180.0 / M_PI)
        continue;
      ++aligned;
      in_line += std::min(std::abs(step.x()), std::abs(step.y())) <= tolerance * h;
    }
    if (in_line == 0 && aligned < 2) kept.push_back(std::move(s));
  }
  *shaped = std::move(kept);
}

// Drops the stable regions the scene repeats: three alike (mean side and aspect within
// kAlikeShare, sides within kAlikeTurnDeg of the same direction) in a row at equal steps, as a
// facade's windows or a shelf's cells stand. A street's windows are as board-shaped as the
// board, and a far one passed every check of a board 14 m away while the real, heavily grained
// board 4 m away was missed (test_fuzz_detectors, hostile view sets). A board among window cells
// of its size is alike but not in their rows.
void dropRepeated(std::vector<ShapedQuad>* quads) {
  struct Shape {
    Eigen::Vector2d centre;
    double side, aspect, turn;
  };
  std::vector<Shape> shapes;
  for (const ShapedQuad& q : *quads) {
    const auto& c = q.quad.corners;
    const double a = (c[1] - c[0]).norm() + (c[3] - c[2]).norm();
    const double b = (c[2] - c[1]).norm() + (c[0] - c[3]).norm();
    const Eigen::Vector2d d = c[1] - c[0];
    // Direction of the first side modulo a quarter turn (a cell named from another corner).
    const double turn = std::fmod(std::atan2(d.y(), d.x()) * 180.0 / M_PI + 360.0, 90.0);
    shapes.push_back({0.25 * (c[0] + c[1] + c[2] + c[3]), meanSidePx(c),
                      std::max(a, b) / std::max(1e-9, std::min(a, b)), turn});
  }
  auto near = [](double x, double y) { return std::abs(x - y) <= kAlikeShare * std::max(x, y); };
  auto alike = [&](size_t i, size_t j) {
    const double dt = std::abs(shapes[i].turn - shapes[j].turn);
    return i != j && near(shapes[i].side, shapes[j].side) &&
           near(shapes[i].aspect, shapes[j].aspect) && std::min(dt, 90.0 - dt) <= kAlikeTurnDeg &&
           (shapes[i].centre - shapes[j].centre).norm() > shapes[i].side;
  };
  std::vector<ShapedQuad> kept;
  for (size_t i = 0; i < quads->size(); ++i) {
    bool repeated = false;
    const double step_tolerance = kAlikeShare * shapes[i].side;
    for (size_t j = 0; j < quads->size() && !repeated; ++j) {
      if (!alike(i, j)) continue;
      const Eigen::Vector2d step = shapes[j].centre - shapes[i].centre;
      for (size_t k = 0; k < quads->size() && !repeated; ++k) {
        if (k == j || !alike(i, k)) continue;
        // i between j and k, or j between i and k, at equal steps.
        repeated = (shapes[i].centre - shapes[k].centre - step).norm() <= step_tolerance ||
                   (shapes[k].centre - shapes[j].centre - step).norm() <= step_tolerance;
      }
    }
    if (!repeated) kept.push_back(std::move((*quads)[i]));
  }
  *quads = std::move(kept);
}

// Drops the stable regions that tile the scene with another: a wall of panels or a floor of tiles
// lies cell beside cell, each sharing a whole side with its neighbour across that side, and a
// square tile fits a square board as well as the board does (test_fuzz_detectors' view sets: a
// tiled room's panels and tiles taken in 27 of 42 frames, normals 18-85 deg off). A board held
// in the air meets no region corner to corner; a region inside it (a print, a shaded half) lies
// on the same side of their shared side and is kept.
void dropTiled(double corner_px, std::vector<QuadHypothesis>* quads) {
  const size_t n = quads->size();
  std::vector<char> tiled(n, 0);
  std::vector<Eigen::Vector2d> centre(n);
  std::vector<double> side(n);
  for (size_t i = 0; i < n; ++i) {
    const auto& c = (*quads)[i].corners;
    centre[i] = 0.25 * (c[0] + c[1] + c[2] + c[3]);
    side[i] = meanSidePx(c);
  }
  for (size_t i = 0; i < n; ++i)
    for (size_t j = i + 1; j < n; ++j) {
      const auto& a = (*quads)[i].corners;
      const auto& b = (*quads)[j].corners;
      const double tol = kSharedCornerShare * std::min(side[i], side[j]) + corner_px;
      for (int s = 0; s < kNumEdges && !tiled[j]; ++s) {
        const Eigen::Vector2d& p = a[s];
        const Eigen::Vector2d& q = a[(s + 1) % kNumEdges];
        int near_p = 0, near_q = 0;
        for (int t = 0; t < kNumEdges; ++t) {
          near_p += (b[t] - p).norm() <= tol;
          near_q += (b[t] - q).norm() <= tol;
        }
        if (near_p == 0 || near_q == 0) continue;
        const Eigen::Vector2d d = q - p;
        const auto sideOf = [&](const Eigen::Vector2d& x) {
          return d.x() * (x.y() - p.y()) - d.y() * (x.x() - p.x());
        };
        if (sideOf(centre[i]) * sideOf(centre[j]) < 0) tiled[i] = tiled[j] = 1;
      }
    }
  std::vector<QuadHypothesis> kept;
  for (size_t i = 0; i < n; ++i)
    if (!tiled[i]) kept.push_back(std::move((*quads)[i]));
  *quads = std::move(kept);
}

// The board (or the attempt that got furthest, or why nothing was tried) and what was seen.
void report(HypothesisSearch&& search, LineEvidence&& evidence, const std::string& region_reason,
            bool no_hypotheses, double noise, ImageDetection* out) {
  search.keepTheBetterFitWhereBoardsCross();
  if (search.found()) {
    *out = std::move(search.best_found);
  } else if (search.best_valid >= 0) {
    *out = std::move(search.best_miss);
    out->details.best_attempt = search.best_miss_index;
  } else {
    out->features.reason =
        no_hypotheses && evidence.lines < kNumEdges
            ? region_reason + cv::format("; %d straight lines from %d segments (need 4)",
                                         evidence.lines, evidence.segments)
            : region_reason +
                  cv::format("; no quadrilateral of straight edges among %d lines", evidence.lines);
  }
  out->details.segments_raw = std::move(evidence.segments_raw);
  out->details.lines_px = std::move(evidence.line_ends);
  out->details.line_segments = evidence.segments;
  out->details.straight_lines = evidence.lines;
  out->details.line_quads = evidence.quads;
  out->details.hypotheses_px = std::move(search.tried);
  out->details.hypothesis_reasons = std::move(search.reasons);
  out->details.boards_px = std::move(search.boards);
  out->details.noise_sigma = noise;
}

}  // namespace

double minEdgeGradient(const ImageBoardDetectorOptions& o, double noise_sigma) {
  return std::max(o.min_edge_contrast, o.edge_snr * kGradientNoiseGain * noise_sigma);
}

bool sidesEndInGray(const cv::Mat& gray, const CameraModel& camera,
                    const ImageBoardDetectorOptions& o, double noise_sigma,
                    CameraBoardFeatures* features) {
  if (sidesEndAtCorners(gray, camera, o, minEdgeGradient(o, noise_sigma), features)) return true;
  features->found = false;
  features->reason += " (in grey)";
  return false;
}

void detectPlain(const cv::Mat& gray, const CameraModel& camera, const Target& target,
                 const ImageBoardDetectorOptions& o, ImageDetection* out,
                 const ExpectedBoard* expected, const StaticScene* excluded, bool grey_frame,
                 bool colour_challenge, bool expected_is_prior) {
  PlainStageTimes times;
  // Edge pixels must stand out of this image's own noise (sensor, compression, texture).
  const double noise = timed(&times.noise_ms, [&] { return estimateNoiseSigma(gray); });
  const double min_gradient = minEdgeGradient(o, noise);
  out->details.noise_sigma = noise;
  const cv::Mat small =
      timed(&times.regions_ms, [&] { return downscale(gray, o.segmentation_width_px); });
  const double sx = static_cast<double>(gray.cols) / small.cols;

  // Hypotheses: regions (best score first, then openings of the rejected ones) and quadrilaterals
  // of long straight edges. None is a gate for the others.
  // Near an expected board, a region need only be as large as a good part of it: the image
  // share that keeps small clutter out of a whole-image search would refuse a far board.
  double min_area = 0;
  if (expected) {
    std::vector<cv::Point2f> quad;
    for (const auto& c : expected->corners_px)
      quad.emplace_back(static_cast<float>(c.x() / sx), static_cast<float>(c.y() / sx));
    min_area = std::min(o.min_board_area_fraction * small.total(),
                        kExpectedAreaShare * cv::contourArea(quad));
  }
  Segmentation seg =
      timed(&times.regions_ms, [&] { return segmentBoard(small, o, std::max(min_area, 0.0)); });
  std::vector<Hypothesis> hypotheses;
  auto addRegions = [&] {
    for (size_t i = 0; i < seg.candidates.size() && i < static_cast<size_t>(o.max_board_candidates);
         ++i)
      hypotheses.push_back(fromRegion(seg.candidates[i], sx, small.size(), camera, o));
  };
  addRegions();
  const size_t first_regions = hypotheses.size();
  const std::string region_reason = seg.reason();
  LineEvidence evidence;
  LineQuads line_quads;
  std::vector<QuadHypothesis> quads;  // the line hypotheses tried, in order

  const ImageDetection fresh = *out;
  HypothesisSearch search;
  RefinedSides refined;
  // Quadrilaterals no line ranking vouches for, judged as weak lines, from `source`.
  auto addWeakQuads = [&](std::vector<QuadHypothesis>* list, const char* source) {
    for (auto& quad : *list) {
      Hypothesis h = fromQuad(quad, camera, o, true);
      h.source = source;
      hypotheses.push_back(std::move(h));
      quads.push_back(std::move(quad));
    }
  };
  // A further line search (another LSD bound or width): its quadrilaterals, those of its first
  // lines with `with_first`, are judged as weak lines.
  auto searchLinesAgain = [&](const ImageBoardDetectorOptions& line_o, double quantization,
                              const char* source, bool with_first) {
    LineEvidence again;
    LineQuads found = timed(&times.quads_ms, [&] {
      return lineQuadHypotheses(gray, camera, line_o, &again, expected,
                                excluded ? &excluded->lines_px : nullptr, quantization);
    });
    times.quads_ms -= again.times.total();
    times += again.times;
    timed(&times.quads_ms, [&] {
      rankWeakQuads(gray, camera, target, o, min_gradient, lineDetectionScale(line_o, gray.cols),
                    &found.faint);
    });
    for (auto* list : {&found.best, &found.ending_at_corners, &found.faint})
      if (list != &found.best || with_first) addWeakQuads(list, source);
  };
  // Openings of the rejected regions (distance transforms: as costly as the segmentation) are
  // made only when no region was the board; they come before the line quadrilaterals.
  size_t regions = first_regions;
  bool projected_tried = false, faint_tried = !grey_frame, fine_tried = false, stable_tried = false;
  for (size_t i = 0;; ++i) {
    if (i == first_regions && !search.found()) {
      timed(&times.regions_ms, [&] { proposeOpenedRegions(small.size(), o, &seg); });
      addRegions();
      regions = hypotheses.size();
    }
    // Line evidence (the costly part) unless a region already gave a board whose four sides
    // show their edge along nearly all their visible length.
    if (i == regions && !search.cleanBoard()) {
      line_quads = timed(&times.quads_ms, [&] {
        return lineQuadHypotheses(gray, camera, o, &evidence, expected,
                                  excluded ? &excluded->lines_px : nullptr);
      });
      times.quads_ms -= evidence.times.total();  // the line stage's own timed parts
      quads = line_quads.best;
      for (const auto& q : quads) hypotheses.push_back(fromQuad(q, camera, o));
    }
    // Quadrilaterals of the weaker lines only when no board settled the search: those their
    // segments support first, then those their sides' gradient does.
    if (i == hypotheses.size() && i >= regions && !search.settled(o.min_side_coverage) &&
        !(line_quads.ending_at_corners.empty() && line_quads.faint.empty())) {
      timed(&times.quads_ms, [&] {
        rankWeakQuads(gray, camera, target, o, min_gradient, lineDetectionScale(o, gray.cols),
                      &line_quads.faint);
      });
      for (auto* list : {&line_quads.ending_at_corners, &line_quads.faint}) {
        for (auto& q : *list) {
          hypotheses.push_back(fromQuad(q, camera, o, true));
          quads.push_back(std::move(q));
        }
        list->clear();
      }
    }
    // Then three lines whose fourth side is traced in the image (faint, or under hands or legs).
    if (i == hypotheses.size() && i >= regions && !search.settled(o.min_side_coverage) &&
        !line_quads.three_sides.empty())
      timed(&times.trace_ms, [&] {
        addTracedSides(gray, camera, target, o, evidence, expected, min_gradient,
                       &line_quads.three_sides, &hypotheses, &quads);
      });
    // Then the lines of a second line search with a lower gradient bound, where the image's
    // noise allows one: LSD's raw bound keeps a faint board's blurred edges (12 grey levels
    // over a ~1.7 px blur) out of the downscaled image's level lines.
    if (i == hypotheses.size() && i >= regions && !search.settled(o.min_side_coverage) &&
        !faint_tried) {
      faint_tried = true;
      const double q = faintLineQuantization(o, gray.cols, noise);
      if (q > 0) searchLinesAgain(o, q, kFaintLinesSource, true);
    }
    // Then, when nothing was the board, the lines of a search at kFineLineScale x the line width:
    // a far board's sides (40-100 px in a 1920 px image) are too short at that width to rank
    // among a cluttered scene's lines or to be found at all. Its first lines are the scene's long
    // lines again, their quadrilaterals tried already (measured with them: a facade rectangle
    // taken in the mono street's memory and pre-pass).
    if (i == hypotheses.size() && i >= regions && !search.found() && !fine_tried) {
      fine_tried = true;
      ImageBoardDetectorOptions fine_o = o;
      fine_o.line_detection_width_px =
          std::min(static_cast<double>(gray.cols), kFineLineScale * o.line_detection_width_px);
      if (o.line_detection_width_px > 0 &&
          fine_o.line_detection_width_px >= kMinFineLineGain * o.line_detection_width_px)
        searchLinesAgain(fine_o, kLsdRawQuantization, kFineLinesSource, false);
    }
    // Then, when still nothing was the board, in the frame's own search: the quadrilaterals of
    // its stable regions (a far board in clutter, whose sides no line search ranks), judged as
    // weak lines. Only where the frame's colour can challenge what they find: a facade's window,
    // a door or a screen is as much a stable region of the board's shape as the board, and its
    // edges, corners and fit pass as well (measured in the simulated mono street, seeds 40-63,
    // single frames, memory and pre-pass: 32 windows taken, no board).
    if (i == hypotheses.size() && i >= regions && !search.found() && !stable_tried && grey_frame &&
        colour_challenge) {
      stable_tried = true;
      std::vector<QuadHypothesis> stable = timed(&times.regions_ms, [&] {
        return stableRegionQuads(
            small, seg, sx, camera, o,
            kStableRegionAreaFactor * o.min_board_area_fraction * small.total());
      });
      timed(&times.quads_ms, [&] {
        const std::vector<QuadHypothesis> all_stable = stable;
        dropTiled(kCoarseCornerPx * sx, &stable);
        std::vector<ShapedQuad> shaped = boardShaped(target, camera, o, sx, std::move(stable));
        dropRepeated(&shaped);
        dropCopiesInTheirPlane(target, camera, sx, all_stable, &shaped);
        stable.clear();
        for (ShapedQuad& q : shaped) stable.push_back(std::move(q.quad));
        rankByEdgeCoverage(gray, camera, o, min_gradient, &stable);
      });
      if (expected)
        stable.erase(std::remove_if(stable.begin(), stable.end(),
                                    [&](const QuadHypothesis& q) {
                                      return expectedOffset(q.corners, *expected) >
                                             expected->tolerance_px;
                                    }),
                     stable.end());
      addWeakQuads(&stable, kStableRegionsSource);
    }
    // Last, a second chance's expected board itself: where the other sensor's board projects,
    // its sides searched as wide as the prior is uncertain (a board no hypothesis of its own
    // outlined: too faint or too small against the scene's longer lines). Not a colour part's
    // own outline: a hand or a leg in front of the board notches it, and a side searched that
    // wide follows their outline, which the colour contrast shows as strongly as the board's
    // edge. Two far rs16 boards of fresh augmented draws so passed with a side 5 and 11 px off,
    // and their corners then fitted the 4:3 board better a quarter turn round (tilted 55 deg).
    if (i == hypotheses.size() && i >= regions && !search.settled(o.min_side_coverage) &&
        expected && expected_is_prior && !projected_tried) {
      projected_tried = true;
      QuadHypothesis q;
      q.corners = expected->corners_px;
      Hypothesis h = fromQuad(q, camera, o);
      h.source = "projected board";
      // Never as far as the opposite side: a third of the mean side at most.
      const double half = std::min(std::max(o.coarse_search_px, expected->tolerance_px),
                                   meanSidePx(q.corners) / 3.0);
      for (auto& side : h.sides) side.search_px = half;
      hypotheses.push_back(std::move(h));
      quads.push_back(std::move(q));
    }
    if (i >= hypotheses.size()) break;
    if (i >= first_regions && i < regions && search.found())
      continue;  // openings only until one is the board
    // The edge support of a hypothesis cannot exceed the length of its sides: skip those that
    // cannot beat the board already accepted.
    double bound = 0;
    for (const auto& side : hypotheses[i].sides) bound += side.length;
    if (bound <= search.best_score) continue;
    if (i >= regions && search.settled(o.min_side_coverage) &&
        search.duplicatesBoard(quads[i - regions].corners))
      continue;
    if (expected && i < regions && !nearExpected(hypotheses[i].inside_u, *expected)) continue;
    ImageDetection attempt = fresh;
    CandidateSupport support;
    const bool is_board = timedFit(gray, camera, target, o, hypotheses[i], min_gradient, &attempt,
                                   &support, &refined, &times) &&
                          keptBoard(expected, excluded, &attempt, &search);
    const auto corners = i >= regions ? quads[i - regions].corners : attempt.features.corners_px;
    const double span_share = is_board ? leastSpanShare(camera, o, attempt) : 0.0;
    search.record(hypotheses[i], corners, is_board, support, span_share, std::move(attempt));
  }
  times += evidence.times;
  report(std::move(search), std::move(evidence), region_reason, hypotheses.empty(), noise, out);
  out->details.stage_times = times;
}

}  // namespace image_detection
}  // namespace board_calib
