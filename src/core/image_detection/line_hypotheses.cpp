// Plain board hypotheses from line evidence (as PBPC-Cal does with LSD): segments from OpenCV's
// line segment detector on a downscaled image, merged in undistorted pixels into long straight
// lines of either polarity, then quadrilaterals of four such lines whose sides carry the segments.
// Only geometry is judged here; edge support along each whole side is measured at full
// resolution by the plain detector.
#include "line_internal.h"

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>

namespace board_calib {
namespace image_detection {
namespace {

constexpr size_t kMaxQuads = 20000;  // quadrilaterals scored (bounds the time in line-rich scenes)
constexpr double kMaxOppositeAngleRad = 0.70;  // ~40 deg: opposite sides converge under perspective
constexpr double kMinCornerSin = 0.42;         // ~25 deg: adjacent sides meet at a real angle
constexpr double kMaxCornerGapFraction =
    0.9;  // gap between a line's support and its corner, of the support extent
constexpr double kCornerToleranceFraction =
    0.03;  // of the side length: support this close to a corner counts
constexpr double kOvershootWeight = 0.5;  // support continuing past a corner counts against a side
constexpr double kGapWeight =
    1.0;  // a visible stretch of a side without segments counts against it
constexpr double kMinSideSupportFraction =
    0.12;  // of the whole side (corners may lie far outside the image)
constexpr double kDuplicateCornerFraction =
    0.05;  // quads whose corners agree to this fraction of their size are one
constexpr int kVisibilitySamples = 24;  // samples along a side to measure its visible part
// A quadrilateral with this many sides on static scene lines is scene structure: the board's
// sides move with it and rarely lie along a scene line (measured on the street: with 3, quads of
// two static and two flickering weak lines took the board's place; docs/BENCHMARKS.md).
constexpr int kStaticSidesOfScene = 2;
// A line's support ends at a corner within this many segment-end sigmas (plus the corner
// tolerance share of its extent).
constexpr double kCornerEndSigmas = 4.0;
// Lines past the first ones form a quadrilateral only with this many of its 8 line ends at its
// corners (the rest may be occluded or too faint near the corner).
constexpr int kMinCornerEnds = 3;
// Three-sided chains whose fourth side is traced (each costs a 1-D gradient search and up to two
// hypothesis fits: bounds the time when nothing else was the board).
constexpr int kMaxThreeSides = 4;
// Quadrilaterals of the lines past the first ones handed on to be ranked by their sides' gradient
// (a look along each side: bounds that ranking to ~1 ms on the rs16 office frames).
constexpr size_t kMaxWeakCandidates = 48;

}  // namespace

cv::Rect2d undistortedBounds(const CameraModel& camera) {
  double box[4] = {1e18, 1e18, -1e18, -1e18};
  constexpr int kSamples = 32;
  for (int i = 0; i <= kSamples; ++i) {
    const double s = static_cast<double>(i) / kSamples;
    const Eigen::Vector2d border[4] = {{s * (camera.width() - 1), 0.0},
                                       {s * (camera.width() - 1), camera.height() - 1.0},
                                       {0.0, s * (camera.height() - 1)},
                                       {camera.width() - 1.0, s * (camera.height() - 1)}};
    for (const auto& b : border) {
      const Eigen::Vector2d u = camera.undistortPixel(b);
      box[0] = std::min(box[0], u.x());
      box[1] = std::min(box[1], u.y());
      box[2] = std::max(box[2], u.x());
      box[3] = std::max(box[3], u.y());
    }
  }
  return {box[0], box[1], box[2] - box[0], box[3] - box[1]};
}

double clippedLength(const Eigen::Vector2d& p, const Eigen::Vector2d& q, const cv::Rect2d& box) {
  const Eigen::Vector2d d = q - p;
  double t0 = 0, t1 = 1;
  const double pk[4] = {-d.x(), d.x(), -d.y(), d.y()};
  const double qk[4] = {p.x() - box.x, box.x + box.width - p.x(), p.y() - box.y,
                        box.y + box.height - p.y()};
  for (int k = 0; k < 4; ++k) {
    if (pk[k] == 0) {
      if (qk[k] < 0) return 0;
      continue;
    }
    const double t = qk[k] / pk[k];
    if (pk[k] < 0)
      t0 = std::max(t0, t);
    else
      t1 = std::min(t1, t);
  }
  return t1 > t0 ? (t1 - t0) * d.norm() : 0.0;
}

bool visibleUndistorted(const CameraModel& camera, const Eigen::Vector2d& u, double margin,
                        Eigen::Vector2d* raw) {
  const CameraIntrinsics& in = camera.intrinsics();  // K's entries, without building K per point
  return camera.isVisible(Eigen::Vector3d((u.x() - in.cx) / in.fx, (u.y() - in.cy) / in.fy, 1.0),
                          margin, raw);
}

bool visibleSideInterval(const CameraModel& camera, const Eigen::Vector2d& p,
                         const Eigen::Vector2d& q, double margin, Eigen::Vector2d* a,
                         Eigen::Vector2d* b) {
  int first = -1, last = -1;
  for (int i = 0; i <= kVisibilitySamples; ++i) {
    const Eigen::Vector2d x = p + (q - p) * (static_cast<double>(i) / kVisibilitySamples);
    if (!visibleUndistorted(camera, x, margin)) continue;
    if (first < 0) first = i;
    last = i;
  }
  if (first < 0) return false;
  // Widen by half a sample step towards the invisible neighbours (the edge refinement skips
  // samples outside the image anyway).
  const double step = 1.0 / kVisibilitySamples;
  const double s0 = first > 0 ? (first - 0.5) * step : 0.0,
               s1 = last < kVisibilitySamples ? (last + 0.5) * step : 1.0;
  *a = p + (q - p) * s0;
  *b = p + (q - p) * s1;
  return true;
}

namespace {

// Which lines may meet at a board corner, and where.
struct CornerGraph {
  int n = 0;
  std::vector<char> adjacent;                // n x n, row-major: 0, kEndCorner or kOpenCorner
  std::vector<Eigen::Vector2d> corner;       // n x n, row-major
  std::vector<std::vector<int>> neighbours;  // at kEndCorner, ascending
  const Eigen::Vector2d& at(int i, int j) const { return corner[static_cast<size_t>(i) * n + j]; }
  char kind(int i, int j) const { return adjacent[static_cast<size_t>(i) * n + j]; }
};

// Kinds of adjacency in a corner graph: lines that meet (the lines-ends graph: at least one of
// them ends there) and lines that both stop short of their corner without crossing it (a hand or
// a leg over a board's corner, or a corner too faint for the line detector).
constexpr char kEndCorner = 1;
constexpr char kOpenCorner = 2;

// px: a line's support ending this close to a corner ends there (segment end noise at the LSD
// scale, and corner rounding of a held board as a share of the line's extent).
double cornerEndTolerance(const MergedLine& l, double end_sigma) {
  return kCornerEndSigmas * end_sigma + kCornerToleranceFraction * l.extent();
}

}  // namespace

// Support alone ranks a far board's sides (50-120 px) past the hundreds of longer ceiling and
// floor lines of an office (rs16_plain: the 200th line had 105 px), which cross each other
// rather than end together. Ends are matched within both lines' corner tolerances, as the corner
// graph of the lines' ends matches them.
void rankLinesEndingAtCorners(std::vector<MergedLine>* lines, size_t first, double end_sigma) {
  std::vector<MergedLine>& l = *lines;
  const size_t n = l.size();
  if (n <= first) return;
  // Every line's ends, by x: an end's partner lies within the two lines' tolerances of it.
  struct End {
    Eigen::Vector2d p;
    double tolerance;
    size_t line;
  };
  std::vector<End> ends;
  ends.reserve(2 * n);
  std::vector<Eigen::Vector3d> homogeneous(n);
  double widest = 0;
  for (size_t i = 0; i < n; ++i) {
    homogeneous[i] = l[i].homogeneous();
    const double tolerance = cornerEndTolerance(l[i], end_sigma);
    widest = std::max(widest, tolerance);
    for (const Eigen::Vector2d& p : l[i].ends()) ends.push_back({p, tolerance, i});
  }
  std::sort(ends.begin(), ends.end(), [](const End& a, const End& b) { return a.p.x() < b.p.x(); });
  std::vector<char> at_corner(n, 0);
  for (size_t k = 0; k < ends.size(); ++k) {
    const End& a = ends[k];
    if (a.line < first || at_corner[a.line]) continue;
    const double reach = a.tolerance + widest;
    // Whether end m (within reach along x) is a's partner at an L corner; false when past reach.
    auto partner = [&](size_t m, bool* past) {
      const End& b = ends[m];
      *past = std::abs(b.p.x() - a.p.x()) > reach;
      if (*past || b.line == a.line || (b.p - a.p).norm() > a.tolerance + b.tolerance ||
          std::abs(cross2(l[a.line].dir, l[b.line].dir)) < kMinCornerSin)
        return false;
      Eigen::Vector2d c;
      return intersectLines(homogeneous[a.line], homogeneous[b.line], &c) &&
             (c - a.p).norm() <= a.tolerance && (c - b.p).norm() <= b.tolerance;
    };
    bool past = false;
    for (size_t m = k + 1; m < ends.size() && !past && !at_corner[a.line]; ++m)
      at_corner[a.line] = partner(m, &past);
    past = false;
    for (size_t m = k; m-- > 0 && !past && !at_corner[a.line];)
      at_corner[a.line] = partner(m, &past);
  }
  std::vector<size_t> order(n);
  for (size_t i = 0; i < n; ++i) order[i] = i;
  std::stable_partition(order.begin() + first, order.end(),
                        [&](size_t i) { return at_corner[i] != 0; });
  std::vector<MergedLine> ranked;
  ranked.reserve(n);
  for (const size_t i : order) ranked.push_back(std::move(l[i]));
  l = std::move(ranked);
}

namespace {

// The line carries support on both sides of c within `reach` of it: it crosses there (a grid or
// a window bay), where a board's side would end. Only within reach: the greedy merge joins
// segments that are collinear by chance hundreds of px apart, and a board side's line that took
// in a scene segment far past its corner would otherwise cross there (augmented real frames: a
// far board's top side and a ceiling segment 450 px on, its bottom side and a segment 870 px
// off; the second board was then taken with the floor line below it as its side, 41 px off).
bool crossesAt(const MergedLine& l, const Eigen::Vector2d& c, double end_sigma, double reach) {
  const double t = l.along(c), tol = cornerEndTolerance(l, end_sigma);
  // No support at all on one side (the intervals lie within [t_min, t_max]).
  if (t - tol <= l.t_min || t + tol >= l.t_max) return false;
  return std::min(l.supportWithin(t - tol - reach, t - tol),
                  l.supportWithin(t + tol, t + tol + reach)) > tol;
}

// One end of the line's support lies at c.
bool endsAt(const MergedLine& l, const Eigen::Vector2d& c, double end_sigma) {
  const double t = l.along(c), tol = cornerEndTolerance(l, end_sigma);
  return std::abs(l.t_min - t) <= tol || std::abs(l.t_max - t) <= tol;
}

// The line's support does not run on past corner c on the side away from corner `from` (its
// side's other end).
bool endsBy(const MergedLine& l, const Eigen::Vector2d& from, const Eigen::Vector2d& c,
            double end_sigma) {
  const double t = l.along(c);
  const double run_on = t > l.along(from) ? l.t_max - t : t - l.t_min;
  return run_on <= cornerEndTolerance(l, end_sigma);
}

// How lines a and b meet at c, for the lines-ends graph: neither crosses there and at least one
// ends there (the other may stop short: occluded, faint), or, with `open`, both stop short; 0
// otherwise. Each is judged crossing within the other's extent, the scale of a quadrilateral
// with that corner: a window grid's line runs on past the corner into the next window, well
// within it.
char cornerOfEnds(const MergedLine& a, const MergedLine& b, const Eigen::Vector2d& c,
                  double end_sigma, bool open) {
  // The cheaper test first.
  const bool ends = endsAt(a, c, end_sigma) || endsAt(b, c, end_sigma);
  if (!ends && !open) return 0;
  if (crossesAt(a, c, end_sigma, b.extent()) || crossesAt(b, c, end_sigma, a.extent())) return 0;
  return ends ? kEndCorner : kOpenCorner;
}

// Corner of lines i and j (both below n) when it is plausible: a real angle, and near both lines'
// support or outside the image (corners of a board held close often are). With `ends_only`,
// only where the lines end rather than cross, or with `open_corners` stop short (cornerOfEnds).
CornerGraph cornerGraph(const LineSet& set, int n, const CameraModel& camera,
                        const ImageBoardDetectorOptions& o, bool ends_only,
                        bool open_corners = false) {
  const std::vector<MergedLine>& lines = set.lines;
  CornerGraph g;
  g.n = n;
  g.adjacent.assign(static_cast<size_t>(n) * n, 0);
  g.corner.assign(static_cast<size_t>(n) * n, Eigen::Vector2d::Zero());
  g.neighbours.resize(n);
  std::vector<Eigen::Vector3d> homogeneous(n);
  for (int i = 0; i < n; ++i) homogeneous[i] = lines[i].homogeneous();
  for (int i = 0; i < n; ++i)
    for (int j = i + 1; j < n; ++j) {
      const double s = std::abs(cross2(lines[i].dir, lines[j].dir));
      if (s < kMinCornerSin) continue;
      Eigen::Vector2d c;
      if (!intersectLines(homogeneous[i], homogeneous[j], &c)) continue;
      const char kind = ends_only
                            ? cornerOfEnds(lines[i], lines[j], c, set.end_sigma_px, open_corners)
                            : kEndCorner;
      if (kind == 0) continue;
      // Where the lines end at the corner (or stop short of it), each may stop as far short of
      // it as a side that shows its segments along kLineCoverageShare x min_side_coverage of its
      // length (a hand over the rest of it).
      const double max_gap = ends_only ? 1.0 / (kLineCoverageShare * o.min_side_coverage) - 1.0
                                       : kMaxCornerGapFraction;
      bool near = true;
      for (const MergedLine* l : {&lines[i], &lines[j]}) {
        const double t = l->along(c);
        const double gap = std::max({0.0, l->t_min - t, t - l->t_max});
        near &= gap <= max_gap * l->extent();
      }
      if (!near && visibleUndistorted(camera, c, 0.0)) continue;
      g.adjacent[i * n + j] = g.adjacent[j * n + i] = kind;
      g.corner[i * n + j] = g.corner[j * n + i] = c;
    }
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j)
      if (g.adjacent[i * n + j] == kEndCorner) g.neighbours[i].push_back(j);
  return g;
}

// Line ends that lie at their quadrilateral's corners (of 8).
int endsAtCorners(const LineSet& set, const std::array<int, 4>& idx,
                  const std::array<Eigen::Vector2d, 4>& c) {
  int ends = 0;
  for (int s = 0; s < 4; ++s) {
    const MergedLine& l = set.lines[idx[s]];
    const double tol = cornerEndTolerance(l, set.end_sigma_px);
    const double tp = l.along(c[(s + 3) % 4]), tr = l.along(c[s]);
    ends += std::abs(l.t_min - std::min(tp, tr)) <= tol;
    ends += std::abs(l.t_max - std::max(tp, tr)) <= tol;
  }
  return ends;
}

bool convexPolygon(const std::array<Eigen::Vector2d, 4>& c) {
  double turn_sign = 0;
  for (int s = 0; s < 4; ++s) {
    const double t = cross2(c[(s + 1) % 4] - c[s], c[(s + 2) % 4] - c[(s + 1) % 4]);
    if (turn_sign == 0) turn_sign = t;
    if (t * turn_sign <= 0) return false;
  }
  return true;
}

// Side of line l from corner p to corner r: its length, the segment support between the corners
// and its share of the quadrilateral's score; false when it is too short or barely carries
// segments.
struct QuadSide {
  double length = 0, support = 0, score = 0;
};

bool scoreSide(const MergedLine& l, const Eigen::Vector2d& p, const Eigen::Vector2d& r,
               const cv::Rect2d& ubox, const ImageBoardDetectorOptions& o, QuadSide* out) {
  const double side = (r - p).norm();
  if (side < o.min_board_size_px) return false;
  const double tp = l.along(p), tr = l.along(r);
  const double tol = kCornerToleranceFraction * side;
  const double inside = l.supportWithin(std::min(tp, tr) - tol, std::max(tp, tr) + tol);
  const double overshoot = l.support - inside;
  if (inside < kMinSideSupportFraction * side && inside < o.min_edge_length_px) return false;
  // A board shows its edge along most of each visible side: unsupported stretches count
  // against a quadrilateral as much as supported ones count for it.
  const double gap = std::max(0.0, clippedLength(p, r, ubox) - inside);
  out->length = side;
  out->support = inside;
  out->score = inside - kGapWeight * gap - kOvershootWeight * overshoot;
  return true;
}

// The quadrilateral of corners c (corner c[s] ends side s and starts side s+1) from its scored
// sides; false when their segment support does not outweigh gaps and overshoots (unless
// `any_score`: the weak lines' quadrilaterals are judged by their gradient instead).
bool scoreQuad(const std::array<QuadSide, 4>& sides, const std::array<Eigen::Vector2d, 4>& c,
               bool any_score, QuadHypothesis* q) {
  double score = 0, size = 0;
  for (int s = 0; s < 4; ++s) {
    score += sides[s].score;
    size += sides[s].length;
    q->support[s] = sides[s].support;
  }
  if (score <= 0 && !any_score) return false;
  q->corners = c;
  q->score = score;
  q->size_px = size / 4;
  return true;
}

// Which quadrilaterals a search enumerates.
struct QuadSearch {
  int lines = 0;               // the first lines of the set that sides are taken from
  int first_new = 0;           // at least one side from the lines from here on
  int min_corner_ends = 0;     // line ends at the corners (of 8)
  bool per_perimeter = false;  // ranked by support per px of perimeter
  // Kept whatever their segment score (gaps may outweigh the support): the plain detector
  // measures their sides' gradient instead.
  bool any_score = false;
  const std::vector<char>* is_static = nullptr;  // lines on the static scene (or none)
  const ExpectedBoard* expected = nullptr;
  // Also the quadrilaterals with one corner that both its lines stop short of (kOpenCorner).
  bool one_open_corner = false;
  // The graph of an earlier search over the lines before first_new: a quadrilateral of those
  // lines alone is enumerated again only where that graph did not join them all.
  const CornerGraph* earlier = nullptr;
};

// The earlier search's graph joined the lines of idx (all before search.first_new) at every
// corner: it enumerated that quadrilateral already.
bool joinedBefore(const QuadSearch& search, const std::array<int, 4>& idx) {
  if (!search.earlier || *std::max_element(idx.begin(), idx.end()) >= search.first_new)
    return false;
  for (int s = 0; s < kNumEdges; ++s)
    if (search.earlier->kind(idx[s], idx[(s + 1) % kNumEdges]) == 0) return false;
  return true;
}

// The rest of the judgement of the quadrilateral of lines idx (corner s where idx[s] meets
// idx[s + 1] in g) whose sides 0 and 1 are scored: not enumerated before, a convex outline, line
// ends at its corners, sides 2 and 3, the score and the expected board.
bool completeQuad(const LineSet& set, const CornerGraph& g, const std::array<int, 4>& idx,
                  const cv::Rect2d& ubox, const ImageBoardDetectorOptions& o,
                  const QuadSearch& search, std::array<QuadSide, 4>& sides, QuadHypothesis* q) {
  if (joinedBefore(search, idx)) return false;
  std::array<Eigen::Vector2d, 4> c;
  for (int s = 0; s < 4; ++s) c[s] = g.at(idx[s], idx[(s + 1) % 4]);
  if (!convexPolygon(c)) return false;
  const int ends = endsAtCorners(set, idx, c);
  if (ends < search.min_corner_ends) return false;
  // Side 3 is scored only while it could still lift the score above 0 (see enumerateQuads).
  const std::vector<MergedLine>& lines = set.lines;
  const double score_01 = sides[0].score + sides[1].score;
  if (!scoreSide(lines[idx[2]], c[1], c[2], ubox, o, &sides[2]) ||
      (!search.any_score && score_01 + sides[2].score + lines[idx[3]].support <= 0) ||
      !scoreSide(lines[idx[3]], c[2], c[3], ubox, o, &sides[3]))
    return false;
  if (!scoreQuad(sides, c, search.any_score, q)) return false;
  q->corner_ends = ends;
  return !search.expected || expectedOffset(c, *search.expected) <= search.expected->tolerance_px;
}

// The quadrilateral of lines idx judged as enumerateQuads judges its cycles, at once rather than
// pruned along the way.
bool quadOfLines(const LineSet& set, const CornerGraph& g, const std::array<int, 4>& idx,
                 const cv::Rect2d& ubox, const ImageBoardDetectorOptions& o,
                 const QuadSearch& search, QuadHypothesis* q) {
  const std::vector<MergedLine>& lines = set.lines;
  int on_static = 0;
  for (const int i : idx) on_static += search.is_static ? (*search.is_static)[i] : 0;
  if (on_static >= kStaticSidesOfScene) return false;
  for (int s = 0; s < 2; ++s)
    if (angleBetweenLines(lines[idx[s]].dir, lines[idx[s + 2]].dir) > kMaxOppositeAngleRad)
      return false;
  std::array<QuadSide, 4> sides;
  for (int s = 0; s < 2; ++s)
    if (!scoreSide(lines[idx[s]], g.at(idx[(s + 3) % 4], idx[s]), g.at(idx[s], idx[s + 1]), ubox, o,
                   &sides[s]))
      return false;
  return completeQuad(set, g, idx, ubox, o, search, sides, q);
}

// Quadrilaterals whose lines end at three of their corners and both stop short of the fourth
// (a hand or a leg over it): paths a-b-c-d of the graph's end corners closed by an open corner
// d-a. Where a side's stretch at the open corner is unseen, its other end must hold it: the sides
// at the open corner may not run on past their other corners (in the simulated mono street, a
// pavement line running on past a dark window's corner made that window a board). Each is met
// from both ends; kept from the one with a < d.
void addOneOpenCorner(const LineSet& set, const CornerGraph& g, const cv::Rect2d& ubox,
                      const ImageBoardDetectorOptions& o, const QuadSearch& search,
                      std::vector<QuadHypothesis>* quads) {
  for (int a = 0; a < search.lines && quads->size() < kMaxQuads; ++a)
    for (const int b : g.neighbours[a])
      for (const int c : g.neighbours[b]) {
        if (c == a) continue;
        for (const int d : g.neighbours[c]) {
          if (d <= a || d == b || g.kind(d, a) != kOpenCorner) continue;
          const Eigen::Vector2d& open = g.at(d, a);
          if (!endsBy(set.lines[a], open, g.at(a, b), set.end_sigma_px) ||
              !endsBy(set.lines[d], open, g.at(c, d), set.end_sigma_px))
            continue;
          if (std::max({a, b, c, d}) < search.first_new && !search.earlier) continue;
          QuadHypothesis q;
          if (quadOfLines(set, g, {a, b, c, d}, ubox, o, search, &q)) quads->push_back(q);
        }
      }
}

// Every convex cycle of four lines (opposite sides may converge under perspective), scored.
std::vector<QuadHypothesis> enumerateQuads(const LineSet& set, const CornerGraph& g,
                                           const CameraModel& camera,
                                           const ImageBoardDetectorOptions& o,
                                           const QuadSearch& search) {
  const std::vector<MergedLine>& lines = set.lines;
  std::vector<QuadHypothesis> quads;
  // Opposite sides may converge under perspective; asked once per pair, not once per path.
  const int n = g.n;
  std::vector<signed char> is_parallel(static_cast<size_t>(n) * n, -1);
  auto parallel = [&](int i, int k) {
    signed char& p = is_parallel[static_cast<size_t>(i) * n + k];
    if (p < 0) p = angleBetweenLines(lines[i].dir, lines[k].dir) <= kMaxOppositeAngleRad;
    return p == 1;
  };
  auto onStatic = [&](int i) { return search.is_static ? (*search.is_static)[i] : 0; };
  const cv::Rect2d ubox = undistortedBounds(camera);
  std::vector<signed char> side_i_state(n);
  std::vector<QuadSide> side_i_score(n);
  // i is the smallest index and j < m: each cycle i-j-k-m is met once. The filters are pruned
  // as early as they can be decided (neighbour lists are ascending).
  for (int i = 0; i < search.lines && quads.size() < kMaxQuads; ++i)
    for (const int j : g.neighbours[i]) {
      if (j <= i) continue;
      // Four lines of the static scene: a window bay or a door, never the moving board.
      const int static_ij = onStatic(i) + onStatic(j);
      if (static_ij >= kStaticSidesOfScene) continue;
      // Side i (from its corner with m to its corner with j) depends on m alone here: scored
      // once per m (0: not yet, 1: scored, -1: fails).
      std::fill(side_i_state.begin(), side_i_state.end(), 0);
      for (const int k : g.neighbours[j]) {
        if (k <= i || static_ij + onStatic(k) >= kStaticSidesOfScene || !parallel(i, k)) continue;
        // Side j lies between its corners with i and k: a quadrilateral fails with it for any m.
        std::array<QuadSide, 4> sides;
        if (!scoreSide(lines[j], g.at(i, j), g.at(j, k), ubox, o, &sides[1])) continue;
        // At least one side from the lines from search.first_new on (the others enumerated
        // before), unless the earlier search's graph may not have joined them.
        const int m_from =
            std::max(j, k) < search.first_new && !search.earlier ? search.first_new : j + 1;
        const std::vector<int>& ms = g.neighbours[k];
        for (auto it = std::lower_bound(ms.begin(), ms.end(), m_from); it != ms.end(); ++it) {
          const int m = *it;
          if (g.kind(m, i) != kEndCorner || !parallel(j, m)) continue;
          if (static_ij + onStatic(k) + onStatic(m) >= kStaticSidesOfScene) continue;
          // Cheap tests first: every test must pass, so their order does not matter.
          signed char& side_i = side_i_state[m];
          if (side_i == 0)
            side_i =
                scoreSide(lines[i], g.at(m, i), g.at(i, j), ubox, o, &side_i_score[m]) ? 1 : -1;
          if (side_i < 0) continue;
          sides[0] = side_i_score[m];
          // Sides k and m are scored only while they could still lift the score above 0. A
          // side adds at most its line's whole support (scoreSide: the support between its
          // corners, less gap and overshoot); scoreQuad adds the sides in this order, and
          // rounding is monotone, so the bound holds in floating point too.
          const double score_ij = sides[0].score + sides[1].score;
          if (!search.any_score && score_ij + lines[k].support + lines[m].support <= 0) continue;
          QuadHypothesis q;
          if (completeQuad(set, g, {i, j, k, m}, ubox, o, search, sides, &q)) quads.push_back(q);
        }
      }
    }
  if (search.one_open_corner) addOneOpenCorner(set, g, ubox, o, search, &quads);
  // Per perimeter, a 100 px board and a 1000 px facade rectangle whose sides are equally well
  // evidenced rank alike; by absolute support the facade always comes first.
  const auto rank = [&](const QuadHypothesis& q) {
    return search.per_perimeter ? q.score / (kNumEdges * q.size_px) : q.score;
  };
  // Among weak lines, the quadrilateral whose lines end at more of its corners first (a scene
  // grid's larger cells outscore a board on support alone).
  std::sort(quads.begin(), quads.end(), [&](const QuadHypothesis& x, const QuadHypothesis& y) {
    if (search.min_corner_ends > 0 && x.corner_ends != y.corner_ends)
      return x.corner_ends > y.corner_ends;
    return rank(x) > rank(y);
  });
  return quads;
}

// The two quadrilaterals' corners agree to kDuplicateCornerFraction of the smaller one's size.
bool sameQuad(const QuadHypothesis& q, const QuadHypothesis& k) {
  double worst = 0;
  for (int s = 0; s < 4; ++s) {
    double best = 1e18;
    for (int t = 0; t < 4; ++t) best = std::min(best, (q.corners[s] - k.corners[t]).norm());
    worst = std::max(worst, best);
  }
  return worst < kDuplicateCornerFraction * std::min(q.size_px, k.size_px);
}

// Visible support: the fraction of each side inside the image that carries segments; a board
// shows its edges along most of every visible side. Keeps the first `limit` distinct
// quadrilaterals whose four sides show.
std::vector<QuadHypothesis> keepBest(std::vector<QuadHypothesis>* quads, const CameraModel& camera,
                                     const ImageBoardDetectorOptions& o, size_t limit) {
  std::vector<QuadHypothesis> kept;
  for (QuadHypothesis& q : *quads) {
    if (kept.size() >= limit) break;
    if (std::any_of(kept.begin(), kept.end(),
                    [&](const QuadHypothesis& k) { return sameQuad(q, k); }))
      continue;
    bool ok = true;
    for (int s = 0; s < 4 && ok; ++s) {
      Eigen::Vector2d a, b;
      const Eigen::Vector2d& p = q.corners[(s + 3) % 4];
      const Eigen::Vector2d& r = q.corners[s];
      if (!visibleSideInterval(camera, p, r, o.border_margin_px, &a, &b)) {
        q.visible[s] = 0;
        continue;  // a side fully outside the image: judged by the others
      }
      q.visible[s] = (b - a).norm();
      ok = q.support[s] >= o.min_side_coverage * q.visible[s] * kLineCoverageShare;
    }
    int visible_sides = 0;
    for (int s = 0; s < 4; ++s) visible_sides += q.visible[s] > 0;
    if (!ok || visible_sides < kNumEdges) continue;
    kept.push_back(q);
  }
  return kept;
}

// Line ends of the chain a-base-b at its two corners (of 4).
int chainEndsAtCorners(const LineSet& set, const std::array<int, 3>& idx,
                       const std::array<Eigen::Vector2d, 2>& c) {
  int ends = 0;
  for (int k = 0; k < 3; ++k) {
    const MergedLine& l = set.lines[idx[k]];
    const double tol = cornerEndTolerance(l, set.end_sigma_px);
    for (int e = 0; e < 2; ++e) {
      if ((k == 0 && e == 1) || (k == 2 && e == 0)) continue;  // an open side at the far corner
      const double t = l.along(c[e]);
      ends += std::min(std::abs(l.t_min - t), std::abs(l.t_max - t)) <= tol;
    }
  }
  return ends;
}

// One open side of a chain leaving its corner c: the direction its segments take, how far they
// reach (less the corner tolerance: the far corner may lie that much short of their end), and the
// segment support up to there; false when it shows less than a short board edge.
bool openSide(const LineSet& set, int i, const Eigen::Vector2d& c,
              const ImageBoardDetectorOptions& o, Eigen::Vector2d* inward, double* reach,
              double* support) {
  const MergedLine& l = set.lines[i];
  const double t = l.along(c), tol = cornerEndTolerance(l, set.end_sigma_px);
  const bool forward = 0.5 * (l.t_min + l.t_max) >= t;
  *inward = forward ? l.dir : Eigen::Vector2d(-l.dir);
  const double end = forward ? l.t_max - t : t - l.t_min;
  *reach = std::max(0.0, end - tol);
  *support = forward ? l.supportWithin(t - tol, l.t_max) : l.supportWithin(l.t_min, t + tol);
  return end >= o.min_edge_length_px && *support >= o.min_edge_length_px;
}

// Chains a-base-b of the corner graph of line ends whose fourth side has no line: a and b roughly
// parallel, both leaving the base towards the same side, the base carrying segments between its
// corners as a side of a quadrilateral must. Most line ends at the corners first, then support.
std::vector<ThreeSides> threeSideChains(const LineSet& set, const CornerGraph& g, int n,
                                        const ImageBoardDetectorOptions& o,
                                        const std::vector<char>& is_static) {
  const std::vector<MergedLine>& lines = set.lines;
  auto onStatic = [&](int i) { return i < static_cast<int>(is_static.size()) && is_static[i]; };
  std::vector<ThreeSides> chains;
  for (int j = 0; j < n; ++j) {
    const MergedLine& base = lines[j];
    const Eigen::Vector2d normal(-base.dir.y(), base.dir.x());
    for (const int a : g.neighbours[j])
      for (const int b : g.neighbours[j]) {
        if (b <= a || angleBetweenLines(lines[a].dir, lines[b].dir) > kMaxOppositeAngleRad)
          continue;
        if (onStatic(a) + onStatic(j) + onStatic(b) >= kStaticSidesOfScene) continue;
        ThreeSides u;
        u.corners = {g.at(a, j), g.at(j, b)};
        const double side = (u.corners[1] - u.corners[0]).norm();
        if (side < o.min_board_size_px) continue;
        double open_support[2];
        if (!openSide(set, a, u.corners[0], o, &u.inward[0], &u.reach[0], &open_support[0]) ||
            !openSide(set, b, u.corners[1], o, &u.inward[1], &u.reach[1], &open_support[1]))
          continue;
        if (normal.dot(u.inward[0]) * normal.dot(u.inward[1]) <= 0) continue;  // not one board
        const double t0 = base.along(u.corners[0]), t1 = base.along(u.corners[1]);
        const double tol = kCornerToleranceFraction * side;
        const double on_base = base.supportWithin(std::min(t0, t1) - tol, std::max(t0, t1) + tol);
        if (on_base < kLineCoverageShare * o.min_side_coverage * side) continue;
        u.lines = {lines[a].homogeneous(), base.homogeneous(), lines[b].homogeneous()};
        u.score = open_support[0] + on_base + open_support[1];
        u.corner_ends = chainEndsAtCorners(set, {a, j, b}, u.corners);
        chains.push_back(u);
      }
  }
  std::sort(chains.begin(), chains.end(), [](const ThreeSides& x, const ThreeSides& y) {
    return x.corner_ends != y.corner_ends ? x.corner_ends > y.corner_ends : x.score > y.score;
  });
  if (chains.size() > static_cast<size_t>(kMaxThreeSides)) chains.resize(kMaxThreeSides);
  return chains;
}

}  // namespace

LineQuads lineQuadHypotheses(const cv::Mat& gray, const CameraModel& camera,
                             const ImageBoardDetectorOptions& o, LineEvidence* evidence,
                             const ExpectedBoard* expected,
                             const std::vector<std::array<Eigen::Vector2d, 2>>* static_lines,
                             double lsd_quantization) {
  if (o.line_detection_width_px <= 0) return {};
  // Once a session knows the static scene, its quadrilaterals are not tried: the search can
  // afford more lines and a scale-free ranking, so a far board competes with near windows.
  // Every line a session may learn is reported (evidence), the quadrilaterals use the first
  // max_lines until the scene is known.
  const bool scene_known = static_lines && !static_lines->empty();
  const LineSet set = detectLines(
      gray, camera, o, evidence, std::max(o.max_lines, o.max_lines_static_scene), lsd_quantization);
  const int all = static_cast<int>(set.lines.size());
  for (const MergedLine& l : set.lines)
    if (evidence) evidence->line_ends.push_back(l.ends());
  QuadSearch best;
  best.lines = std::min(all, scene_known ? o.max_lines_static_scene : o.max_lines);
  best.per_perimeter = scene_known;
  best.expected = expected;
  if (evidence) evidence->lines = best.lines;
  const double tolerance = sameLineTolerancePx(o, gray.cols);
  std::vector<char> is_static(best.lines, 0);
  for (int k = 0; k < best.lines && scene_known; ++k)
    for (const auto& s : *static_lines) is_static[k] |= sameLine(set.lines[k].ends(), s, tolerance);
  best.is_static = &is_static;
  LineQuads out;
  // Three lines of a board whose fourth has none (faint, hidden) are worth a trace.
  const CornerGraph ends_graph = cornerGraph(set, all, camera, o, true, true);
  out.three_sides = threeSideChains(set, ends_graph, all, o, is_static);
  if (best.lines < kNumEdges) return out;
  const CornerGraph best_graph = cornerGraph(set, best.lines, camera, o, false);
  std::vector<QuadHypothesis> quads = enumerateQuads(set, best_graph, camera, o, best);
  if (evidence) evidence->quads = static_cast<int>(quads.size());
  const size_t max_hypotheses = static_cast<size_t>(std::max(0, o.max_line_hypotheses));
  out.best = keepBest(&quads, camera, o, max_hypotheses);
  // A wall of panels or tiles gives hundreds of quadrilaterals whose long seams outscore the
  // board's sides on support alone, and the board's own quadrilateral of the first lines ranked
  // past the kept ones (a dark board before a tiled wall: test_fuzz_detectors' view sets). Those
  // whose lines end at their corners, as a board's do and a seam grid's crossing lines do not,
  // are tried with the quadrilaterals of the further lines below.
  std::vector<QuadHypothesis> ending;
  for (QuadHypothesis& q : quads)
    if (q.corner_ends >= kMinCornerEnds &&
        std::none_of(out.best.begin(), out.best.end(),
                     [&](const QuadHypothesis& k) { return sameQuad(q, k); }))
      ending.push_back(std::move(q));
  // The board's sides may rank far below a line-rich scene's (an office ceiling and floor): the
  // lines past the first ones give quadrilaterals only where the lines end at the corners, as a
  // board's sides do and a scene grid's crossing lines do not.
  if (all > best.lines) {
    QuadSearch ends;
    ends.lines = all;
    ends.first_new = best.lines;
    ends.min_corner_ends = kMinCornerEnds;
    ends.any_score = true;
    ends.expected = expected;
    ends.one_open_corner = true;
    ends.earlier = &best_graph;
    std::vector<QuadHypothesis> supported = enumerateQuads(set, ends_graph, camera, o, ends);
    // The line cap hid them, not their support: each must carry as much as the quadrilaterals
    // kept from the best lines (a door of a street facade does not). The others go to the
    // plain detector, which judges them by the gradient along their sides.
    // (max_line_hypotheses 0 keeps none: no least score then.)
    double least = 0;
    if (!out.best.empty() && out.best.size() >= max_hypotheses) {
      least = out.best.front().score;
      for (const auto& q : out.best) least = std::min(least, q.score);
    }
    const auto first_faint = std::stable_partition(
        supported.begin(), supported.end(),
        [&](const QuadHypothesis& q) { return q.score > 0 && q.score >= least; });
    std::vector<QuadHypothesis> faint(std::make_move_iterator(first_faint),
                                      std::make_move_iterator(supported.end()));
    supported.erase(first_faint, supported.end());
    ending.insert(ending.end(), std::make_move_iterator(supported.begin()),
                  std::make_move_iterator(supported.end()));
    out.faint = keepBest(&faint, camera, o, kMaxWeakCandidates);
  }
  // Ranked as enumerateQuads ranks the further lines' quadrilaterals.
  const auto rank = [&](const QuadHypothesis& q) {
    return scene_known ? q.score / (kNumEdges * q.size_px) : q.score;
  };
  std::stable_sort(
      ending.begin(), ending.end(), [&](const QuadHypothesis& x, const QuadHypothesis& y) {
        return x.corner_ends != y.corner_ends ? x.corner_ends > y.corner_ends : rank(x) > rank(y);
      });
  out.ending_at_corners = keepBest(&ending, camera, o, max_hypotheses);
  return out;
}

}  // namespace image_detection
}  // namespace board_calib
