// board_calib/image_board_detector: finds the calibration board in a camera image.
// Wiring only: Image + CameraInfo -> core image + CameraModel -> ImageBoardDetector ->
// board_calib/CameraBoard (header = image header). Lazy: subscribes to the camera only while
// `camera_board` or `debug_image` has a subscriber; the debug image is drawn only when watched.
#include "image_detector_options.h"

#include <board_calib/conversions.h>
#include <board_calib/core/image_detection/image_board_detector.h>
#include <board_calib/core/image_detection/image_board_tracker.h>

#include <cv_bridge/cv_bridge.h>
#include <diagnostic_updater/diagnostic_updater.h>
#include <dynamic_reconfigure/server.h>
#include <image_transport/image_transport.h>
#include <nodelet/nodelet.h>
#include <ros/ros.h>
#include <pluginlib/class_list_macros.hpp>

#include <deque>
#include <memory>
#include <mutex>
#include <optional>

namespace board_calib {
namespace {

constexpr double kDiagnosticsPeriodS = 1.0;
constexpr double kStatsWindowS = 10.0;  // input rate and detection ratio over this window
constexpr double kWarnThrottleS = 10.0;

}  // namespace

class ImageBoardDetectorNodelet : public nodelet::Nodelet {
 private:
  void onInit() override {
    ros::NodeHandle& nh = getNodeHandle();
    ros::NodeHandle& pnh = getPrivateNodeHandle();
    std::string target_file;
    if (!pnh.getParam("target_file", target_file)) {
      NODELET_FATAL("~target_file is required (board description YAML, see config/targets/)");
      return;
    }
    auto target = loadTarget(target_file);
    if (!target) {
      NODELET_FATAL_STREAM("~target_file: " << target.error());
      return;
    }
    target_ = *target;
    pnh.param<std::string>("image_transport", transport_, "raw");
    auto detector = ImageBoardDetector::create(target_, ImageBoardDetectorOptions{});
    if (!detector) {
      NODELET_FATAL_STREAM("detector: " << detector.error());
      return;
    }
    detector_.emplace(std::move(*detector));
    // Memory of the session: rectangles and lines that stay put are the scene (issue 14).
    pnh.param("session_memory", session_memory_, StaticMemoryOptions().enabled);
    if (session_memory_) {
      auto tracker = ImageBoardTracker::create(target_, ImageBoardDetectorOptions{});
      if (!tracker) {
        NODELET_FATAL_STREAM("session memory: " << tracker.error());
        return;
      }
      tracker_.emplace(std::move(*tracker));
    }

    it_ = std::make_unique<image_transport::ImageTransport>(nh);
    std::lock_guard<std::mutex> lock(connect_mutex_);
    board_pub_ = nh.advertise<CameraBoard>(
        "camera_board", 10, boost::bind(&ImageBoardDetectorNodelet::connectCb, this),
        boost::bind(&ImageBoardDetectorNodelet::connectCb, this));
    debug_pub_ =
        it_->advertise("debug_image", 1, boost::bind(&ImageBoardDetectorNodelet::connectCb, this),
                       boost::bind(&ImageBoardDetectorNodelet::connectCb, this));

    reconfigure_ = std::make_unique<dynamic_reconfigure::Server<ImageBoardDetectorConfig>>(
        reconfigure_mutex_, pnh);
    reconfigure_->setCallback([this](const ImageBoardDetectorConfig& config, uint32_t level) {
      reconfigure(config, level);
    });

    diagnostics_ = std::make_unique<diagnostic_updater::Updater>(nh, pnh);
    diagnostics_->setHardwareID("camera (" + std::string(targetTypeName(target_.type)) + " board)");
    diagnostics_->add("image board detection", this, &ImageBoardDetectorNodelet::diagnose);
    // The timer also re-checks the lazy subscription: a safety net should a connect callback be
    // missed.
    diagnostics_timer_ = nh.createWallTimer(ros::WallDuration(kDiagnosticsPeriodS),
                                            [this](const ros::WallTimerEvent&) {
                                              connectCb();
                                              diagnostics_->update();
                                            });
    NODELET_INFO_STREAM("image_board_detector: " << targetTypeName(target_.type) << " board from "
                                                 << target_file << ", transport '" << transport_
                                                 << "'");
  }

  void connectCb() {
    std::lock_guard<std::mutex> lock(connect_mutex_);
    const bool wanted = board_pub_.getNumSubscribers() > 0 || debug_pub_.getNumSubscribers() > 0;
    if (wanted && !camera_sub_) {
      camera_sub_ =
          it_->subscribeCamera("image_raw", 1, &ImageBoardDetectorNodelet::imageCb, this,
                               image_transport::TransportHints(transport_, ros::TransportHints(),
                                                               getPrivateNodeHandle()));
    } else if (!wanted && camera_sub_) {
      camera_sub_.shutdown();
    }
  }

  void reconfigure(const ImageBoardDetectorConfig& config, uint32_t /*level*/) {
    const ImageBoardDetectorOptions options = optionsFromConfig(config);
    if (const std::string why = options.validate(); !why.empty()) {
      NODELET_WARN_STREAM("dynamic_reconfigure rejected: " << why
                                                           << " (keeping the previous options)");
      return;
    }
    auto detector = ImageBoardDetector::create(target_, options);
    if (!detector) {
      NODELET_WARN_STREAM("dynamic_reconfigure rejected: " << detector.error());
      return;
    }
    std::lock_guard<std::mutex> lock(detector_mutex_);
    detector_.emplace(std::move(*detector));
    if (tracker_) tracker_->setDetectorOptions(options);  // validated above; the memory is kept
  }

  // Camera model from CameraInfo, re-created only when the calibration changes.
  const CameraModel* cameraModel(const sensor_msgs::CameraInfo& info,
                                 const sensor_msgs::Image& image) {
    if (info.K[0] == 0.0 || info.K[4] == 0.0) {
      NODELET_WARN_THROTTLE(kWarnThrottleS,
                            "camera_info (frame '%s') has a zero K: the camera is not calibrated",
                            info.header.frame_id.c_str());
      return nullptr;
    }
    if (info.width != image.width || info.height != image.height) {
      NODELET_WARN_THROTTLE(
          kWarnThrottleS, "camera_info is %ux%u but the image is %ux%u (frame '%s'): skipping",
          info.width, info.height, image.width, image.height, image.header.frame_id.c_str());
      return nullptr;
    }
    if (camera_ && sameCameraInfo(info, last_info_)) return &*camera_;
    auto intrinsics = fromCameraInfo(info);
    if (!intrinsics) {
      NODELET_WARN_THROTTLE(kWarnThrottleS, "camera_info (frame '%s'): %s",
                            info.header.frame_id.c_str(), intrinsics.error().c_str());
      return nullptr;
    }
    auto camera = CameraModel::create(*intrinsics);
    if (!camera) {
      NODELET_WARN_THROTTLE(kWarnThrottleS, "camera_info (frame '%s'): %s",
                            info.header.frame_id.c_str(), camera.error().c_str());
      return nullptr;
    }
    camera_ = *camera;
    last_info_ = info;
    return &*camera_;
  }

  void imageCb(const sensor_msgs::ImageConstPtr& image_msg,
               const sensor_msgs::CameraInfoConstPtr& info_msg) {
    const ros::WallTime now = ros::WallTime::now();
    const CameraModel* camera = cameraModel(*info_msg, *image_msg);
    if (!camera) return record(now, false, "bad camera_info");
    auto image = imageFromMsg(*image_msg);
    if (!image) {
      NODELET_WARN_THROTTLE(kWarnThrottleS, "image (frame '%s', encoding '%s'): %s",
                            image_msg->header.frame_id.c_str(), image_msg->encoding.c_str(),
                            image.error().c_str());
      return record(now, false, "bad image: " + image.error());
    }
    ImageDetection detection;
    {
      std::lock_guard<std::mutex> lock(detector_mutex_);
      // The memory resets itself when time goes back (a bag replayed again).
      detection = tracker_ ? tracker_->detect(*image, *camera, image_msg->header.stamp.toSec())
                           : detector_->detect(*image, *camera);
    }
    CameraBoardFeatures& f = detection.features;
    f.frame_id = image_msg->header.frame_id;
    f.stamp = image_msg->header.stamp.toSec();
    if (board_pub_.getNumSubscribers() > 0) {
      CameraBoard msg = toMsg(f);
      msg.header = image_msg->header;
      board_pub_.publish(msg);
    }
    if (debug_pub_.getNumSubscribers() > 0)
      debug_pub_.publish(cv_bridge::CvImage(image_msg->header, "bgr8",
                                            drawImageDetection(*image, *camera, detection))
                             .toImageMsg());
    record(now, f.found, f.found ? "" : f.reason, detection.details.time_ms);
  }

  void record(const ros::WallTime& now, bool found, const std::string& reason,
              double time_ms = 0.0) {
    std::lock_guard<std::mutex> lock(stats_mutex_);
    history_.push_back({now, found});
    while (!history_.empty() && (now - history_.front().first).toSec() > kStatsWindowS)
      history_.pop_front();
    last_reason_ = reason;
    last_time_ms_ = time_ms;
  }

  void diagnose(diagnostic_updater::DiagnosticStatusWrapper& stat) {
    std::lock_guard<std::mutex> lock(stats_mutex_);
    const ros::WallTime now = ros::WallTime::now();
    while (!history_.empty() && (now - history_.front().first).toSec() > kStatsWindowS)
      history_.pop_front();
    int found = 0;
    for (const auto& h : history_) found += h.second;
    const double rate = history_.size() / kStatsWindowS;
    const double ratio = history_.empty() ? 0.0 : static_cast<double>(found) / history_.size();
    stat.add("input rate (Hz)", rate);
    stat.add("detection ratio", ratio);
    stat.add("last detection time (ms)", last_time_ms_);
    stat.add("last reason", last_reason_);
    stat.add("subscribed", static_cast<bool>(camera_sub_));
    if (!camera_sub_)
      stat.summary(diagnostic_msgs::DiagnosticStatus::OK, "idle (no subscribers)");
    else if (history_.empty())
      stat.summary(diagnostic_msgs::DiagnosticStatus::WARN, "no images");
    else if (found == 0)
      stat.summary(diagnostic_msgs::DiagnosticStatus::WARN, "no board: " + last_reason_);
    else
      stat.summary(diagnostic_msgs::DiagnosticStatus::OK, "board found");
  }

  Target target_;
  std::string transport_;
  std::optional<ImageBoardDetector> detector_;
  bool session_memory_ = StaticMemoryOptions().enabled;
  std::optional<ImageBoardTracker> tracker_;  // with session_memory_: one memory per camera
  std::mutex detector_mutex_;
  std::optional<CameraModel> camera_;
  sensor_msgs::CameraInfo last_info_;

  std::unique_ptr<image_transport::ImageTransport> it_;
  std::mutex connect_mutex_;
  image_transport::CameraSubscriber camera_sub_;
  ros::Publisher board_pub_;
  image_transport::Publisher debug_pub_;

  boost::recursive_mutex reconfigure_mutex_;
  std::unique_ptr<dynamic_reconfigure::Server<ImageBoardDetectorConfig>> reconfigure_;
  std::unique_ptr<diagnostic_updater::Updater> diagnostics_;
  ros::WallTimer diagnostics_timer_;

  std::mutex stats_mutex_;
  std::deque<std::pair<ros::WallTime, bool>> history_;
  std::string last_reason_;
  double last_time_ms_ = 0.0;
};

}  // namespace board_calib

PLUGINLIB_EXPORT_CLASS(board_calib::ImageBoardDetectorNodelet, nodelet::Nodelet)
