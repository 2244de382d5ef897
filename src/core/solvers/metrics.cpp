// Quality figures that need no solver: MLRE and plane RMS for a given extrinsic.
#include <board_calib/core/common/edge_association.h>
#include <board_calib/core/solvers/solvers.h>

#include <cmath>

namespace board_calib {

namespace {

// Sum and count of the perpendicular pixel distances of the LiDAR edge points paired with
// image edges by the one association (core/common/edge_association.h); only image edge `only`
// when it is >= 0.
void accumulateView(const View& view, const Eigen::Isometry3d& camera_T_lidar, int only,
                    double* sum, int* count) {
  const EdgeAssociation a = associateEdges(view.camera, view.lidar, camera_T_lidar);
  for (int j = 0; j < kNumEdges; ++j) {
    if (!a.scored[j] || (only >= 0 && j != only)) continue;
    int n = 0;
    const double mean = edgeLineDistancePx(view.camera, j, view.lidar.edge_points[a.lidar_edge[j]],
                                           camera_T_lidar, &n);
    *sum += mean * n;
    *count += n;
  }
}

std::optional<double> mean(double sum, int count) {
  if (count == 0) return std::nullopt;
  return sum / count;
}

}  // namespace

std::optional<double> edgeLineReprojectionErrorPx(const View& view, int edge,
                                                  const Eigen::Isometry3d& camera_T_lidar) {
  if (edge < 0 || edge >= kNumEdges) return std::nullopt;
  double sum = 0.0;
  int count = 0;
  accumulateView(view, camera_T_lidar, edge, &sum, &count);
  return mean(sum, count);
}

std::optional<double> viewLineReprojectionErrorPx(const View& view,
                                                  const Eigen::Isometry3d& camera_T_lidar) {
  double sum = 0.0;
  int count = 0;
  accumulateView(view, camera_T_lidar, -1, &sum, &count);
  return mean(sum, count);
}

std::optional<double> meanLineReprojectionErrorPx(const std::vector<View>& views,
                                                  const Eigen::Isometry3d& camera_T_lidar) {
  double sum = 0.0;
  int count = 0;
  for (const View& view : views) accumulateView(view, camera_T_lidar, -1, &sum, &count);
  return mean(sum, count);
}

std::optional<double> planeRmsM(const std::vector<View>& views,
                                const Eigen::Isometry3d& camera_T_lidar) {
  double sum = 0.0;
  int count = 0;
  for (const View& view : views) {
    if (!view.camera.found || !view.camera.plane.normal.allFinite()) continue;
    for (const Eigen::Vector3d& q : view.lidar.board_points) {
      const double r = view.camera.plane.signedDistance(camera_T_lidar * q);
      if (!std::isfinite(r)) continue;
      sum += r * r;
      ++count;
    }
  }
  if (count == 0) return std::nullopt;
  return std::sqrt(sum / count);
}

}  // namespace board_calib
