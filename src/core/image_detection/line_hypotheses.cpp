// Plain board hypotheses from line evidence (as PBPC-Cal does with LSD): segments from OpenCV's
// line segment detector on a downscaled image, merged in undistorted pixels into long straight
// lines of either polarity, then quadrilaterals of four such lines whose sides carry the segments.
// Only geometry is judged here; edge support along each whole side is measured at full
// resolution by the plain detector.
#include "detection_internal.h"

#include <Eigen/Eigenvalues>

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <limits>

namespace board_calib {
namespace image_detection {
namespace {

constexpr double kMinSegmentPx = 5.0;       // LSD-scale px: shorter segments are texture, not edges
constexpr double kSegmentEndSigmaPx = 0.7;  // LSD-scale px, endpoint noise of a segment
constexpr double kMergeSigmas = 3.0;        // angle tolerance of a merge, in endpoint-noise sigmas
constexpr double kMinMergeAngleRad = 0.02;  // ~1 deg: floor of that tolerance (long segments)
constexpr double kMaxMergeAngleRad = 0.10;  // ~6 deg: cap (short segments)
constexpr double kMergeOffsetPx = 3.5;      // full-res px: a held board bows ~3 px
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
// LSD misses weak stretches the gradient search still finds: segments need only cover this share
// of the side coverage required of the refined edge.
constexpr double kLineCoverageShare = 0.5;

// Segment ends this far from a line still lie on it: a held board's bow, or the ends' noise.
double mergeOffsetPx(double end_sigma) { return std::max(kMergeOffsetPx, 2.0 * end_sigma); }

// full-resolution px per LSD px
double lineDetectionScale(const ImageBoardDetectorOptions& o, int image_width) {
  return std::max(1.0, static_cast<double>(image_width) / o.line_detection_width_px);
}

double cross2(const Eigen::Vector2d& a, const Eigen::Vector2d& b) {
  return a.x() * b.y() - a.y() * b.x();
}

struct Member {
  Eigen::Vector2d a, b;
  double length;
};

struct MergedLine {
  Eigen::Vector2d point, dir;  // undistorted px, unit direction
  std::vector<Member> members;
  std::vector<std::pair<double, double>> intervals;  // union of member projections along dir
  double support = 0, t_min = 0, t_max = 0;

  double offset(const Eigen::Vector2d& p) const { return cross2(dir, p - point); }
  double along(const Eigen::Vector2d& p) const { return dir.dot(p - point); }

  // Length-weighted total least squares through the member segments (each sampled at its ends
  // and middle), then the union of their projections.
  void refit() {
    double w = 0;
    Eigen::Vector2d mean = Eigen::Vector2d::Zero();
    for (const auto& m : members)
      for (const Eigen::Vector2d& p : {m.a, m.b, Eigen::Vector2d(0.5 * (m.a + m.b))}) {
        mean += m.length * p;
        w += m.length;
      }
    mean /= w;
    Eigen::Matrix2d cov = Eigen::Matrix2d::Zero();
    for (const auto& m : members)
      for (const Eigen::Vector2d& p : {m.a, m.b, Eigen::Vector2d(0.5 * (m.a + m.b))})
        cov += m.length * (p - mean) * (p - mean).transpose();
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig(cov);
    Eigen::Vector2d d = eig.eigenvectors().col(1);
    if (d.dot(dir) < 0) d = -d;
    point = mean;
    dir = d.normalized();
    intervals.clear();
    for (const auto& m : members) {
      const double ta = along(m.a), tb = along(m.b);
      intervals.emplace_back(std::min(ta, tb), std::max(ta, tb));
    }
    std::sort(intervals.begin(), intervals.end());
    std::vector<std::pair<double, double>> merged;
    for (const auto& iv : intervals) {
      if (!merged.empty() && iv.first <= merged.back().second)
        merged.back().second = std::max(merged.back().second, iv.second);
      else
        merged.push_back(iv);
    }
    intervals = std::move(merged);
    support = 0;
    for (const auto& iv : intervals) support += iv.second - iv.first;
    t_min = intervals.front().first;
    t_max = intervals.back().second;
  }

  // Support inside [lo, hi] along the line.
  double supportWithin(double lo, double hi) const {
    double s = 0;
    for (const auto& iv : intervals)
      s += std::max(0.0, std::min(hi, iv.second) - std::max(lo, iv.first));
    return s;
  }

  std::array<Eigen::Vector2d, 2> ends() const { return {point + t_min * dir, point + t_max * dir}; }

  Eigen::Vector3d homogeneous() const {
    const Eigen::Vector2d n(-dir.y(), dir.x());
    return {n.x(), n.y(), -n.dot(point)};
  }
};

// Bounding box of the image border in undistorted px.
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

// Length of the segment p-q inside a box (Liang-Barsky clipping): a quick upper bound of the
// visible length of a side.
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

double angleBetweenLines(const Eigen::Vector2d& d1, const Eigen::Vector2d& d2) {
  return std::acos(std::min(1.0, std::abs(d1.dot(d2))));
}

}  // namespace

bool visibleUndistorted(const CameraModel& camera, const Eigen::Vector2d& u, double margin) {
  const Eigen::Matrix3d K = camera.K();
  return camera.isVisible(
      Eigen::Vector3d((u.x() - K(0, 2)) / K(0, 0), (u.y() - K(1, 2)) / K(1, 1), 1.0), margin);
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

// LSD segments of the downscaled image, in undistorted full-resolution px, longest first.
// `scale`: full-resolution px per LSD px.
std::vector<Member> detectSegments(const cv::Mat& gray, const CameraModel& camera,
                                   const ImageBoardDetectorOptions& o, LineEvidence* evidence,
                                   double* scale) {
  *scale = lineDetectionScale(o, gray.cols);
  cv::Mat small;
  if (*scale > 1.0)
    cv::resize(gray, small,
               cv::Size(static_cast<int>(std::lround(gray.cols / *scale)),
                        static_cast<int>(std::lround(gray.rows / *scale))),
               0, 0, cv::INTER_AREA);
  else
    small = gray;
  const double sx = static_cast<double>(gray.cols) / small.cols,
               sy = static_cast<double>(gray.rows) / small.rows;
  // LSD with its own a-contrario false-detection control; no internal rescale (done above, by
  // area averaging, which also lowers the noise).
  const cv::Ptr<cv::LineSegmentDetector> lsd =
      cv::createLineSegmentDetector(cv::LSD_REFINE_NONE, 1.0);
  std::vector<cv::Vec4f> raw_segments;
  lsd->detect(small, raw_segments);

  std::vector<Member> segments;
  for (const auto& s : raw_segments) {
    const double len_small = std::hypot(s[2] - s[0], s[3] - s[1]);
    if (len_small < kMinSegmentPx) continue;
    const Eigen::Vector2d a_raw((s[0] + 0.5) * sx - 0.5, (s[1] + 0.5) * sy - 0.5);
    const Eigen::Vector2d b_raw((s[2] + 0.5) * sx - 0.5, (s[3] + 0.5) * sy - 0.5);
    if (evidence) evidence->segments_raw.push_back({a_raw, b_raw});
    Member m{camera.undistortPixel(a_raw), camera.undistortPixel(b_raw), 0};
    m.length = (m.b - m.a).norm();
    if (m.length > 0) segments.push_back(m);
  }
  if (evidence) evidence->segments = static_cast<int>(segments.size());
  std::sort(segments.begin(), segments.end(),
            [](const Member& x, const Member& y) { return x.length > y.length; });
  return segments;
}

// Greedy merge, longest first: a segment joins a line when its direction agrees within its own
// endpoint noise and both its ends lie within the bow of a held board. Returns the lines with
// enough support, most supported first, at most max_lines (a floor or ceiling has many longer
// than the board).
std::vector<MergedLine> mergeSegments(const std::vector<Member>& segments, double end_sigma,
                                      const ImageBoardDetectorOptions& o, int max_lines) {
  std::vector<MergedLine> lines;
  const double max_offset = mergeOffsetPx(end_sigma);
  for (const Member& s : segments) {
    const Eigen::Vector2d d = (s.b - s.a) / s.length;
    const double angle_tol = std::clamp(kMergeSigmas * std::sqrt(2.0) * end_sigma / s.length,
                                        kMinMergeAngleRad, kMaxMergeAngleRad);
    MergedLine* host = nullptr;
    for (auto& l : lines) {
      if (angleBetweenLines(d, l.dir) > angle_tol) continue;
      if (std::abs(l.offset(s.a)) > max_offset || std::abs(l.offset(s.b)) > max_offset) continue;
      host = &l;
      break;
    }
    if (host) {
      host->members.push_back(s);
      host->refit();
    } else {
      MergedLine l;
      l.point = s.a;
      l.dir = d;
      l.members.push_back(s);
      l.refit();
      lines.push_back(std::move(l));
    }
  }
  const double min_support = std::max(o.min_edge_length_px, 0.5 * o.min_board_size_px);
  lines.erase(std::remove_if(lines.begin(), lines.end(),
                             [&](const MergedLine& l) { return l.support < min_support; }),
              lines.end());
  std::sort(lines.begin(), lines.end(),
            [](const MergedLine& x, const MergedLine& y) { return x.support > y.support; });
  if (lines.size() > static_cast<size_t>(max_lines)) lines.resize(max_lines);
  return lines;
}

// Which lines may meet at a board corner, and where.
struct CornerGraph {
  std::vector<std::vector<char>> adjacent;
  std::vector<std::vector<Eigen::Vector2d>> corner;
  std::vector<std::vector<int>> neighbours;
};

// Corner of lines i and j when it is plausible: a real angle, and near both lines' support or
// outside the image (corners of a board held close often are).
CornerGraph cornerGraph(const std::vector<MergedLine>& lines, const CameraModel& camera) {
  const int n = static_cast<int>(lines.size());
  CornerGraph g;
  g.adjacent.assign(n, std::vector<char>(n, 0));
  g.corner.assign(n, std::vector<Eigen::Vector2d>(n, Eigen::Vector2d::Zero()));
  g.neighbours.resize(n);
  for (int i = 0; i < n; ++i)
    for (int j = i + 1; j < n; ++j) {
      const double s = std::abs(cross2(lines[i].dir, lines[j].dir));
      if (s < kMinCornerSin) continue;
      Eigen::Vector2d c;
      if (!intersectLines(lines[i].homogeneous(), lines[j].homogeneous(), &c)) continue;
      const bool outside = !visibleUndistorted(camera, c, 0.0);
      bool near = true;
      for (const MergedLine* l : {&lines[i], &lines[j]}) {
        const double t = l->along(c);
        const double gap = std::max({0.0, l->t_min - t, t - l->t_max});
        near &= gap <= kMaxCornerGapFraction * (l->t_max - l->t_min);
      }
      if (!near && !outside) continue;
      g.adjacent[i][j] = g.adjacent[j][i] = 1;
      g.corner[i][j] = g.corner[j][i] = c;
    }
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j)
      if (g.adjacent[i][j]) g.neighbours[i].push_back(j);
  return g;
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

// Segment support of the quadrilateral of lines idx (corner c[s] ends side s and starts side
// s+1); false when a side is too short or barely carries segments.
bool scoreQuad(const std::vector<MergedLine>& lines, const std::array<int, 4>& idx,
               const std::array<Eigen::Vector2d, 4>& c, const cv::Rect2d& ubox,
               const ImageBoardDetectorOptions& o, QuadHypothesis* q) {
  double score = 0, size = 0;
  for (int s = 0; s < 4; ++s) {
    const MergedLine& l = lines[idx[s]];
    const Eigen::Vector2d& p = c[(s + 3) % 4];
    const Eigen::Vector2d& r = c[s];
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
    score += inside - kGapWeight * gap - kOvershootWeight * overshoot;
    size += side;
    q->support[s] = inside;
  }
  if (score <= 0) return false;
  q->corners = c;
  q->score = score;
  q->size_px = size / 4;
  return true;
}

// Every convex cycle of four lines (opposite sides may converge under perspective), scored.
std::vector<QuadHypothesis> enumerateQuads(const std::vector<MergedLine>& lines,
                                           const CornerGraph& g, const CameraModel& camera,
                                           const ImageBoardDetectorOptions& o,
                                           const ExpectedBoard* expected,
                                           const std::vector<char>& is_static, bool per_perimeter) {
  std::vector<QuadHypothesis> quads;
  auto parallel = [&](int i, int k) {
    return angleBetweenLines(lines[i].dir, lines[k].dir) <= kMaxOppositeAngleRad;
  };
  const cv::Rect2d ubox = undistortedBounds(camera);
  const int n = static_cast<int>(lines.size());
  for (int i = 0; i < n && quads.size() < kMaxQuads; ++i)
    for (const int j : g.neighbours[i]) {
      if (j <= i) continue;
      for (const int k : g.neighbours[j]) {
        if (k <= i || !parallel(i, k)) continue;
        for (const int m : g.neighbours[k]) {
          // i is the smallest index and j < m: each cycle i-j-k-m is met once.
          if (m <= j || !g.adjacent[m][i] || !parallel(j, m)) continue;
          // Four lines of the static scene: a window bay or a door, never the moving board.
          if (is_static[i] + is_static[j] + is_static[k] + is_static[m] >= kStaticSidesOfScene)
            continue;
          const std::array<int, 4> idx = {i, j, k, m};
          std::array<Eigen::Vector2d, 4> c;
          for (int s = 0; s < 4; ++s) c[s] = g.corner[idx[s]][idx[(s + 1) % 4]];
          if (!convexPolygon(c)) continue;
          QuadHypothesis q;
          if (!scoreQuad(lines, idx, c, ubox, o, &q)) continue;
          if (expected && worstCornerOffset(c, expected->corners_px) > expected->tolerance_px)
            continue;
          quads.push_back(q);
        }
      }
    }
  // Per perimeter, a 100 px board and a 1000 px facade rectangle whose sides are equally well
  // evidenced rank alike; by absolute support the facade always comes first.
  const auto rank = [&](const QuadHypothesis& q) {
    return per_perimeter ? q.score / (kNumEdges * q.size_px) : q.score;
  };
  std::sort(quads.begin(), quads.end(),
            [&](const QuadHypothesis& x, const QuadHypothesis& y) { return rank(x) > rank(y); });
  return quads;
}

// Visible support: the fraction of each side inside the image that carries segments; a board
// shows its edges along most of every visible side. Keeps the best distinct quadrilaterals.
std::vector<QuadHypothesis> keepBest(std::vector<QuadHypothesis>* quads, const CameraModel& camera,
                                     const ImageBoardDetectorOptions& o) {
  std::vector<QuadHypothesis> kept;
  for (QuadHypothesis& q : *quads) {
    if (static_cast<int>(kept.size()) >= o.max_line_hypotheses) break;
    bool duplicate = false;
    for (const auto& k : kept) {
      double worst = 0;
      for (int s = 0; s < 4; ++s) {
        double best = 1e18;
        for (int t = 0; t < 4; ++t) best = std::min(best, (q.corners[s] - k.corners[t]).norm());
        worst = std::max(worst, best);
      }
      duplicate |= worst < kDuplicateCornerFraction * std::min(q.size_px, k.size_px);
    }
    if (duplicate) continue;
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

}  // namespace

double sameLineTolerancePx(const ImageBoardDetectorOptions& o, int image_width) {
  if (o.line_detection_width_px <= 0) return kMergeOffsetPx;
  return mergeOffsetPx(kSegmentEndSigmaPx * lineDetectionScale(o, image_width));
}

std::vector<std::array<Eigen::Vector2d, 2>> sceneLines(const cv::Mat& gray,
                                                       const CameraModel& camera,
                                                       const ImageBoardDetectorOptions& o) {
  if (o.line_detection_width_px <= 0) return {};
  double scale = 1.0;
  const std::vector<Member> segments = detectSegments(gray, camera, o, nullptr, &scale);
  std::vector<std::array<Eigen::Vector2d, 2>> out;
  for (const MergedLine& l : mergeSegments(segments, kSegmentEndSigmaPx * scale, o,
                                           std::max(o.max_lines, o.max_lines_static_scene)))
    out.push_back(l.ends());
  return out;
}

std::vector<QuadHypothesis> lineQuadHypotheses(
    const cv::Mat& gray, const CameraModel& camera, const ImageBoardDetectorOptions& o,
    LineEvidence* evidence, const ExpectedBoard* expected,
    const std::vector<std::array<Eigen::Vector2d, 2>>* static_lines) {
  if (o.line_detection_width_px <= 0) return {};
  double scale = 1.0;
  const std::vector<Member> segments = detectSegments(gray, camera, o, evidence, &scale);
  // Once a session knows the static scene, its quadrilaterals are not tried: the search can
  // afford more lines and a scale-free ranking, so a far board competes with near windows.
  // Every line a session may learn is reported (evidence), the quadrilaterals use the first
  // max_lines until the scene is known.
  const bool scene_known = static_lines && !static_lines->empty();
  std::vector<MergedLine> lines = mergeSegments(segments, kSegmentEndSigmaPx * scale, o,
                                                std::max(o.max_lines, o.max_lines_static_scene));
  for (const MergedLine& l : lines)
    if (evidence) evidence->line_ends.push_back(l.ends());
  const size_t used = static_cast<size_t>(scene_known ? o.max_lines_static_scene : o.max_lines);
  if (lines.size() > used) lines.resize(used);
  if (evidence) evidence->lines = static_cast<int>(lines.size());
  const double tolerance = sameLineTolerancePx(o, gray.cols);
  std::vector<char> is_static(lines.size(), 0);
  for (size_t k = 0; k < lines.size() && scene_known; ++k)
    for (const auto& s : *static_lines) is_static[k] |= sameLine(lines[k].ends(), s, tolerance);
  if (lines.size() < static_cast<size_t>(kNumEdges)) return {};
  std::vector<QuadHypothesis> quads = enumerateQuads(lines, cornerGraph(lines, camera), camera, o,
                                                     expected, is_static, scene_known);
  if (evidence) evidence->quads = static_cast<int>(quads.size());
  return keepBest(&quads, camera, o);
}

}  // namespace image_detection
}  // namespace board_calib
