// Reads calibration data straight from rosbags (rosbag C++ API: no master, no sim time),
// converting to core types through the conversions unit. Used by calibrate_bag and tests.
#pragma once

#include <board_calib/core/camera_model.h>
#include <board_calib/core/lidar_detection/lidar_cloud.h>

#include <opencv2/core.hpp>

#include <functional>
#include <map>
#include <string>
#include <vector>

namespace board_calib {

struct ImageFrame {
  std::string topic;
  std::string frame_id;
  double stamp = 0.0;  ///< s, from the image header
  cv::Mat image;       ///< bgr8 (colour input) or mono8 (mono / 16-bit input)
};

struct BagCallbacks {
  /// Called for every image on a requested image topic, in bag order.
  std::function<void(const ImageFrame&)> on_image;
  /// Called for every CameraInfo on a requested camera_info topic.
  std::function<void(const std::string& topic, const std::string& frame_id,
                     const CameraIntrinsics&)>
      on_camera_info;
  /// Called for every cloud on a requested cloud topic.
  std::function<void(const std::string& topic, const LidarCloud&)> on_cloud;
  /// Called for a message that could not be converted (bad encoding, missing fields...).
  std::function<void(const std::string& topic, const std::string& reason)> on_bad_message;
};

struct BagTopics {
  std::vector<std::string> image_topics;
  std::vector<std::string> camera_info_topics;
  std::vector<std::string> cloud_topics;
};

/// Message counts per topic in the bags (for "missing topic" errors and progress).
Expected<std::map<std::string, size_t>> bagTopicCounts(const std::vector<std::string>& bag_paths);

/// Receive times (s, bag time, no deserialisation) of every message on `topic`.
Expected<std::vector<double>> topicTimes(const std::vector<std::string>& bag_paths,
                                         const std::string& topic);

/// Streams the requested topics of one or more bags, in time order. Fails with a one-line
/// reason when a bag cannot be opened or a requested topic is absent from every bag.
Status readBags(const std::vector<std::string>& bag_paths, const BagTopics& topics,
                const BagCallbacks& callbacks);

/// Frames as the pipelines take them: each image with the newest intrinsics of its camera.
struct BagFrameCallbacks {
  std::function<void(const ImageFrame&, const CameraIntrinsics&)> on_image;
  std::function<void(const std::string& topic, const LidarCloud&)> on_cloud;
  std::function<void(const std::string& topic, const std::string& reason)> on_bad_message;
};

struct BagFrameStats {
  std::map<std::string, size_t>
      images_before_info;  ///< image topic -> images held for a late first camera_info
  std::map<std::string, size_t>
      images_dropped;  ///< image topic -> images that found no camera_info
};

/// Images held per camera while its first camera_info has not arrived (recorders often start
/// the image topic first); later ones are dropped and counted.
constexpr size_t kMaxImagesBeforeCameraInfo = 20;

/// The one bag-reading loop of the tools: streams the bags as readBags does, pairing
/// `image_topics[i]` with `camera_info_topics[i]`; images wait for their camera's first
/// camera_info (see kMaxImagesBeforeCameraInfo).
Expected<BagFrameStats> readBagFrames(const std::vector<std::string>& bag_paths,
                                      const BagTopics& topics, const BagFrameCallbacks& callbacks);

}  // namespace board_calib
