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

// Sparse boards (a few scan lines): too few extremes per edge for four line fits, but the
// declared rectangle has only 3 degrees of freedom in the plane. Fit it to all extremes, each
// moved out by its expected inset (half a column step minus the beam's bloom, along the scan
// line), with every board point inside; its sides are the edges, the extremes each side owns
// its edge points.
bool extractEdgesByRectangle(const LidarCloud& cloud, const std::vector<ValidPoint>& pts,
                             const std::vector<int>& board, const Target& target,
                             const LidarBoardDetectorOptions& o, LidarBoardDetection* det) {
  auto& f = det->features;
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  for (int i : board) centroid += pts[i].p;
  centroid /= static_cast<double>(board.size());
  centroid -= f.plane.normal * f.plane.signedDistance(centroid);
  PlaneFrame frame;
  if (!makePlaneFrame(f.plane.normal, centroid, &frame)) return false;
  std::string source;
  const std::vector<int> line = scanLines(cloud, board, pts, o, &source);
  const double center_azimuth = std::atan2(centroid.y(), centroid.x());
  struct Extremes {
    int count = 0, left = -1, right = -1;
    double left_az = -std::numeric_limits<double>::infinity(),
           right_az = std::numeric_limits<double>::infinity();
  };
  std::map<int, Extremes> per_line;
  for (size_t k = 0; k < board.size(); ++k) {
    const double az =
        wrapAngle(std::atan2(pts[board[k]].p.y(), pts[board[k]].p.x()) - center_azimuth);
    Extremes& e = per_line[line[k]];
    ++e.count;
    if (az > e.left_az) {
      e.left_az = az;
      e.left = board[k];
    }
    if (az < e.right_az) {
      e.right_az = az;
      e.right = board[k];
    }
  }
  const double range = centroid.norm();
  const double bloom = 0.5 * o.beam_divergence_deg * kRadPerDeg * range;
  Points2 board2, extremes;
  std::vector<double> insets;
  std::vector<int> extreme_index;
  double gap_sum = 0.0;
  int lines = 0;
  for (int i : board) board2.push_back(frame.project(pts[i].p));
  for (const auto& kv : per_line) {
    const Extremes& e = kv.second;
    if (e.count < o.min_points_per_scan_line || e.left == e.right) continue;
    ++lines;
    const Eigen::Vector2d a = frame.project(pts[e.left].p), b = frame.project(pts[e.right].p);
    const double gap = (b - a).norm() / (e.count - 1);
    gap_sum += gap;
    const double inset = o.correct_edge_sampling_bias ? std::max(0.0, 0.5 * gap - bloom) : 0.0;
    for (int idx : {e.left, e.right}) {
      extremes.push_back(frame.project(pts[idx].p));
      insets.push_back(inset);
      extreme_index.push_back(idx);
    }
  }
  if (lines < o.min_scan_lines) return false;
  const double column_m = gap_sum / lines;
  // Extremes scatter within a column step of the outline; the range noise moves them in-plane
  // only on tilted boards, the beam's bloom adds to the outside.
  const double tolerance =
      std::max(o.edge_inlier_threshold_m, column_m + 2.0 * bloom + 3.0 * o.range_noise_m);
  // Only the hull matters for "every board point inside".
  const auto fit = lidar_detail::fitRectangle(lidar_detail::convexHull(board2), extremes, insets,
                                              target.width, target.height, tolerance);
  if (!fit.ok || fit.rms_m > tolerance || fit.worst_outside_m > tolerance) return false;
  // Sides: outward normals of the four sides; UL is the one nearest to up-left (135 deg), then
  // clockwise UR, LR, LL.
  std::array<Eigen::Vector2d, kNumEdges> a, b;  // side endpoints, counter-clockwise corners
  std::array<double, kNumEdges> normal_angle;
  for (int k = 0; k < kNumEdges; ++k) {
    a[k] = fit.corners[k];
    b[k] = fit.corners[(k + 1) % kNumEdges];
    const Eigen::Vector2d d = b[k] - a[k];
    normal_angle[k] = std::atan2(-d.x(), d.y());  // ccw polygon: outward normal = (d.y, -d.x)
  }
  int ul = 0;
  auto angleTo = [](double x, double ref) { return std::abs(wrapAngle(x - ref)); };
  for (int k = 1; k < kNumEdges; ++k)
    if (angleTo(normal_angle[k], 0.75 * kPi) < angleTo(normal_angle[ul], 0.75 * kPi)) ul = k;
  // Clockwise from UL = backwards through the counter-clockwise sides.
  std::array<int, kNumEdges> side_of_edge;
  for (int j = 0; j < kNumEdges; ++j) side_of_edge[j] = (ul - j + kNumEdges) % kNumEdges;
  std::array<lidar_detail::LineFit2D, kNumEdges> lines2;
  for (int j = 0; j < kNumEdges; ++j) {
    const int k = side_of_edge[j];
    lines2[j].ok = true;
    lines2[j].point = 0.5 * (a[k] + b[k]);
    lines2[j].direction = (b[k] - a[k]).normalized();
    f.edge_points[j].clear();
  }
  for (size_t e = 0; e < extremes.size(); ++e) {
    int owner = 0;
    for (int j = 1; j < kNumEdges; ++j)
      if (lines2[j].distance(extremes[e]) < lines2[owner].distance(extremes[e])) owner = j;
    f.edge_points[owner].push_back(pts[extreme_index[e]].p);
  }
  std::string missing;
  for (int j = 0; j < kNumEdges; ++j)
    if (f.edge_points[j].empty()) missing += std::string(missing.empty() ? "" : ", ") + edgeName(j);
  if (!missing.empty()) return false;
  for (int j = 0; j < kNumEdges; ++j) {
    f.edge_valid[j] = true;
    f.edge_line_point[j] = frame.lift(lines2[j].point);
    f.edge_line_direction[j] =
        (frame.lift(lines2[j].point + lines2[j].direction) - frame.lift(lines2[j].point))
            .normalized();
    // Corner j = edge j x edge j+1: the end of side j shared with side j+1 (clockwise).
    const int k = side_of_edge[j];
    f.corners[j] = frame.lift(a[k]);
  }
  det->num_scan_lines = lines;
  det->scan_line_source = source;
  f.measured_size_m = Eigen::Vector2d(target.width, target.height);
  f.reason =
      fmt("edges from the declared %.3f x %.3f m rectangle fitted to %.0f scan lines (RMS %.3f m)",
          target.width, target.height, lines, fit.rms_m);
  return true;
}

}  // namespace lidar_detail
}  // namespace board_calib
