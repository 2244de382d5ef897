// Ground truth of a simulated LiDAR board for the detector tests: its plane, its corners in the
// detector's order, the error of a detected edge line against the true edge, a candidate's log line.
#pragma once

#include <board_calib/core/features.h>
#include <board_calib/core/lidar_detection/lidar_board_detector.h>
#include <board_calib/core/sim/simulator.h>
#include <board_calib/core/target.h>
#include <board_calib/core/transform.h>

#include <Eigen/Geometry>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <vector>

namespace board_calib {
namespace lidar_truth {

/// Issue target: a detected edge line within 1.5 cm of the true edge at 3 m.
constexpr double kMaxEdgeLineM = 0.015;

inline Target plainBoard() {
  Target t;
  t.type = TargetType::kPlain;
  t.width = 1.016;
  t.height = 1.016;
  return t;
}

struct Truth {
  Plane plane;
  std::array<Eigen::Vector3d, 4> corners;  // top, right, bottom, left (detector convention)
};

inline Truth truthOf(const Target& target, const Eigen::Isometry3d& lidar_T_board) {
  Truth t;
  t.plane.normal = lidar_T_board.linear().col(2);
  t.plane.offset = t.plane.normal.dot(lidar_T_board.translation());
  std::array<Eigen::Vector3d, 4> c;
  const auto outer = target.outerCorners();
  for (int i = 0; i < 4; ++i) c[i] = lidar_T_board * outer[i];
  // Top = highest; bottom = lowest; of the other two, right = smaller azimuth (seen from the
  // LiDAR).
  std::array<int, 4> idx = {0, 1, 2, 3};
  std::sort(idx.begin(), idx.end(), [&](int a, int b) { return c[a].z() > c[b].z(); });
  const int top = idx[0], bottom = idx[3];
  int right = idx[1], left = idx[2];
  if (std::atan2(c[right].y(), c[right].x()) > std::atan2(c[left].y(), c[left].x()))
    std::swap(right, left);
  t.corners = {c[top], c[right], c[bottom], c[left]};
  return t;
}

// RMS distance between the detected edge line and the true edge segment, along the segment.
inline double edgeLineError(const LidarBoardFeatures& f, int j, const Truth& truth) {
  const Eigen::Vector3d a = truth.corners[(j + 3) % 4], b = truth.corners[j];
  auto dist = [&](const Eigen::Vector3d& p) {
    const Eigen::Vector3d d = p - f.edge_line_point[j];
    return (d - d.dot(f.edge_line_direction[j]) * f.edge_line_direction[j]).norm();
  };
  double sum = 0.0;
  constexpr int kSamples = 11;
  for (int k = 0; k < kSamples; ++k) sum += std::pow(dist(a + (b - a) * k / (kSamples - 1.0)), 2);
  return std::sqrt(sum / kSamples);
}

// Elevation gap (rad) between the two beams around the direction of `p` (LiDAR frame).
inline double sampleRingSpacingRad(const sim::LidarSpec& spec, const Eigen::Vector3d& p) {
  std::vector<double> el = spec.elevations_deg;
  std::sort(el.begin(), el.end());
  const double e = std::atan2(p.z(), std::hypot(p.x(), p.y())) / kRadPerDeg;
  auto it = std::lower_bound(el.begin(), el.end(), e);
  if (it == el.begin()) it = el.begin() + 1;
  if (it == el.end()) it = el.end() - 1;
  return (*it - *(it - 1)) * kRadPerDeg;
}

/// One line per detector candidate, for the log of a missed board.
inline void printCandidate(const LidarBoardCandidate& c) {
  std::printf(
      "    cand n=%d at (%.2f %.2f %.2f) rect %.2f x %.2f fill %.2f rms %.3f score %.1f %s\n",
      c.num_points, c.centroid.x(), c.centroid.y(), c.centroid.z(), c.rectangle_m.x(),
      c.rectangle_m.y(), c.fill_ratio, c.rms_m, c.score, c.rejected_because.c_str());
}

}  // namespace lidar_truth
}  // namespace board_calib
