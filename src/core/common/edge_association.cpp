// LiDAR edge <-> image edge line association by projection (see the header for the policy).
#include <board_calib/core/common/edge_association.h>

#include <algorithm>
#include <cmath>
#include <limits>

namespace board_calib {

namespace {

// The best permutation must halve the summed distance of the detectors' naming to replace it.
constexpr double kRelabelGain = 2.0;

bool usableLine(const CameraBoardFeatures& image, int j) {
  const Eigen::Vector3d& l = image.edge_lines[j];
  return image.edge_valid[j] && l.allFinite() && l.head<2>().norm() > 0.0;
}

struct Score {
  int matched = 0;
  double cost = 0.0;
};

Score scoreOf(const std::array<int, kNumEdges>& perm,
              const std::array<std::array<double, kNumEdges>, kNumEdges>& cost) {
  Score s;
  for (int j = 0; j < kNumEdges; ++j)
    if (std::isfinite(cost[j][perm[j]])) {
      s.cost += cost[j][perm[j]];
      ++s.matched;
    }
  return s;
}

}  // namespace

double edgeLineDistancePx(const Eigen::Matrix3d& K, const CameraBoardFeatures& image,
                          int image_edge, const Points3& lidar_points,
                          const Eigen::Isometry3d& camera_T_lidar, int* count) {
  const Eigen::Vector3d& l = image.edge_lines[image_edge];
  const double norm = l.head<2>().norm();
  double sum = 0.0;
  *count = 0;
  for (const Eigen::Vector3d& q : lidar_points) {
    const Eigen::Vector3d p = camera_T_lidar * q;
    if (!p.allFinite() || !(p.z() > 0.0)) continue;
    sum += std::abs(l.dot(K * (p / p.z()))) / norm;
    ++*count;
  }
  return *count > 0 ? sum / *count : std::numeric_limits<double>::infinity();
}

EdgeAssociation associateEdges(const Eigen::Matrix3d& K, const CameraBoardFeatures& image,
                               const LidarBoardFeatures& lidar,
                               const Eigen::Isometry3d& camera_T_lidar, int min_lidar_points) {
  std::array<std::array<double, kNumEdges>, kNumEdges> cost;  // [image edge][LiDAR edge]
  for (int j = 0; j < kNumEdges; ++j)
    for (int k = 0; k < kNumEdges; ++k) {
      cost[j][k] = std::numeric_limits<double>::infinity();
      if (!usableLine(image, j) || !lidar.edge_valid[k] ||
          static_cast<int>(lidar.edge_points[k].size()) < min_lidar_points)
        continue;
      int count = 0;
      cost[j][k] = edgeLineDistancePx(K, image, j, lidar.edge_points[k], camera_T_lidar, &count);
    }
  const std::array<int, kNumEdges> named{{0, 1, 2, 3}};
  const Score named_score = scoreOf(named, cost);
  std::array<int, kNumEdges> perm = named, best = named;
  Score best_score = named_score;
  do {
    const Score s = scoreOf(perm, cost);
    if (s.matched > best_score.matched ||
        (s.matched == best_score.matched && s.cost < best_score.cost)) {
      best = perm;
      best_score = s;
    }
  } while (std::next_permutation(perm.begin(), perm.end()));
  const bool relabel = best != named && (best_score.matched > named_score.matched ||
                                         best_score.cost * kRelabelGain < named_score.cost);
  EdgeAssociation a;
  a.lidar_edge = relabel ? best : named;
  a.relabelled = relabel;
  for (int j = 0; j < kNumEdges; ++j) {
    a.mean_px[j] = cost[j][a.lidar_edge[j]];
    a.scored[j] = std::isfinite(a.mean_px[j]);
    a.matched += a.scored[j] ? 1 : 0;
  }
  return a;
}

}  // namespace board_calib
