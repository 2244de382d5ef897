// board_calib/cloud_board_detector: finds the calibration board in a LiDAR cloud.
// Wiring only: PointCloud2 -> core LidarCloud -> detectLidarBoard -> board_calib/LidarBoard.
// Lazy: subscribes to `points` only while an output has a subscriber (or a background capture
// is running); debug outputs are built only when someone listens.
#include "cloud_detector_options.h"

#include <board_calib/conversions.h>
#include <board_calib/core/lidar_detection/lidar_board_detector.h>

#include <diagnostic_updater/diagnostic_updater.h>
#include <dynamic_reconfigure/server.h>
#include <nodelet/nodelet.h>
#include <ros/ros.h>
#include <sensor_msgs/PointCloud2.h>
#include <std_srvs/Trigger.h>
#include <visualization_msgs/MarkerArray.h>
#include <pluginlib/class_list_macros.hpp>

#include <deque>
#include <memory>
#include <mutex>

namespace board_calib {
namespace {

constexpr double kDiagnosticsPeriodS = 1.0;
constexpr double kStatsWindowS = 10.0;  // input rate and detection ratio over this window
constexpr double kWarnThrottleS = 10.0;
constexpr double kMarkerLineWidthM = 0.01;
constexpr double kCornerMarkerSizeM = 0.04;
constexpr double kNormalArrowLengthM = 0.3;

LidarCloud pointsCloud(const std_msgs::Header& header, const Points3& points, float intensity) {
  LidarCloud c;
  c.frame_id = header.frame_id;
  c.stamp = header.stamp.toSec();
  c.width = static_cast<int>(points.size());
  c.height = 1;
  c.has_intensity = true;
  for (const auto& p : points) {
    LidarPoint q;
    q.x = static_cast<float>(p.x());
    q.y = static_cast<float>(p.y());
    q.z = static_cast<float>(p.z());
    q.intensity = intensity;
    c.points.push_back(q);
  }
  return c;
}

visualization_msgs::MarkerArray makeMarkers(const std_msgs::Header& header,
                                            const LidarBoardFeatures& f) {
  visualization_msgs::MarkerArray out;
  visualization_msgs::Marker clear;
  clear.header = header;
  clear.action = visualization_msgs::Marker::DELETEALL;
  out.markers.push_back(clear);
  if (!f.found) return out;
  auto base = [&](int id, int type, const std::string& ns) {
    visualization_msgs::Marker m;
    m.header = header;
    m.ns = ns;
    m.id = id;
    m.type = type;
    m.action = visualization_msgs::Marker::ADD;
    m.pose.orientation.w = 1.0;
    m.color.a = 1.0;
    return m;
  };
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();
  for (const auto& p : f.board_points) centre += p;
  if (!f.board_points.empty()) centre /= static_cast<double>(f.board_points.size());
  // Plane normal.
  auto normal = base(0, visualization_msgs::Marker::ARROW, "plane");
  normal.points = {toPointMsg(centre), toPointMsg(centre + kNormalArrowLengthM * f.plane.normal)};
  normal.scale.x = kMarkerLineWidthM;
  normal.scale.y = 2 * kMarkerLineWidthM;
  normal.color.b = 1.0;
  out.markers.push_back(normal);
  // Edges: valid ones red, between their corners when both exist, else along their points.
  auto edges = base(1, visualization_msgs::Marker::LINE_LIST, "edges");
  edges.scale.x = kMarkerLineWidthM;
  edges.color.r = 1.0;
  for (int j = 0; j < kNumEdges; ++j) {
    if (!f.edge_valid[j] || f.edge_points[j].empty()) continue;
    const Eigen::Vector3d& p0 = f.edge_line_point[j];
    const Eigen::Vector3d& d = f.edge_line_direction[j];
    double lo = 0, hi = 0;
    for (const auto& p : f.edge_points[j]) {
      lo = std::min(lo, (p - p0).dot(d));
      hi = std::max(hi, (p - p0).dot(d));
    }
    const int prev = (j + kNumEdges - 1) % kNumEdges;
    if (f.edge_valid[prev] && f.edge_valid[(j + 1) % kNumEdges]) {
      edges.points.push_back(toPointMsg(f.corners[prev]));
      edges.points.push_back(toPointMsg(f.corners[j]));
    } else {
      edges.points.push_back(toPointMsg(p0 + lo * d));
      edges.points.push_back(toPointMsg(p0 + hi * d));
    }
  }
  if (!edges.points.empty()) out.markers.push_back(edges);
  auto corners = base(2, visualization_msgs::Marker::SPHERE_LIST, "corners");
  corners.scale.x = corners.scale.y = corners.scale.z = kCornerMarkerSizeM;
  corners.color.g = 1.0;
  for (int j = 0; j < kNumEdges; ++j)
    if (f.edge_valid[j] && f.edge_valid[(j + 1) % kNumEdges])
      corners.points.push_back(toPointMsg(f.corners[j]));
  if (!corners.points.empty()) out.markers.push_back(corners);
  if (!f.reason.empty()) {
    auto text = base(3, visualization_msgs::Marker::TEXT_VIEW_FACING, "reason");
    text.pose.position = toPointMsg(centre + Eigen::Vector3d(0, 0, 0.8));
    text.scale.z = 0.08;
    text.color.r = text.color.g = text.color.b = 1.0;
    text.text = f.reason;
    out.markers.push_back(text);
  }
  return out;
}

}  // namespace

class CloudBoardDetectorNodelet : public nodelet::Nodelet {
 private:
  void onInit() override {
    ros::NodeHandle& nh = getNodeHandle();
    ros::NodeHandle& pnh = getPrivateNodeHandle();
    std::string target_file;
    if (!pnh.getParam("target_file", target_file) || target_file.empty()) {
      NODELET_FATAL(
          "cloud_board_detector: private parameter ~target_file (board description YAML) is "
          "required");
      return;
    }
    auto target = loadTarget(target_file);
    if (!target) {
      NODELET_FATAL("cloud_board_detector: cannot use target file '%s': %s", target_file.c_str(),
                    target.error().c_str());
      return;
    }
    target_ = *target;
    pnh.param("background_frames", background_frames_, 5);
    // Memory of the session: board-like planes that stay put are background (issue 14).
    pnh.param("session_memory", session_memory_, StaticMemoryOptions().enabled);
    tracker_ = std::make_unique<LidarBoardTracker>(target_);
    if (background_frames_ < 1) background_frames_ = 1;

    {
      // Connect callbacks run on the manager's threads, possibly while onInit is still here: they
      // wait for this lock, so they never read a publisher that is not assigned yet (a subscriber
      // connecting in that window was otherwise never served).
      std::lock_guard<std::mutex> lock(subscription_mutex_);
      auto connect = [this](const ros::SingleSubscriberPublisher&) { updateSubscription(); };
      board_pub_ = nh.advertise<LidarBoard>("lidar_board", 5, connect, connect);
      points_pub_ = nh.advertise<sensor_msgs::PointCloud2>("board_points", 1, connect, connect);
      edges_pub_ = nh.advertise<sensor_msgs::PointCloud2>("edge_points", 1, connect, connect);
      markers_pub_ = nh.advertise<visualization_msgs::MarkerArray>("markers", 1, connect, connect);
    }
    capture_srv_ =
        pnh.advertiseService("capture_background", &CloudBoardDetectorNodelet::onCapture, this);
    clear_srv_ =
        pnh.advertiseService("clear_background", &CloudBoardDetectorNodelet::onClear, this);

    reconfigure_ = std::make_unique<dynamic_reconfigure::Server<CloudBoardDetectorConfig>>(
        reconfigure_mutex_, pnh);
    reconfigure_->setCallback([this](CloudBoardDetectorConfig& config, uint32_t) {
      const LidarBoardDetectorOptions o = optionsFromConfig(config);
      const std::string bad = o.validate();
      std::lock_guard<std::mutex> lock(mutex_);
      if (!bad.empty()) {
        NODELET_WARN(
            "cloud_board_detector: rejected reconfiguration (%s); keeping the previous options",
            bad.c_str());
        return;
      }
      options_ = o;
      use_background_ = config.use_background;
    });

    diagnostics_.setHardwareID(
        "lidar board detector (" + std::string(targetTypeName(target_.type)) + " " +
        std::to_string(target_.width) + " x " + std::to_string(target_.height) + " m)");
    diagnostics_.add("cloud_board_detector", this, &CloudBoardDetectorNodelet::diagnose);
    // The timer also re-checks the lazy subscription: a safety net should a connect callback be
    // missed.
    diagnostics_timer_ = nh.createWallTimer(ros::WallDuration(kDiagnosticsPeriodS),
                                            [this](const ros::WallTimerEvent&) {
                                              updateSubscription();
                                              diagnostics_.update();
                                            });
    NODELET_INFO("cloud_board_detector: target %s %.3f x %.3f m from %s; waiting for subscribers",
                 targetTypeName(target_.type), target_.width, target_.height, target_file.c_str());
  }

  void updateSubscription() {
    std::lock_guard<std::mutex> lock(subscription_mutex_);
    const bool wanted = board_pub_.getNumSubscribers() > 0 || points_pub_.getNumSubscribers() > 0 ||
                        edges_pub_.getNumSubscribers() > 0 ||
                        markers_pub_.getNumSubscribers() > 0 || capturing_left_ > 0;
    if (wanted && !cloud_sub_) {
      cloud_sub_ =
          getNodeHandle().subscribe("points", 2, &CloudBoardDetectorNodelet::onCloud, this);
    } else if (!wanted && cloud_sub_) {
      cloud_sub_.shutdown();
    }
  }

  bool onCapture(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res) {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      background_.clear();
      capturing_left_ = background_frames_;
    }
    updateSubscription();
    res.success = true;
    res.message = "capturing the background from the next " + std::to_string(background_frames_) +
                  " clouds on " + getNodeHandle().resolveName("points") +
                  "; keep the board out of view";
    NODELET_INFO("cloud_board_detector: %s", res.message.c_str());
    return true;
  }

  bool onClear(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res) {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      background_.clear();
      capturing_left_ = 0;
    }
    updateSubscription();
    res.success = true;
    res.message = "background model cleared";
    return true;
  }

  void onCloud(const sensor_msgs::PointCloud2::ConstPtr& msg) {
    const std::string topic = getNodeHandle().resolveName("points");
    const ros::WallTime now = ros::WallTime::now();
    auto cloud = fromPointCloud2(*msg);
    if (!cloud) {
      NODELET_WARN_THROTTLE(kWarnThrottleS,
                            "cloud_board_detector: cloud on %s (frame '%s') rejected: %s",
                            topic.c_str(), msg->header.frame_id.c_str(), cloud.error().c_str());
      record(now, false, cloud.error());
      return;
    }
    LidarBoardDetectorOptions options;
    bool finished_capture = false;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (capturing_left_ > 0) {
        const Status st = background_.addFrame(*cloud);
        if (!st) {
          NODELET_WARN_THROTTLE(kWarnThrottleS,
                                "cloud_board_detector: background frame from %s (frame '%s'): %s",
                                topic.c_str(), msg->header.frame_id.c_str(), st.reason.c_str());
        } else if (--capturing_left_ == 0) {
          finished_capture = true;
          NODELET_INFO("cloud_board_detector: background model captured (%d clouds)",
                       background_.numFrames());
        }
      }
      options = options_;
    }
    if (finished_capture) updateSubscription();
    LidarBoardDetection det;
    {
      // The background model is read while detecting; captures do not run concurrently
      // because the subscription has a single callback queue per nodelet.
      std::lock_guard<std::mutex> lock(mutex_);
      const BackgroundModel* background =
          use_background_ && !background_.empty() && capturing_left_ == 0 ? &background_ : nullptr;
      if (session_memory_) {
        tracker_->setDetectorOptions(options);
        det = tracker_->detect(*cloud, background);
      } else {
        det = detectLidarBoard(*cloud, target_, options, background);
      }
    }
    if (det.code == LidarDetectionCode::kEmptyCloud ||
        det.code == LidarDetectionCode::kNoValidPoints ||
        det.code == LidarDetectionCode::kInvalidOptions) {
      NODELET_WARN_THROTTLE(kWarnThrottleS,
                            "cloud_board_detector: cloud on %s (frame '%s', %zu points): %s",
                            topic.c_str(), msg->header.frame_id.c_str(), cloud->points.size(),
                            det.features.reason.c_str());
    }
    record(now, det.features.found, det.features.reason);

    LidarBoard out = toMsg(det.features);
    out.header = msg->header;
    if (board_pub_.getNumSubscribers() > 0) board_pub_.publish(out);
    if (points_pub_.getNumSubscribers() > 0) {
      auto pc = toPointCloud2(pointsCloud(msg->header, det.features.board_points, 1.0f));
      pc.header = msg->header;
      points_pub_.publish(pc);
    }
    if (edges_pub_.getNumSubscribers() > 0) {
      // Intensity carries the edge index (0 UL, 1 UR, 2 LR, 3 LL).
      LidarCloud all = pointsCloud(msg->header, {}, 0.0f);
      for (int j = 0; j < kNumEdges; ++j) {
        const LidarCloud e =
            pointsCloud(msg->header, det.features.edge_points[j], static_cast<float>(j));
        all.points.insert(all.points.end(), e.points.begin(), e.points.end());
      }
      all.width = static_cast<int>(all.points.size());
      auto pc = toPointCloud2(all);
      pc.header = msg->header;
      edges_pub_.publish(pc);
    }
    if (markers_pub_.getNumSubscribers() > 0)
      markers_pub_.publish(makeMarkers(msg->header, det.features));
  }

  void record(const ros::WallTime& now, bool found, const std::string& reason) {
    std::lock_guard<std::mutex> lock(stats_mutex_);
    history_.push_back({now.toSec(), found});
    while (!history_.empty() && history_.front().first < now.toSec() - kStatsWindowS)
      history_.pop_front();
    last_reason_ = reason;
  }

  void diagnose(diagnostic_updater::DiagnosticStatusWrapper& stat) {
    std::lock_guard<std::mutex> lock(stats_mutex_);
    const double now = ros::WallTime::now().toSec();
    while (!history_.empty() && history_.front().first < now - kStatsWindowS) history_.pop_front();
    int found = 0;
    for (const auto& h : history_) found += h.second;
    const double rate = history_.size() / kStatsWindowS;
    const double ratio = history_.empty() ? 0.0 : static_cast<double>(found) / history_.size();
    int background_frames = 0;
    int capturing = 0;
    {
      std::lock_guard<std::mutex> lock2(mutex_);
      background_frames = background_.numFrames();
      capturing = capturing_left_;
    }
    stat.add("input rate (Hz)", rate);
    stat.add("detection ratio", ratio);
    stat.add("clouds in window", static_cast<int>(history_.size()));
    stat.add("window (s)", kStatsWindowS);
    stat.add("background frames", background_frames);
    stat.add("background clouds still to capture", capturing);
    stat.add("last reason", last_reason_);
    bool subscribed = false;
    {
      std::lock_guard<std::mutex> lock3(subscription_mutex_);
      subscribed = static_cast<bool>(cloud_sub_);
    }
    if (!subscribed) {
      stat.summary(diagnostic_msgs::DiagnosticStatus::OK, "idle (no subscribers)");
    } else if (history_.empty()) {
      stat.summary(diagnostic_msgs::DiagnosticStatus::WARN,
                   "no clouds received on " + getNodeHandle().resolveName("points"));
    } else if (found == 0) {
      stat.summary(diagnostic_msgs::DiagnosticStatus::WARN, "no board found: " + last_reason_);
    } else {
      stat.summary(diagnostic_msgs::DiagnosticStatus::OK,
                   "board found in " + std::to_string(found) + " of " +
                       std::to_string(history_.size()) + " clouds");
    }
  }

  Target target_;
  LidarBoardDetectorOptions options_;
  bool use_background_ = true;
  BackgroundModel background_;
  bool session_memory_ = StaticMemoryOptions().enabled;
  std::unique_ptr<LidarBoardTracker>
      tracker_;  // one detector state per LiDAR (this nodelet's cloud)
  int background_frames_ = 5;
  int capturing_left_ = 0;
  std::mutex mutex_;               // options, background model, capture state
  std::mutex subscription_mutex_;  // cloud_sub_
  std::mutex stats_mutex_;
  boost::recursive_mutex reconfigure_mutex_;
  std::unique_ptr<dynamic_reconfigure::Server<CloudBoardDetectorConfig>> reconfigure_;
  ros::Publisher board_pub_, points_pub_, edges_pub_, markers_pub_;
  ros::Subscriber cloud_sub_;
  ros::ServiceServer capture_srv_, clear_srv_;
  diagnostic_updater::Updater diagnostics_;
  ros::WallTimer diagnostics_timer_;
  std::deque<std::pair<double, bool>> history_;
  std::string last_reason_;
};

}  // namespace board_calib

PLUGINLIB_EXPORT_CLASS(board_calib::CloudBoardDetectorNodelet, nodelet::Nodelet)
