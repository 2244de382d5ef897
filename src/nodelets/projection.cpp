// board_calib/projection: draws the LiDAR cloud onto the camera image with the current
// extrinsic (TF or the latched calibration result) and colours the cloud from the image.
// Lazy: inputs are subscribed only while someone listens to an output. Thin wiring around
// core/projection/projection.h; see docs/nodes/projection.md for the node API.
#include <board_calib/ProjectionConfig.h>
#include <board_calib/conversions.h>
#include <board_calib/core/projection/projection.h>

#include <dynamic_reconfigure/server.h>
#include <image_transport/image_transport.h>
#include <image_transport/subscriber_filter.h>
#include <message_filters/subscriber.h>
#include <message_filters/sync_policies/approximate_time.h>
#include <message_filters/synchronizer.h>
#include <nodelet/nodelet.h>
#include <tf2_ros/buffer.h>
#include <tf2_ros/transform_listener.h>
#include <visualization_msgs/Marker.h>
#include <pluginlib/class_list_macros.hpp>

#include <atomic>
#include <cmath>
#include <memory>
#include <mutex>

namespace board_calib {

namespace {

constexpr double kWarnPeriodS = 10.0;  // throttle of repeated warnings
constexpr double kInputCheckPeriodS = 5.0;
constexpr double kMinDepthSpanM = 0.01;  // keeps max_depth > min_depth whatever the sliders say

}  // namespace

class ProjectionNodelet : public nodelet::Nodelet {
 public:
  ~ProjectionNodelet() override {
    std::lock_guard<std::mutex> lock(connect_mutex_);
    unsubscribe();
  }

 private:
  using SyncPolicy =
      message_filters::sync_policies::ApproximateTime<sensor_msgs::Image, sensor_msgs::CameraInfo,
                                                      sensor_msgs::PointCloud2>;

  void onInit() override {
    ros::NodeHandle& nh = getNodeHandle();
    ros::NodeHandle& pnh = getPrivateNodeHandle();
    pnh.param("use_tf", use_tf_, true);
    pnh.param("queue_size", queue_size_, 5);
    pnh.param("max_interval", max_interval_s_, 0.1);
    pnh.param("tf_timeout", tf_timeout_s_, 0.05);
    pnh.param("camera_frame", camera_frame_override_, std::string());
    pnh.param("image_transport", image_transport_, std::string("raw"));

    tf_buffer_ = std::make_unique<tf2_ros::Buffer>();
    tf_listener_ = std::make_unique<tf2_ros::TransformListener>(*tf_buffer_, nh);
    it_ = std::make_unique<image_transport::ImageTransport>(nh);

    sync_ = std::make_unique<message_filters::Synchronizer<SyncPolicy>>(
        SyncPolicy(queue_size_), image_sub_, info_sub_, cloud_sub_);
    sync_->setMaxIntervalDuration(ros::Duration(max_interval_s_));
    sync_->registerCallback(&ProjectionNodelet::onFrame, this);
    // Arrival counters: tell the user which input is missing when nothing synchronises.
    image_sub_.registerCallback([this](const sensor_msgs::ImageConstPtr&) { ++images_seen_; });
    info_sub_.registerCallback([this](const sensor_msgs::CameraInfoConstPtr&) { ++infos_seen_; });
    cloud_sub_.registerCallback(
        [this](const sensor_msgs::PointCloud2ConstPtr&) { ++clouds_seen_; });

    reconfigure_ =
        std::make_unique<dynamic_reconfigure::Server<ProjectionConfig>>(reconfigure_mutex_, pnh);
    reconfigure_->setCallback(
        [this](ProjectionConfig& config, uint32_t) { onReconfigure(config); });

    // The result is latched and tiny: always listen, so the extrinsic is ready when an output
    // gets its first subscriber.
    result_sub_ = nh.subscribe("calibration_result", 1, &ProjectionNodelet::onResult, this);

    std::lock_guard<std::mutex> lock(connect_mutex_);
    image_transport::SubscriberStatusCallback image_cb =
        [this](const image_transport::SingleSubscriberPublisher&) { onConnect(); };
    ros::SubscriberStatusCallback cloud_cb = [this](const ros::SingleSubscriberPublisher&) {
      onConnect();
    };
    overlay_pub_ = it_->advertise("overlay", 1, image_cb, image_cb);
    cloud_pub_ = nh.advertise<sensor_msgs::PointCloud2>("colored_cloud", 1, cloud_cb, cloud_cb);
    frustum_pub_ = nh.advertise<visualization_msgs::Marker>("camera_frustum", 1, true);
    check_timer_ = nh.createWallTimer(ros::WallDuration(kInputCheckPeriodS),
                                      &ProjectionNodelet::checkInputs, this);
  }

  void onReconfigure(const ProjectionConfig& config) {
    bool edge_check_changed = false;
    {
      std::lock_guard<std::mutex> lock(options_mutex_);
      projection_options_.min_depth_m = config.min_depth;
      projection_options_.max_depth_m =
          std::max(config.max_depth, config.min_depth + kMinDepthSpanM);
      projection_options_.zbuffer_cell_px = config.occlusion_cell;
      projection_options_.occlusion_tolerance_m = config.occlusion_tolerance;
      overlay_options_.color_mode = static_cast<ColorMode>(config.color_mode);
      overlay_options_.depth_min_m = projection_options_.min_depth_m;
      overlay_options_.depth_max_m = projection_options_.max_depth_m;
      overlay_options_.intensity_min = config.intensity_min;
      overlay_options_.intensity_max = config.intensity_max;
      overlay_options_.point_radius_px = config.point_size;
      overlay_options_.alpha = config.alpha;
      edge_options_.residual_scale_px = config.edge_residual_scale;
      edge_max_age_s_ = config.edge_max_age;
      edge_check_changed = edge_check_ != config.edge_check;
      edge_check_ = config.edge_check;
    }
    if (edge_check_changed) onConnect();  // (un)subscribe the board topics
  }

  // Subscribe the inputs while anyone listens to an output; drop them otherwise.
  void onConnect() {
    std::lock_guard<std::mutex> lock(connect_mutex_);
    const bool wanted = overlay_pub_.getNumSubscribers() > 0 || cloud_pub_.getNumSubscribers() > 0;
    if (!wanted) {
      unsubscribe();
      return;
    }
    ros::NodeHandle& nh = getNodeHandle();
    if (!subscribed_) {
      image_transport::TransportHints hints(image_transport_, ros::TransportHints(),
                                            getPrivateNodeHandle());
      image_sub_.subscribe(*it_, "image", queue_size_, hints);
      info_sub_.subscribe(nh, "camera_info", queue_size_);
      cloud_sub_.subscribe(nh, "points", queue_size_);
      subscribed_ = true;
    }
    bool edge_check = false;
    {
      std::lock_guard<std::mutex> options_lock(options_mutex_);
      edge_check = edge_check_;
    }
    if (edge_check && !camera_board_sub_) {
      camera_board_sub_ = nh.subscribe("camera_board", 2, &ProjectionNodelet::onCameraBoard, this);
      lidar_board_sub_ = nh.subscribe("lidar_board", 2, &ProjectionNodelet::onLidarBoard, this);
    } else if (!edge_check && camera_board_sub_) {
      camera_board_sub_.shutdown();
      lidar_board_sub_.shutdown();
    }
  }

  void unsubscribe() {
    if (subscribed_) {
      image_sub_.unsubscribe();
      info_sub_.unsubscribe();
      cloud_sub_.unsubscribe();
      subscribed_ = false;
    }
    camera_board_sub_.shutdown();
    lidar_board_sub_.shutdown();
  }

  void onResult(const CalibrationResultConstPtr& msg) {
    std::lock_guard<std::mutex> lock(extrinsic_mutex_);
    if (!msg->success) {
      NODELET_WARN_THROTTLE(
          kWarnPeriodS,
          "calibration_result reports a failed solve (%s); keeping the previous extrinsic",
          msg->reason.c_str());
      return;
    }
    if (const std::string why = validateTransform(msg->camera_T_lidar); !why.empty()) {
      NODELET_WARN_THROTTLE(
          kWarnPeriodS,
          "calibration_result: camera_T_lidar refused (%s); keeping the previous extrinsic",
          why.c_str());
      return;
    }
    result_ = msg;
  }

  void onCameraBoard(const CameraBoardConstPtr& msg) {
    std::lock_guard<std::mutex> lock(board_mutex_);
    camera_board_ = msg;
  }

  void onLidarBoard(const LidarBoardConstPtr& msg) {
    std::lock_guard<std::mutex> lock(board_mutex_);
    lidar_board_ = msg;
  }

  // camera_T_lidar from TF, else from the latched calibration result.
  bool extrinsic(const std::string& camera_frame, const std::string& lidar_frame,
                 Eigen::Isometry3d* camera_T_lidar) {
    std::string tf_error = "use_tf is false";
    if (use_tf_) {
      try {
        const auto tf = tf_buffer_->lookupTransform(camera_frame, lidar_frame, ros::Time(0),
                                                    ros::Duration(tf_timeout_s_));
        tf_error = validateTransform(tf.transform);
        if (tf_error.empty()) {
          *camera_T_lidar = fromTransformMsg(tf.transform);
          return true;
        }
      } catch (const tf2::TransformException& e) {
        tf_error = e.what();
      }
    }
    std::lock_guard<std::mutex> lock(extrinsic_mutex_);
    if (!result_) {
      NODELET_WARN_THROTTLE(
          kWarnPeriodS, "no extrinsic yet: TF %s <- %s unavailable (%s) and nothing received on %s",
          camera_frame.c_str(), lidar_frame.c_str(), tf_error.c_str(),
          result_sub_.getTopic().c_str());
      return false;
    }
    if ((!result_->lidar_frame.empty() && result_->lidar_frame != lidar_frame) ||
        (!result_->camera_frame.empty() && result_->camera_frame != camera_frame)) {
      NODELET_WARN_THROTTLE(
          kWarnPeriodS,
          "calibration_result is for %s <- %s but the inputs are %s <- %s; using it anyway",
          result_->camera_frame.c_str(), result_->lidar_frame.c_str(), camera_frame.c_str(),
          lidar_frame.c_str());
    }
    *camera_T_lidar = fromTransformMsg(result_->camera_T_lidar);
    return true;
  }

  // The camera model of this camera_info (rebuilt only when it changes); false when unusable.
  bool updateCamera(const sensor_msgs::CameraInfo& info) {
    if (camera_ && sameCameraInfo(info, last_info_)) return true;
    const auto intrinsics = fromCameraInfo(info);
    auto camera = intrinsics ? CameraModel::create(*intrinsics)
                             : Expected<CameraModel>::failure(intrinsics.error());
    if (!camera) {
      NODELET_WARN_THROTTLE(kWarnPeriodS, "unusable camera_info on %s: %s",
                            info_sub_.getTopic().c_str(), camera.error().c_str());
      return false;
    }
    camera_ = std::make_unique<CameraModel>(*camera);
    last_info_ = info;
    return true;
  }

  void publishColoredCloud(const LidarCloud& cloud, const ProjectedCloud& projected,
                           const cv::Mat& image, const std_msgs::Header& header) {
    const auto colored = colorCloud(cloud, projected, image);
    if (!colored) {
      NODELET_WARN_THROTTLE(kWarnPeriodS, "colouring the cloud failed: %s",
                            colored.error().c_str());
      return;
    }
    sensor_msgs::PointCloud2 out = toPointCloud2(*colored);
    out.header = header;
    cloud_pub_.publish(out);
  }

  void onFrame(const sensor_msgs::ImageConstPtr& image_msg,
               const sensor_msgs::CameraInfoConstPtr& info_msg,
               const sensor_msgs::PointCloud2ConstPtr& cloud_msg) {
    ++frames_synced_;
    const bool want_overlay = overlay_pub_.getNumSubscribers() > 0;
    const bool want_cloud = cloud_pub_.getNumSubscribers() > 0;
    if (!want_overlay && !want_cloud) return;

    if (!updateCamera(*info_msg)) return;
    // Size check on the header first: the conversion then only sees plausible images.
    if (image_msg->width != uint32_t(camera_->width()) ||
        image_msg->height != uint32_t(camera_->height())) {
      NODELET_WARN_THROTTLE(
          kWarnPeriodS, "image on %s is %ux%u but camera_info says %dx%d (binning/ROI unsupported)",
          image_sub_.getTopic().c_str(), image_msg->width, image_msg->height, camera_->width(),
          camera_->height());
      return;
    }
    auto image = imageFromMsg(*image_msg);
    if (!image) {
      NODELET_WARN_THROTTLE(kWarnPeriodS, "image on %s: %s", image_sub_.getTopic().c_str(),
                            image.error().c_str());
      return;
    }
    const auto cloud = fromPointCloud2(*cloud_msg);
    if (!cloud) {
      NODELET_WARN_THROTTLE(kWarnPeriodS, "cloud on %s: %s", cloud_sub_.getTopic().c_str(),
                            cloud.error().c_str());
      return;
    }
    const std::string camera_frame =
        camera_frame_override_.empty() ? image_msg->header.frame_id : camera_frame_override_;
    if (frustum_pub_.getNumSubscribers() > 0) publishFrustum(camera_frame, image_msg->header.stamp);
    Eigen::Isometry3d camera_T_lidar;
    if (!extrinsic(camera_frame, cloud_msg->header.frame_id, &camera_T_lidar)) return;

    ProjectionOptions projection_options;
    OverlayOptions overlay_options;
    EdgeCheckOptions edge_options;
    bool edge_check = false;
    double edge_max_age_s = 0;
    {
      std::lock_guard<std::mutex> lock(options_mutex_);
      projection_options = projection_options_;
      overlay_options = overlay_options_;
      edge_options = edge_options_;
      edge_check = edge_check_;
      edge_max_age_s = edge_max_age_s_;
    }
    const auto projected = projectCloud(*cloud, *camera_, camera_T_lidar, projection_options);
    if (!projected) {
      NODELET_WARN_THROTTLE(kWarnPeriodS, "projection failed: %s", projected.error().c_str());
      return;
    }

    if (want_cloud) publishColoredCloud(*cloud, *projected, *image, cloud_msg->header);
    if (!want_overlay) return;

    cv::Mat overlay = *image;  // imageFromMsg returned a private copy
    const Status drawn = drawProjectedCloud(*projected, overlay_options, &overlay);
    if (!drawn) {
      NODELET_WARN_THROTTLE(kWarnPeriodS, "drawing the overlay failed: %s", drawn.reason.c_str());
      return;
    }
    if (edge_check)
      drawEdges(image_msg->header.stamp, cloud_msg->header.stamp, camera_T_lidar, edge_options,
                edge_max_age_s, &overlay);
    const auto out = imageToMsg(overlay, image_msg->header);
    if (out) overlay_pub_.publish(*out);
  }

  // The camera's field of view as lines from the optical centre to the image corners at
  // kFrustumDepthM, in the camera frame (rviz places it with the calibrated TF).
  void publishFrustum(const std::string& camera_frame, const ros::Time& stamp) {
    constexpr double kFrustumDepthM = 1.0;
    const auto corners = frustumCorners(*camera_, kFrustumDepthM);
    visualization_msgs::Marker m;
    m.header.frame_id = camera_frame;
    m.header.stamp = stamp;
    m.ns = "camera_frustum";
    m.type = visualization_msgs::Marker::LINE_LIST;
    m.pose.orientation.w = 1.0;
    m.scale.x = 0.01;
    m.color.r = 1.0f;
    m.color.g = 0.8f;
    m.color.a = 1.0f;
    auto point = [](const Eigen::Vector3d& p) {
      geometry_msgs::Point q;
      q.x = p.x();
      q.y = p.y();
      q.z = p.z();
      return q;
    };
    for (int i = 0; i < 4; ++i) {
      m.points.push_back(point(Eigen::Vector3d::Zero()));
      m.points.push_back(point(corners[i]));
      m.points.push_back(point(corners[i]));
      m.points.push_back(point(corners[(i + 1) % 4]));
    }
    frustum_pub_.publish(m);
  }

  // The projected-edges check on the latest board detections close enough to this frame.
  void drawEdges(const ros::Time& image_stamp, const ros::Time& cloud_stamp,
                 const Eigen::Isometry3d& camera_T_lidar, const EdgeCheckOptions& options,
                 double max_age_s, cv::Mat* overlay) {
    CameraBoardConstPtr camera_board;
    LidarBoardConstPtr lidar_board;
    {
      std::lock_guard<std::mutex> lock(board_mutex_);
      camera_board = camera_board_;
      lidar_board = lidar_board_;
    }
    if (!camera_board || !lidar_board) {
      NODELET_WARN_THROTTLE(kWarnPeriodS, "edge_check: waiting for %s and %s",
                            camera_board_sub_.getTopic().c_str(),
                            lidar_board_sub_.getTopic().c_str());
      return;
    }
    if (std::abs((camera_board->header.stamp - image_stamp).toSec()) > max_age_s ||
        std::abs((lidar_board->header.stamp - cloud_stamp).toSec()) > max_age_s)
      return;  // stale detections would be drawn on the wrong board pose
    const CameraBoardFeatures image_features = fromMsg(*camera_board);
    const LidarBoardFeatures lidar_features = fromMsg(*lidar_board);
    const auto check =
        checkProjectedEdges(lidar_features, image_features, *camera_, camera_T_lidar, options);
    if (!check) {
      NODELET_DEBUG_THROTTLE(kWarnPeriodS, "edge_check: %s", check.error().c_str());
      return;
    }
    const Status drawn = drawEdgeCheck(image_features, *check, *camera_, options, overlay);
    if (!drawn)
      NODELET_WARN_THROTTLE(kWarnPeriodS, "edge_check drawing failed: %s", drawn.reason.c_str());
  }

  // Names the missing input when subscribed but nothing synchronises.
  void checkInputs(const ros::WallTimerEvent&) {
    bool subscribed = false;
    {
      std::lock_guard<std::mutex> lock(connect_mutex_);
      subscribed = subscribed_;
    }
    const int images = images_seen_.exchange(0), infos = infos_seen_.exchange(0),
              clouds = clouds_seen_.exchange(0), frames = frames_synced_.exchange(0);
    if (!subscribed || frames > 0) return;
    if (images > 0 && infos == 0)
      NODELET_WARN("images arrive on %s but no camera_info on %s", image_sub_.getTopic().c_str(),
                   info_sub_.getTopic().c_str());
    else if ((images > 0 || infos > 0) && clouds == 0)
      NODELET_WARN("no cloud on %s", cloud_sub_.getTopic().c_str());
    else if (images == 0 && clouds > 0)
      NODELET_WARN("clouds arrive but no image on %s", image_sub_.getTopic().c_str());
    else if (images > 0 && infos > 0 && clouds > 0)
      NODELET_WARN(
          "image, camera_info and cloud arrive but their stamps never lie within %.3f s of each "
          "other",
          max_interval_s_);
  }

  // Startup parameters.
  bool use_tf_ = true;
  int queue_size_ = 5;
  double max_interval_s_ = 0.1;
  double tf_timeout_s_ = 0.05;
  std::string camera_frame_override_;
  std::string image_transport_;

  std::unique_ptr<tf2_ros::Buffer> tf_buffer_;
  std::unique_ptr<tf2_ros::TransformListener> tf_listener_;
  std::unique_ptr<image_transport::ImageTransport> it_;
  image_transport::SubscriberFilter image_sub_;
  message_filters::Subscriber<sensor_msgs::CameraInfo> info_sub_;
  message_filters::Subscriber<sensor_msgs::PointCloud2> cloud_sub_;
  std::unique_ptr<message_filters::Synchronizer<SyncPolicy>> sync_;
  ros::Subscriber result_sub_, camera_board_sub_, lidar_board_sub_;
  image_transport::Publisher overlay_pub_;
  ros::Publisher cloud_pub_;
  ros::Publisher frustum_pub_;
  ros::WallTimer check_timer_;
  std::mutex connect_mutex_;
  bool subscribed_ = false;

  boost::recursive_mutex reconfigure_mutex_;
  std::unique_ptr<dynamic_reconfigure::Server<ProjectionConfig>> reconfigure_;
  std::mutex options_mutex_;
  ProjectionOptions projection_options_;
  OverlayOptions overlay_options_;
  EdgeCheckOptions edge_options_;
  bool edge_check_ = false;
  double edge_max_age_s_ = 0.5;

  std::mutex extrinsic_mutex_;
  CalibrationResultConstPtr result_;
  std::mutex board_mutex_;
  CameraBoardConstPtr camera_board_;
  LidarBoardConstPtr lidar_board_;

  // Touched only from the synchronised callback (message_filters serialises it).
  std::unique_ptr<CameraModel> camera_;
  sensor_msgs::CameraInfo last_info_;

  std::atomic<int> images_seen_{0}, infos_seen_{0}, clouds_seen_{0}, frames_synced_{0};
};

}  // namespace board_calib

PLUGINLIB_EXPORT_CLASS(board_calib::ProjectionNodelet, nodelet::Nodelet)
