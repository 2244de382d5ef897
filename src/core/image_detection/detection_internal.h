// Private helpers shared by the three board detectors (not installed, not public API).
#pragma once

#include <board_calib/core/image_board_detector.h>

#include <opencv2/core.hpp>

namespace board_calib {
namespace image_detection {

/// Result of a PnP fit on undistorted pixels (zero distortion, camera K).
struct PoseFit {
  bool ok = false;
  std::string reason;
  Eigen::Isometry3d camera_T_board = Eigen::Isometry3d::Identity();
  double rms_px = 0.0;
  std::vector<double> errors_px;
  Eigen::Matrix<double, 6, 6> covariance = Eigen::Matrix<double, 6, 6>::Zero();
};

/// PnP on coplanar board points (z = 0) seen at undistorted pixels: IPPE, then Levenberg-Marquardt
/// when there are more than four points; covariance from the projection Jacobian.
PoseFit fitPose(const Points3& board_points, const Points2& pixels, const Eigen::Matrix3d& K, double sigma_floor_px);

/// Board plane in the camera frame from the pose: normal = board +z (away from the camera).
Plane planeFromPose(const Eigen::Isometry3d& camera_T_board);

/// Names edges by their outward normal angle (atan2(b, a), image v down). `angles` are in
/// clockwise image order when `cyclic` (then a cyclic shift is chosen); otherwise each edge gets
/// the nearest name and ties keep the edge with the larger weight. Returns the name per input, -1 if dropped.
std::vector<int> nameEdges(const std::vector<double>& angles, const std::vector<double>& weights, bool cyclic);

/// Outer edges, corners and validity derived from the pose and the target's outer size.
void outerEdgesFromPose(const Target& target, CameraBoardFeatures* features);

/// Grey conversion of a bgr8/mono8 image (shares data for mono8).
cv::Mat toGray(const cv::Mat& image);

/// Intersection of two lines (homogeneous), false when (nearly) parallel.
bool intersectLines(const Eigen::Vector3d& l1, const Eigen::Vector3d& l2, Eigen::Vector2d* point);

void detectPlain(const cv::Mat& gray, const CameraModel& camera, const Target& target,
                 const ImageBoardDetectorOptions& options, ImageDetection* out);
void detectCheckerboard(const cv::Mat& gray, const CameraModel& camera, const Target& target,
                        const ImageBoardDetectorOptions& options, ImageDetection* out);

}  // namespace image_detection
}  // namespace board_calib
