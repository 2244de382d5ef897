// One board view drawn on its raw camera image, as the reports show it, and how well the
// LiDAR's board lands on the camera's. The pair report and the rig report both draw with it, so
// an overlay means the same in both. ROS-free.
#pragma once

#include <board_calib/core/projection/projection.h>

#include <optional>

namespace board_calib {

struct ViewOverlayStyle {
  ProjectionOptions projection;
  OverlayOptions points;  ///< the projected cloud, or the LiDAR's board points without a cloud
  EdgeCheckOptions edges;
  std::string validate() const;
};

/// Draws onto `canvas` (the raw image, bgr8; mono8 is converted): the LiDAR points projected
/// with camera_T_lidar (the whole `cloud` when given, else the view's LiDAR board points), then
/// the projected-edges check of the view's LiDAR edges against its image lines. A part that
/// cannot be drawn (nothing in front of the camera, no edges) is left out; `check` (optional)
/// receives the edge check when there is one. Fails only on bad options or an unusable canvas.
Status drawViewOverlay(const View& view, const LidarCloud* cloud, const CameraModel& camera,
                       const Eigen::Isometry3d& camera_T_lidar, const ViewOverlayStyle& style,
                       cv::Mat* canvas, std::optional<EdgeCheck>* check = nullptr);

/// Share of the LiDAR's board points that project, with camera_T_lidar, inside the board's
/// outline in the image (its four edge lines, undistorted px); points behind the camera count
/// as outside. nullopt when the camera does not have all four lines or the LiDAR no board point.
std::optional<double> boardPointsInsideImageBoard(const LidarBoardFeatures& lidar,
                                                  const CameraBoardFeatures& image,
                                                  const Eigen::Isometry3d& camera_T_lidar);

}  // namespace board_calib
