// Projection of LiDAR data into camera images, the visual check of a calibration: a cloud drawn
// onto the raw image (coloured by depth or intensity, occlusion-culled), the image edge lines
// and the projected LiDAR edge points with their residuals (the reference paper's "projected
// edges" check), and a cloud coloured from the image. ROS-free; images are cv::Mat, raw
// (distorted) pixels unless a name says "undistorted".
#pragma once

#include <board_calib/core/camera_model.h>
#include <board_calib/core/features.h>
#include <board_calib/core/lidar_detection/lidar_cloud.h>

#include <opencv2/core.hpp>

#include <array>
#include <cstdint>
#include <string>
#include <vector>

namespace board_calib {

enum class ColorMode { kDepth, kIntensity, kFlat };
const char* colorModeName(ColorMode mode);
/// "depth", "intensity", "flat".
Expected<ColorMode> parseColorMode(const std::string& name);

struct ProjectionOptions {
  double min_depth_m = 0.3;  ///< m, points nearer to the camera (along its z) are dropped
  double max_depth_m =
      30.0;  ///< m, points farther are dropped; also the top of the depth colour scale
  /// Occlusion culling: the image is split into square cells of this size and a point is
  /// dropped when the nearest point of its cell is closer by more than occlusion_tolerance_m
  /// (the LiDAR sees things the camera cannot, e.g. behind the board's edge). 0 disables it.
  int zbuffer_cell_px = 6;             ///< px
  double occlusion_tolerance_m = 0.3;  ///< m
  double margin_px = 0.0;  ///< px, how far outside the image a projected point is still kept
  std::string validate() const;
};

/// One visible point after culling.
struct ProjectedPoint {
  float u = 0, v = 0;  ///< raw (distorted) px
  float depth = 0;     ///< m, camera z
  float intensity = 0;
  int index = 0;  ///< index into LidarCloud::points
};

struct ProjectedCloud {
  std::vector<ProjectedPoint> points;
  int invalid = 0;       ///< NaN or zero-range returns
  int out_of_range = 0;  ///< behind the camera or outside [min_depth_m, max_depth_m]
  int outside_image =
      0;             ///< in front but not inside the image (or folding back through distortion)
  int occluded = 0;  ///< removed by the z-buffer
};

/// Projects a cloud into the image with camera_T_lidar (p_camera = camera_T_lidar * p_lidar).
/// Culls invalid, behind-camera and far-off-axis points by the undistorted ray before
/// distorting (CameraModel::isVisible), then applies the z-buffer.
Expected<ProjectedCloud> projectCloud(const LidarCloud& cloud, const CameraModel& camera,
                                      const Eigen::Isometry3d& camera_T_lidar,
                                      const ProjectionOptions& options);

struct OverlayOptions {
  ColorMode color_mode = ColorMode::kDepth;
  double depth_min_m = 0.3;   ///< m, colour scale start (ColorMode::kDepth)
  double depth_max_m = 30.0;  ///< m, colour scale end
  /// Intensity colour scale; when intensity_max <= intensity_min the scale is taken from the
  /// 2nd and 98th percentiles of the visible points.
  double intensity_min = 0.0;
  double intensity_max = 0.0;
  int point_radius_px = 2;          ///< px, 0 draws single pixels
  double alpha = 1.0;               ///< opacity of the drawn points, 0..1
  cv::Vec3b flat_color{0, 255, 0};  ///< BGR for ColorMode::kFlat
  std::string validate() const;
};

/// Colour table used for depth and intensity (256 BGR entries, blue to red). Depth maps near
/// to red, intensity maps high to red.
const std::vector<cv::Vec3b>& colorTable();

/// Draws projected points onto a bgr8 image (mono8 is converted to bgr8 first). Points are
/// drawn far to near so nearer points stay on top.
Status drawProjectedCloud(const ProjectedCloud& projected, const OverlayOptions& options,
                          cv::Mat* image);

/// Draws a line a*u + b*v + c = 0 given in *undistorted* pixels onto the raw image: the line is
/// sampled every sample_step_px, each sample distorted, and the visible samples joined.
/// Returns the number of drawn segments (0 when the line misses the image).
struct LineStyle {
  cv::Vec3b color{255, 255, 0};  ///< BGR
  int thickness_px = 2;          ///< px
  double sample_step_px = 8.0;   ///< px, along the undistorted line
};
int drawUndistortedLine(const Eigen::Vector3d& line, const CameraModel& camera,
                        const LineStyle& style, cv::Mat* image);
/// Same for the segment between two undistorted pixels.
int drawUndistortedSegment(const Eigen::Vector2d& from, const Eigen::Vector2d& to,
                           const CameraModel& camera, const LineStyle& style, cv::Mat* image);

/// The "projected edges" check: LiDAR edge points projected with an estimate against the
/// image edge lines.
struct EdgeCheckOptions {
  /// Pair LiDAR edges with image lines by projection (core/common/edge_association.h, as the
  /// solvers do) instead of by index (the detectors may name the edges differently).
  bool reassociate = true;
  double residual_scale_px = 5.0;  ///< px, residual drawn fully magenta (0 px is white)
  int point_radius_px = 4;         ///< px
  LineStyle line_style;
  bool annotate = true;  ///< write the MLRE in the image's top-left corner
  std::string validate() const;
};

struct EdgePointCheck {
  Eigen::Vector2d pixel = Eigen::Vector2d::Zero();  ///< raw px where the point is drawn
  double residual_px = 0.0;  ///< perpendicular distance to its image line, undistorted px
};

struct EdgeCheck {
  std::array<std::vector<EdgePointCheck>, kNumEdges> points;  ///< per LiDAR edge, visible points
  std::array<int, kNumEdges> image_edge{
      {-1, -1, -1, -1}};  ///< image line each LiDAR edge was scored against
  std::array<double, kNumEdges> mean_residual_px{};  ///< per LiDAR edge, NaN when empty
  double mlre_px = 0.0;                              ///< mean over all scored points
  int num_points = 0;                                ///< scored points
};

/// Scores the LiDAR edge points against the image lines (undistorted px). Fails with a reason
/// when nothing can be scored (no valid edges, all points behind the camera or off-image).
Expected<EdgeCheck> checkProjectedEdges(const LidarBoardFeatures& lidar,
                                        const CameraBoardFeatures& image, const CameraModel& camera,
                                        const Eigen::Isometry3d& camera_T_lidar,
                                        const EdgeCheckOptions& options);

/// Draws the image lines and the scored points (green -> red by residual) and the MLRE.
Status drawEdgeCheck(const CameraBoardFeatures& image, const EdgeCheck& check,
                     const CameraModel& camera, const EdgeCheckOptions& options,
                     cv::Mat* bgr_image);

/// A LiDAR point with the colour of the image pixel it projects to.
struct ColoredPoint {
  float x = 0, y = 0, z = 0;  ///< m, LiDAR frame
  float intensity = 0;
  std::uint8_t r = 0, g = 0, b = 0;
};

struct ColoredCloud {
  std::string frame_id;              ///< the LiDAR frame
  double stamp = 0.0;                ///< s
  std::vector<ColoredPoint> points;  ///< only points the camera sees (after the z-buffer)
};

/// Colours the visible points of `cloud` from a bgr8 or mono8 image (bilinear sampling).
Expected<ColoredCloud> colorCloud(const LidarCloud& cloud, const ProjectedCloud& projected,
                                  const cv::Mat& image);

/// The four image corners' viewing rays scaled to depth_m (camera frame; top-left, top-right,
/// bottom-right, bottom-left): the far face of the camera frustum, for markers.
std::array<Eigen::Vector3d, 4> frustumCorners(const CameraModel& camera, double depth_m);

}  // namespace board_calib
