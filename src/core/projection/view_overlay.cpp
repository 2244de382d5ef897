// One view drawn on its camera image (see view_overlay.h).
#include <board_calib/core/projection/view_overlay.h>

namespace board_calib {

std::string ViewOverlayStyle::validate() const {
  if (auto why = projection.validate(); !why.empty()) return "projection: " + why;
  if (auto why = points.validate(); !why.empty()) return "points: " + why;
  if (auto why = edges.validate(); !why.empty()) return "edges: " + why;
  return {};
}

Status drawViewOverlay(const View& view, const LidarCloud* cloud, const CameraModel& camera,
                       const Eigen::Isometry3d& camera_T_lidar, const ViewOverlayStyle& style,
                       cv::Mat* canvas, std::optional<EdgeCheck>* check) {
  if (auto why = style.validate(); !why.empty())
    return Status::failure("view overlay options: " + why);
  if (check) check->reset();
  LidarCloud board;
  if (!cloud) {
    board.frame_id = view.lidar.frame_id;
    board.stamp = view.lidar.stamp;
    for (const auto& p : view.lidar.board_points)
      board.points.push_back({static_cast<float>(p.x()), static_cast<float>(p.y()),
                              static_cast<float>(p.z()), 0.0f, -1});
    board.width = static_cast<int>(board.points.size());
  }
  if (auto projected =
          projectCloud(cloud ? *cloud : board, camera, camera_T_lidar, style.projection)) {
    if (Status st = drawProjectedCloud(*projected, style.points, canvas); !st) return st;
  }
  if (auto edges =
          checkProjectedEdges(view.lidar, view.camera, camera, camera_T_lidar, style.edges)) {
    if (Status st = drawEdgeCheck(view.camera, *edges, camera, style.edges, canvas); !st) return st;
    if (check) *check = std::move(*edges);
  }
  return Status::success();
}

std::optional<double> boardPointsInsideImageBoard(const LidarBoardFeatures& lidar,
                                                  const CameraBoardFeatures& image,
                                                  const Eigen::Isometry3d& camera_T_lidar) {
  if (!image.allEdgesValid() || lidar.board_points.empty()) return std::nullopt;
  int inside = 0;
  for (const auto& p : lidar.board_points) {
    const Eigen::Vector3d q = camera_T_lidar * p;
    if (!(q.z() > 0.0)) continue;
    const Eigen::Vector3d uv1 = image.K * (q / q.z());  // undistorted px, homogeneous
    bool in = true;
    // Each line's (a, b) is the outward normal: the interior gives a negative value.
    for (const auto& line : image.edge_lines) in = in && line.dot(uv1) < 0.0;
    inside += in ? 1 : 0;
  }
  return static_cast<double>(inside) / static_cast<double>(lidar.board_points.size());
}

}  // namespace board_calib
