// LiDAR board detector, stage 4 for sparse boards: the declared rectangle fitted to the
// per-line extremes when there are too few for four line fits.
#include "detector_internal.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <numeric>

namespace board_calib {
namespace lidar_detail {

namespace {

// The per-line extremes in the plane frame, each with its expected inset (half a column step
// minus the beam's bloom, along the scan line).
struct SparseExtremes {
  Points2 board2, extremes;
  std::vector<double> insets;
  std::vector<int> index;  // into pts
  int lines = 0;
  double column_m = 0.0;  // mean in-plane spacing of a line's samples, m
};

SparseExtremes sparseExtremes(const std::vector<ValidPoint>& pts, const std::vector<int>& board,
                              const std::vector<int>& line, const PlaneFrame& frame,
                              const Eigen::Vector3d& centroid, double bloom,
                              const LidarBoardDetectorOptions& o) {
  SparseExtremes x;
  double gap_sum = 0.0;
  for (int i : board) x.board2.push_back(frame.project(pts[i].p));
  for (const auto& kv : lineExtremes<std::map<int, LineExtremes>>(pts, board, line, centroid)) {
    const LineExtremes& e = kv.second;
    if (e.count < o.min_points_per_scan_line || e.left == e.right) continue;
    ++x.lines;
    const Eigen::Vector2d a = frame.project(pts[e.left].p), b = frame.project(pts[e.right].p);
    const double gap = (b - a).norm() / (e.count - 1);
    gap_sum += gap;
    const double inset = o.correct_edge_sampling_bias ? std::max(0.0, 0.5 * gap - bloom) : 0.0;
    for (int idx : {e.left, e.right}) {
      x.extremes.push_back(frame.project(pts[idx].p));
      x.insets.push_back(inset);
      x.index.push_back(idx);
    }
  }
  if (x.lines > 0) x.column_m = gap_sum / x.lines;
  return x;
}

// The fitted rectangle's sides as the four edges: UL is the side whose outward normal is nearest
// to up-left (135 deg), then clockwise UR, LR, LL.
struct RectangleSides {
  std::array<Eigen::Vector2d, kNumEdges> a, b;  // side endpoints, counter-clockwise corners
  std::array<int, kNumEdges> side_of_edge;
  std::array<lidar_detail::LineFit2D, kNumEdges> lines;  // per edge
};

RectangleSides rectangleSides(const RectangleFit& fit) {
  RectangleSides r;
  std::array<double, kNumEdges> normal_angle;
  for (int k = 0; k < kNumEdges; ++k) {
    r.a[k] = fit.corners[k];
    r.b[k] = fit.corners[(k + 1) % kNumEdges];
    const Eigen::Vector2d d = r.b[k] - r.a[k];
    normal_angle[k] = std::atan2(-d.x(), d.y());  // ccw polygon: outward normal = (d.y, -d.x)
  }
  int ul = 0;
  auto angleTo = [](double x, double ref) { return std::abs(wrapAngle(x - ref)); };
  for (int k = 1; k < kNumEdges; ++k)
    if (angleTo(normal_angle[k], 0.75 * kPi) < angleTo(normal_angle[ul], 0.75 * kPi)) ul = k;
  // Clockwise from UL = backwards through the counter-clockwise sides.
  for (int j = 0; j < kNumEdges; ++j) {
    const int k = (ul - j + kNumEdges) % kNumEdges;
    r.side_of_edge[j] = k;
    r.lines[j].ok = true;
    r.lines[j].point = 0.5 * (r.a[k] + r.b[k]);
    r.lines[j].direction = (r.b[k] - r.a[k]).normalized();
  }
  return r;
}

}  // namespace

// Sparse boards (a few scan lines): too few extremes per edge for four line fits, but the
// declared rectangle has only 3 degrees of freedom in the plane. Fit it to all extremes, each
// moved out by its expected inset, with every board point inside; its sides are the edges, the
// extremes each side owns its edge points.
bool extractEdgesByRectangle(const LidarCloud& cloud, const std::vector<ValidPoint>& pts,
                             const std::vector<int>& board, const Target& target,
                             const LidarBoardDetectorOptions& o, LidarBoardDetection* det) {
  auto& f = det->features;
  Eigen::Vector3d centroid;
  PlaneFrame frame;
  if (!boardFrameAtCentroid(pts, board, f.plane, &centroid, &frame)) return false;
  std::string source;
  const std::vector<int> line = scanLines(cloud, board, pts, o, &source);
  const double bloom = 0.5 * o.beam_divergence_deg * kRadPerDeg * centroid.norm();
  const SparseExtremes x = sparseExtremes(pts, board, line, frame, centroid, bloom, o);
  if (x.lines < o.min_scan_lines) return false;
  // Extremes scatter within a column step of the outline; the range noise moves them in-plane
  // only on tilted boards, the beam's bloom adds to the outside.
  const double tolerance =
      std::max(o.edge_inlier_threshold_m, x.column_m + 2.0 * bloom + 3.0 * o.range_noise_m);
  // Only the hull matters for "every board point inside".
  const auto fit = lidar_detail::fitRectangle(lidar_detail::convexHull(x.board2), x.extremes,
                                              x.insets, target.width, target.height, tolerance);
  if (!fit.ok || fit.rms_m > tolerance || fit.worst_outside_m > tolerance) return false;
  const RectangleSides sides = rectangleSides(fit);
  for (int j = 0; j < kNumEdges; ++j) f.edge_points[j].clear();
  for (size_t e = 0; e < x.extremes.size(); ++e) {
    int owner = 0;
    for (int j = 1; j < kNumEdges; ++j)
      if (sides.lines[j].distance(x.extremes[e]) < sides.lines[owner].distance(x.extremes[e]))
        owner = j;
    f.edge_points[owner].push_back(pts[x.index[e]].p);
  }
  for (int j = 0; j < kNumEdges; ++j)
    if (f.edge_points[j].empty()) return false;
  for (int j = 0; j < kNumEdges; ++j) {
    const auto& l = sides.lines[j];
    f.edge_valid[j] = true;
    f.edge_line_point[j] = frame.lift(l.point);
    f.edge_line_direction[j] =
        (frame.lift(l.point + l.direction) - frame.lift(l.point)).normalized();
    // Corner j = edge j x edge j+1: the end of side j shared with side j+1 (clockwise).
    f.corners[j] = frame.lift(sides.a[sides.side_of_edge[j]]);
  }
  det->num_scan_lines = x.lines;
  det->scan_line_source = source;
  f.measured_size_m = Eigen::Vector2d(target.width, target.height);
  f.reason =
      fmt("edges from the declared %.3f x %.3f m rectangle fitted to %.0f scan lines (RMS %.3f m)",
          target.width, target.height, x.lines, fit.rms_m);
  return true;
}

}  // namespace lidar_detail
}  // namespace board_calib
