// Quality figures that need no solver: MLRE and plane RMS for a given extrinsic.
#include <board_calib/core/solvers.h>

#include <cmath>

namespace board_calib {

namespace {

// Sum of perpendicular pixel distances of one LiDAR edge's points to one image line.
void accumulateEdge(const View& view, int image_edge, int lidar_edge, const Eigen::Isometry3d& camera_T_lidar,
                    double* sum, int* count) {
  const CameraBoardFeatures& cam = view.camera;
  if (!cam.edge_valid[image_edge] || !view.lidar.edge_valid[lidar_edge]) return;
  const Eigen::Vector3d& l = cam.edge_lines[image_edge];
  const double norm = l.head<2>().norm();
  if (!(norm > 0.0) || !l.allFinite()) return;
  for (const Eigen::Vector3d& q : view.lidar.edge_points[lidar_edge]) {
    const Eigen::Vector3d p = camera_T_lidar * q;
    if (!p.allFinite() || !(p.z() > 0.0)) continue;
    const Eigen::Vector3d uv1 = cam.K * (p / p.z());
    *sum += std::abs(l.dot(uv1)) / norm;
    ++*count;
  }
}

std::optional<double> mean(double sum, int count) {
  if (count == 0) return std::nullopt;
  return sum / count;
}

}  // namespace

std::optional<double> edgeLineReprojectionErrorPx(const View& view, int edge, const Eigen::Isometry3d& camera_T_lidar) {
  if (edge < 0 || edge >= kNumEdges) return std::nullopt;
  double sum = 0.0;
  int count = 0;
  accumulateEdge(view, edge, edge, camera_T_lidar, &sum, &count);
  return mean(sum, count);
}

std::optional<double> viewLineReprojectionErrorPx(const View& view, const Eigen::Isometry3d& camera_T_lidar) {
  double sum = 0.0;
  int count = 0;
  for (int j = 0; j < kNumEdges; ++j) accumulateEdge(view, j, j, camera_T_lidar, &sum, &count);
  return mean(sum, count);
}

std::optional<double> meanLineReprojectionErrorPx(const std::vector<View>& views,
                                                  const Eigen::Isometry3d& camera_T_lidar) {
  double sum = 0.0;
  int count = 0;
  for (const View& view : views)
    for (int j = 0; j < kNumEdges; ++j) accumulateEdge(view, j, j, camera_T_lidar, &sum, &count);
  return mean(sum, count);
}

std::optional<double> planeRmsM(const std::vector<View>& views, const Eigen::Isometry3d& camera_T_lidar) {
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
