// LiDAR board detector, stage 4: scan lines on the board and its four edges, from the per-line
// extremes (line fits) or, for sparse boards, a rectangle fit.
#include "detector_internal.h"

#include <board_calib/core/common/statistics.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <numeric>
#include <unordered_set>

namespace board_calib {
namespace lidar_detail {

namespace {

struct SideFit {
  LineFit2D upper, lower;
  std::vector<int> upper_members, lower_members;  // indices into the side's points
};

// Splits the extremes of one side (left or right) into an upper and a lower edge and fits both.
// `outward` is -1 for the left side (smaller u), +1 for the right side.
// Sum of squared distances of points to their total-least-squares line.
double lineResidual(const Points2& pts, const std::vector<size_t>& order, size_t begin,
                    size_t end) {
  Eigen::Vector2d mean = Eigen::Vector2d::Zero();
  for (size_t k = begin; k < end; ++k) mean += pts[order[k]];
  mean /= static_cast<double>(end - begin);
  Eigen::Matrix2d cov = Eigen::Matrix2d::Zero();
  for (size_t k = begin; k < end; ++k) {
    const Eigen::Vector2d d = pts[order[k]] - mean;
    cov += d * d.transpose();
  }
  return Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d>(cov).eigenvalues()(0);
}

// `search_split`: instead of taking the most outward point as the corner (a hand at the corner
// can fool it), split the extremes, ordered top to bottom, where two lines fit best.
SideFit fitSide(const Points2& side, double outward, const LidarBoardDetectorOptions& o,
                std::mt19937& rng, bool search_split = false) {
  SideFit s;
  if (side.size() < 2) return s;
  std::vector<int> label(side.size(), -1);  // 0 upper, 1 lower
  if (search_split && side.size() >= 4) {
    std::vector<size_t> order(side.size());
    std::iota(order.begin(), order.end(), 0);
    std::sort(order.begin(), order.end(),
              [&](size_t a, size_t b) { return side[a].y() > side[b].y(); });
    double best = std::numeric_limits<double>::infinity();
    size_t split = 2;
    for (size_t k = 2; k + 2 <= order.size(); ++k) {
      const double cost =
          lineResidual(side, order, 0, k) + lineResidual(side, order, k, order.size());
      if (cost < best) {
        best = cost;
        split = k;
      }
    }
    for (size_t k = 0; k < order.size(); ++k) label[order[k]] = k < split ? 0 : 1;
  } else {
    // The side's corner is its most outward point: above it the upper edge, below it the lower.
    size_t corner = 0;
    for (size_t i = 1; i < side.size(); ++i)
      if (outward * side[i].x() > outward * side[corner].x()) corner = i;
    for (size_t i = 0; i < side.size(); ++i)
      if (i != corner) label[i] = side[i].y() > side[corner].y() ? 0 : 1;
  }
  for (int round = 0; round < kEdgeAssignmentRounds; ++round) {
    Points2 up, lo;
    for (size_t i = 0; i < side.size(); ++i) {
      if (label[i] == 0) up.push_back(side[i]);
      if (label[i] == 1) lo.push_back(side[i]);
    }
    s.upper = fitLineRobust(up, o.edge_inlier_threshold_m, o.ransac_iterations, rng);
    s.lower = fitLineRobust(lo, o.edge_inlier_threshold_m, o.ransac_iterations, rng);
    if (!s.upper.ok || !s.lower.ok) break;
    // Re-assign every extreme to the nearer line (fixes points near the corner).
    Eigen::Vector2d x;
    const bool meet = intersectLines(s.upper, s.lower, &x);
    bool changed = false;
    for (size_t i = 0; i < side.size(); ++i) {
      const double du = s.upper.distance(side[i]), dl = s.lower.distance(side[i]);
      int l = du < dl ? 0 : 1;
      // Beyond the corner along v the nearer line can be the wrong one: keep the geometric side.
      if (meet)
        l = side[i].y() > x.y() ? (du < 3 * o.edge_inlier_threshold_m || du < dl ? 0 : 1)
                                : (dl < 3 * o.edge_inlier_threshold_m || dl < du ? 1 : 0);
      if (l != label[i]) {
        label[i] = l;
        changed = true;
      }
    }
    if (!changed) break;
  }
  // Final fits with membership.
  Points2 up, lo;
  std::vector<int> up_idx, lo_idx;
  for (size_t i = 0; i < side.size(); ++i) {
    if (label[i] == 0) {
      up.push_back(side[i]);
      up_idx.push_back(static_cast<int>(i));
    } else if (label[i] == 1) {
      lo.push_back(side[i]);
      lo_idx.push_back(static_cast<int>(i));
    }
  }
  s.upper = fitLineRobust(up, o.edge_inlier_threshold_m, o.ransac_iterations, rng);
  s.lower = fitLineRobust(lo, o.edge_inlier_threshold_m, o.ransac_iterations, rng);
  for (size_t i = 0; i < up_idx.size(); ++i)
    if (s.upper.ok && s.upper.inlier[i]) s.upper_members.push_back(up_idx[i]);
  for (size_t i = 0; i < lo_idx.size(); ++i)
    if (s.lower.ok && s.lower.inlier[i]) s.lower_members.push_back(lo_idx[i]);
  return s;
}

// The extreme returns of every scan line on the board (left = larger azimuth, seen from the
// sensor), projected into the board plane, with each line's direction and sample spacing.
struct SideExtremes {
  std::vector<int> left_pts, right_pts;     // indices into the valid points
  Points2 left2, right2;                    // in-plane positions
  Points2 left_dir, right_dir;              // the scan line's in-plane direction
  std::vector<double> left_gap, right_gap;  // its mean spacing between samples
};

SideExtremes sideExtremes(const LidarCloud& cloud, const std::vector<ValidPoint>& pts,
                          const std::vector<int>& board, const LidarBoardDetectorOptions& o,
                          const PlaneFrame& frame, const Eigen::Vector3d& centroid,
                          LidarBoardDetection* det) {
  SideExtremes x;
  auto& left_pts = x.left_pts;
  auto& right_pts = x.right_pts;
  auto& left_dir = x.left_dir;
  auto& right_dir = x.right_dir;
  auto& left_gap = x.left_gap;
  auto& right_gap = x.right_gap;
  const std::vector<int> line = scanLines(cloud, board, pts, o, &det->scan_line_source);
  const auto per_line =
      lineExtremes<std::unordered_map<int, LineExtremes>>(pts, board, line, centroid);
  // Per extreme: the scan line's in-plane direction and its mean spacing between samples.
  for (const auto& kv : per_line) {
    if (kv.second.count < o.min_points_per_scan_line || kv.second.left == kv.second.right) continue;
    ++det->num_scan_lines;
    left_pts.push_back(kv.second.left);
    right_pts.push_back(kv.second.right);
    const Eigen::Vector2d span =
        frame.project(pts[kv.second.right].p) - frame.project(pts[kv.second.left].p);
    const double gap = span.norm() / (kv.second.count - 1);
    left_dir.push_back(span.normalized());
    right_dir.push_back(span.normalized());
    left_gap.push_back(gap);
    right_gap.push_back(gap);
  }
  for (int i : left_pts) x.left2.push_back(frame.project(pts[i].p));
  for (int i : right_pts) x.right2.push_back(frame.project(pts[i].p));
  return x;
}

struct TwoSides {
  SideFit left, right;
};

// Upper and lower edge of each side; the split search where the corners are not right angles,
// then the sampling bias (extremes lie inside the true edge) corrected.
TwoSides fitSides(const SideExtremes& x, const LidarBoardDetectorOptions& o,
                  const Eigen::Vector3d& centroid, std::mt19937& rng) {
  const Points2& left2 = x.left2;
  const Points2& right2 = x.right2;
  const auto& left_gap = x.left_gap;
  const auto& right_gap = x.right_gap;
  const auto& left_dir = x.left_dir;
  const auto& right_dir = x.right_dir;
  // Extremes scatter inward by up to one sample spacing: the inlier band must cover that at
  // long range, where the spacing exceeds the configured threshold.
  LidarBoardDetectorOptions edge_options = o;
  if (!left_gap.empty()) {
    edge_options.edge_inlier_threshold_m = std::max(o.edge_inlier_threshold_m, medianOf(left_gap));
  }
  SideFit left = fitSide(left2, -1.0, edge_options, rng);
  SideFit right = fitSide(right2, +1.0, edge_options, rng);
  // Adjacent edges of a rectangle meet at right angles; when they do not, one side's split was
  // wrong: try the split search on either side, then on both.
  auto anglesOk = [&](const SideFit& l, const SideFit& r) {
    const std::array<const LineFit2D*, kNumEdges> ls = {&l.upper, &r.upper, &r.lower, &l.lower};
    for (int j = 0; j < kNumEdges; ++j) {
      const LineFit2D& a = *ls[j];
      const LineFit2D& b = *ls[(j + 1) % kNumEdges];
      if (!a.ok || !b.ok) return false;
      const double angle =
          std::acos(std::min(1.0, std::abs(a.direction.dot(b.direction)))) / kRadPerDeg;
      if (std::abs(90.0 - angle) > o.max_corner_angle_error_deg) return false;
    }
    return true;
  };
  if (!anglesOk(left, right)) {
    const SideFit left_split = fitSide(left2, -1.0, edge_options, rng, true);
    const SideFit right_split = fitSide(right2, +1.0, edge_options, rng, true);
    if (anglesOk(left_split, right)) {
      left = left_split;
    } else if (anglesOk(left, right_split)) {
      right = right_split;
    } else if (anglesOk(left_split, right_split)) {
      left = left_split;
      right = right_split;
    }
  }
  if (o.correct_edge_sampling_bias) {
    // The true edge lies between a scan line's extreme and the next (missing) sample outside:
    // on average half a sample spacing further out along the scan line.
    // A return registers once part of the beam's footprint is on the board, so the extremes
    // bloom out by about half the divergence (times the range), which offsets that inset.
    const double bloom = 0.5 * o.beam_divergence_deg * kRadPerDeg * centroid.norm();
    auto shiftOut = [bloom](LineFit2D& l, const std::vector<int>& members, const Points2& dirs,
                            const std::vector<double>& gaps) {
      if (!l.ok || members.empty()) return;
      Eigen::Vector2d normal(-l.direction.y(), l.direction.x());
      if (normal.dot(l.point) < 0) normal = -normal;  // away from the board centre (the origin)
      double shift = 0.0;
      for (int m : members)
        shift += std::max(0.0, 0.5 * gaps[m] - bloom) * std::abs(dirs[m].dot(normal));
      l.point += normal * (shift / members.size());
    };
    shiftOut(left.upper, left.upper_members, left_dir, left_gap);
    shiftOut(left.lower, left.lower_members, left_dir, left_gap);
    shiftOut(right.upper, right.upper_members, right_dir, right_gap);
    shiftOut(right.lower, right.lower_members, right_dir, right_gap);
  }

  return {left, right};
}

// The four edges (UL, UR, LR, LL) and corners from the two sides; false with the reason when
// they are inconsistent or rejected.
bool writeEdges(const SideExtremes& x, const TwoSides& sides, const std::vector<ValidPoint>& pts,
                const LidarBoardDetectorOptions& o, const PlaneFrame& frame,
                LidarBoardFeatures* features) {
  auto& f = *features;
  const SideFit& left = sides.left;
  const SideFit& right = sides.right;
  const auto& left_pts = x.left_pts;
  const auto& right_pts = x.right_pts;
  // Edge order: UL, UR, LR, LL.
  const std::array<const LineFit2D*, kNumEdges> lines = {&left.upper, &right.upper, &right.lower,
                                                         &left.lower};
  const std::array<const std::vector<int>*, kNumEdges> members = {
      &left.upper_members, &right.upper_members, &right.lower_members, &left.lower_members};
  const std::array<const std::vector<int>*, kNumEdges> side_pts = {&left_pts, &right_pts,
                                                                   &right_pts, &left_pts};
  std::string edge_problems;
  for (int j = 0; j < kNumEdges; ++j) {
    f.edge_points[j].clear();
    for (int m : *members[j]) f.edge_points[j].push_back(pts[(*side_pts[j])[m]].p);
    const LineFit2D& l = *lines[j];
    const int n = l.ok ? l.num_inliers : 0;
    f.edge_valid[j] = l.ok && n >= o.min_edge_points && l.rms <= o.max_edge_rms_m;
    if (!f.edge_valid[j]) {
      edge_problems += std::string(edge_problems.empty() ? "" : ", ") + edgeName(j) + ": " +
                       (n < o.min_edge_points ? "too few points (" + std::to_string(n) + ")"
                                              : fmt("line fit RMS %.3f m", l.rms));
    }
    f.edge_line_point[j] = frame.lift(l.point);
    f.edge_line_direction[j] =
        (frame.lift(l.point + l.direction) - frame.lift(l.point)).normalized();
  }
  // Corners j = edge j x edge j+1.
  std::array<bool, kNumEdges> corner_ok{};
  std::array<Eigen::Vector2d, kNumEdges> corner2;
  std::string angle_problems;
  static const char* kCornerNames[kNumEdges] = {"top", "right", "bottom", "left"};
  for (int j = 0; j < kNumEdges; ++j) {
    const int k = (j + 1) % kNumEdges;
    if (!f.edge_valid[j] || !f.edge_valid[k]) continue;
    corner_ok[j] = intersectLines(*lines[j], *lines[k], &corner2[j]);
    if (!corner_ok[j]) continue;
    f.corners[j] = frame.lift(corner2[j]);
    const double angle =
        std::acos(std::min(1.0, std::abs(lines[j]->direction.dot(lines[k]->direction)))) /
        kRadPerDeg;
    if (std::abs(90.0 - angle) > o.max_corner_angle_error_deg)
      angle_problems +=
          std::string(" ") + kCornerNames[j] + fmt(" corner meets at %.0f deg", angle);
  }
  // Line points and directions from the corners when both ends exist: edge j runs from corner
  // j-1 to corner j (clockwise as the sensor sees it).
  for (int j = 0; j < kNumEdges; ++j) {
    const int prev = (j + kNumEdges - 1) % kNumEdges;
    if (corner_ok[j] && corner_ok[prev]) {
      f.edge_line_point[j] = 0.5 * (f.corners[j] + f.corners[prev]);
      f.edge_line_direction[j] = (f.corners[j] - f.corners[prev]).normalized();
    }
  }
  if (!angle_problems.empty()) {
    for (int j = 0; j < kNumEdges; ++j) f.edge_valid[j] = false;
    f.reason = "edges inconsistent:" + angle_problems;
    return false;
  }
  if (!edge_problems.empty()) {
    f.reason = "edges rejected: " + edge_problems;
    return false;
  }
  bool all_corners = corner_ok[0] && corner_ok[1] && corner_ok[2] && corner_ok[3];
  if (!all_corners) {
    for (int j = 0; j < kNumEdges; ++j) f.edge_valid[j] = false;
    f.reason = "edges inconsistent: parallel adjacent edges";
    return false;
  }
  return true;
}

// Measured size against the declared one.
void checkSize(const Target& target, const LidarBoardDetectorOptions& o,
               LidarBoardFeatures* features) {
  auto& f = *features;
  // Sides: UL (left-top) and LR (right-bottom) are opposite, as are UR and LL.
  const double ul = (f.corners[0] - f.corners[3]).norm(), ur = (f.corners[1] - f.corners[0]).norm();
  const double lr = (f.corners[2] - f.corners[1]).norm(), ll = (f.corners[3] - f.corners[2]).norm();
  const double s1 = 0.5 * (ul + lr), s2 = 0.5 * (ur + ll);
  const double w = target.width, h = target.height;
  const bool direct = std::abs(s1 - w) + std::abs(s2 - h) <= std::abs(s1 - h) + std::abs(s2 - w);
  f.measured_size_m = direct ? Eigen::Vector2d(s1, s2) : Eigen::Vector2d(s2, s1);
  const double rw = f.measured_size_m.x() / w, rh = f.measured_size_m.y() / h;
  if (rw < o.min_size_ratio || rh < o.min_size_ratio || rw > o.max_size_ratio ||
      rh > o.max_size_ratio) {
    for (int j = 0; j < kNumEdges; ++j) f.edge_valid[j] = false;
    f.reason = "edges inconsistent: " + fmt("corners span %.3f x %.3f m, declared %.3f x %.3f m",
                                            f.measured_size_m.x(), f.measured_size_m.y(), w, h);
    return;
  }
  if (std::abs(rw - 1.0) > o.size_doubt_ratio || std::abs(rh - 1.0) > o.size_doubt_ratio)
    f.reason = fmt("measured %.3f x %.3f m, declared %.3f x %.3f m", f.measured_size_m.x(),
                   f.measured_size_m.y(), w, h);
}

void extractEdgesByLines(const LidarCloud& cloud, const std::vector<ValidPoint>& pts,
                         const std::vector<int>& board, const Target& target,
                         const LidarBoardDetectorOptions& o, std::mt19937& rng,
                         LidarBoardDetection* det) {
  auto& f = det->features;
  Eigen::Vector3d centroid;
  PlaneFrame frame;
  if (!boardFrameAtCentroid(pts, board, f.plane, &centroid, &frame)) {
    f.reason = "board plane is nearly horizontal: its edges cannot be named";
    return;
  }
  const SideExtremes x = sideExtremes(cloud, pts, board, o, frame, centroid, det);
  const TwoSides sides = fitSides(x, o, centroid, rng);
  if (!writeEdges(x, sides, pts, o, frame, &f)) return;
  checkSize(target, o, &f);
}

}  // namespace

// Stage 4: scan lines and edges.
// ------------------------------------------------------------------------------------------
std::vector<int> scanLines(const LidarCloud& cloud, const std::vector<int>& board,
                           const std::vector<ValidPoint>& pts, const LidarBoardDetectorOptions& o,
                           std::string* source) {
  std::vector<int> line(board.size(), -1);
  bool rings_ok = cloud.has_ring;
  for (size_t k = 0; k < board.size() && rings_ok; ++k)
    rings_ok = cloud.points[pts[board[k]].cloud_index].ring >= 0;
  if (rings_ok) {
    *source = "ring";
    for (size_t k = 0; k < board.size(); ++k)
      line[k] = cloud.points[pts[board[k]].cloud_index].ring;
    return line;
  }
  if (cloud.organized() && cloud.width > 0) {
    *source = "row";
    for (size_t k = 0; k < board.size(); ++k) line[k] = pts[board[k]].cloud_index / cloud.width;
    return line;
  }
  // Beams of a spinning LiDAR have fixed elevations: cluster the elevation angles.
  *source = "elevation";
  std::vector<std::pair<double, int>> elev(board.size());
  for (size_t k = 0; k < board.size(); ++k) {
    const auto& p = pts[board[k]].p;
    elev[k] = {std::atan2(p.z(), std::hypot(p.x(), p.y())), static_cast<int>(k)};
  }
  std::sort(elev.begin(), elev.end());
  const double gap = o.elevation_gap_deg * kRadPerDeg;
  int id = 0;
  for (size_t k = 0; k < elev.size(); ++k) {
    if (k > 0 && elev[k].first - elev[k - 1].first > gap) ++id;
    line[elev[k].second] = id;
  }
  return line;
}

void extractEdges(const LidarCloud& cloud, const std::vector<ValidPoint>& pts,
                  const std::vector<int>& board, const Target& target,
                  const LidarBoardDetectorOptions& o, std::mt19937& rng, LidarBoardDetection* det) {
  const LidarBoardDetection before = *det;
  extractEdgesByLines(cloud, pts, board, target, o, rng, det);
  if (det->features.allEdgesValid() || !o.sparse_candidates) return;
  LidarBoardDetection sparse = before;
  if (extractEdgesByRectangle(cloud, pts, board, target, o, &sparse)) {
    *det = std::move(sparse);
  }
}

}  // namespace lidar_detail
}  // namespace board_calib
