// The one place where ROS messages meet core types. Heavy headers (pcl_conversions, PCL)
// stay out of here on purpose.
#pragma once

#include <board_calib/core/camera_model.h>
#include <board_calib/core/features.h>
#include <board_calib/core/lidar_detection/lidar_cloud.h>
#include <board_calib/core/msg_graph/msg_graph.h>
#include <board_calib/core/projection/projection.h>
#include <board_calib/core/result_io.h>
#include <board_calib/core/solvers/solvers.h>
#include <board_calib/core/verdict/verdict.h>

#include <board_calib/CalibrationResult.h>
#include <board_calib/CameraBoard.h>
#include <board_calib/LidarBoard.h>
#include <board_calib/SensorPose.h>
#include <geometry_msgs/Point.h>
#include <geometry_msgs/Pose.h>
#include <visualization_msgs/MarkerArray.h>
#include <geometry_msgs/Transform.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>
#include <sensor_msgs/PointCloud2.h>
#include <opencv2/core.hpp>

namespace board_calib {

struct RigPairRun;  // core/pipeline/rig_calibration.h

// Validation of incoming messages, before any pointer arithmetic: each returns an empty string
// for a usable message, else a specific reason naming the field and value. The from*()
// conversions below run it first, so a caller only logs the reason and goes on.

/// Sizes 1..65536 px, K and D finite, fx, fy > 0, at most 14 coefficients.
std::string validateCameraInfo(const sensor_msgs::CameraInfo& info);
/// x/y/z float32/float64; every read field's offset+count*size inside point_step (known
/// datatypes); row_step >= width*point_step; data >= height*row_step (64-bit arithmetic);
/// at most 2^24 points. Either endianness (converted).
std::string validatePointCloud2(const sensor_msgs::PointCloud2& msg);
/// Sides 1..65536 px; supported encoding; step >= width*bytes per pixel; height*step < 2 GiB
/// and <= data size (64-bit arithmetic); foreign byte order only for mono16/16UC1 (converted).
std::string validateImage(const sensor_msgs::Image& msg);
/// Finite translation and rotation, quaternion with |q|^2 within 0.01 of 1 (tf2's tolerance).
std::string validateTransform(const geometry_msgs::Transform& msg);

/// CameraInfo -> intrinsics (validateCameraInfo first; CameraModel::create checks the rest).
Expected<CameraIntrinsics> fromCameraInfo(const sensor_msgs::CameraInfo& info);
sensor_msgs::CameraInfo toCameraInfo(const CameraIntrinsics& intrinsics);

/// PointCloud2 -> core cloud. Needs float32 x/y/z; takes intensity (any numeric type) and ring
/// (uint8/uint16/int/float; out of 0..65535 -> -1) when present. Fails with
/// validatePointCloud2's reason.
Expected<LidarCloud> fromPointCloud2(const sensor_msgs::PointCloud2& msg);
/// Core cloud -> PointCloud2 with x y z intensity (float32) and ring (uint16, when present).
sensor_msgs::PointCloud2 toPointCloud2(const LidarCloud& cloud);

/// Image-coloured cloud -> PointCloud2 with x y z intensity (float32) and rgb (float32 holding
/// packed 0x00RRGGBB, the PCL/rviz convention), unorganized.
sensor_msgs::PointCloud2 toPointCloud2(const ColoredCloud& cloud);

/// Image -> cv::Mat: bgr8 for colour and Bayer input, mono8 for mono8/mono16 (16-bit scaled
/// to 8 bits by its maximum, either byte order). Fails with validateImage's reason.
Expected<cv::Mat> imageFromMsg(const sensor_msgs::Image& msg);
/// cv::Mat (CV_8UC3 as bgr8, CV_8UC1 as mono8) -> Image with the given header.
Expected<sensor_msgs::Image> imageToMsg(const cv::Mat& image, const std_msgs::Header& header);

LidarBoard toMsg(const LidarBoardFeatures& features);
LidarBoardFeatures fromMsg(const LidarBoard& msg);
CameraBoard toMsg(const CameraBoardFeatures& features);
CameraBoardFeatures fromMsg(const CameraBoard& msg);

geometry_msgs::Transform toTransformMsg(const Eigen::Isometry3d& T);
Eigen::Isometry3d fromTransformMsg(const geometry_msgs::Transform& msg);
geometry_msgs::Pose toPoseMsg(const Eigen::Isometry3d& T);
geometry_msgs::Point toPointMsg(const Eigen::Vector3d& p);

/// Same image size, K, D and distortion model: the cached camera model still applies
/// (CameraInfo arrives with every image).
bool sameCameraInfo(const sensor_msgs::CameraInfo& a, const sensor_msgs::CameraInfo& b);
Eigen::Isometry3d fromPoseMsg(const geometry_msgs::Pose& msg);

/// One pair method's solution -> CalibrationResult (stamped `stamp`, frames from `file`). The
/// uncertainty is the verdict's (never below the cross-validation's spread) once judged;
/// success needs the solve and a verdict other than failed.
CalibrationResult toResultMsg(const CalibrationSolution& solution, const VerdictReport& verdict,
                              const ResultFile& file, const ros::Time& stamp);
/// One camera <- LiDAR pair of a rig run: `pair` is the result-file entry of `run` (same order),
/// with its verdict; success unless the verdict failed. NaN 1 sigma without a covariance.
CalibrationResult toPairResultMsg(const PairEntry& pair, const RigPairRun& run,
                                  const multi_sensor::MsgSolution& solution,
                                  const ros::Time& stamp);
/// One POINTS marker per view (its LiDAR board points, in the LiDAR frame), coloured by the
/// view's plane residual under `solution` relative to the median view's: green at or below the
/// median, red at 3x or worse (the report's outlier factor); white before any solve (null).
/// Relative, because the absolute plane RMS follows the LiDAR's range noise. A DELETEALL first.
visualization_msgs::MarkerArray toViewMarkers(const std::vector<View>& views,
                                              const CalibrationSolution* solution);
/// One sensor's pose of a rig solve.
SensorPose toSensorPoseMsg(const multi_sensor::SensorEstimate& sensor);

}  // namespace board_calib
