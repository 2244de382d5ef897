// rostest of board_calib/projection: it subscribes to its inputs only while an output has a
// subscriber, and turns a synthetic frame (solid-colour image, grid of LiDAR points ahead)
// plus a latched calibration result into an overlay with the points drawn where the pinhole
// model puts them and a cloud coloured with the image's colour.
#include <board_calib/CalibrationResult.h>
#include <board_calib/conversions.h>
#include <board_calib/core/transform.h>

#include <gtest/gtest.h>
#include <ros/ros.h>
#include <sensor_msgs/point_cloud2_iterator.h>

#include <cstring>

using namespace board_calib;

namespace {

constexpr int kWidth = 640, kHeight = 480;
constexpr double kFocal = 500.0;
const cv::Vec3b kBackground(10, 20, 200);  // BGR

bool waitFor(const std::function<bool()>& condition, double timeout_s) {
  const ros::WallTime end = ros::WallTime::now() + ros::WallDuration(timeout_s);
  while (ros::ok() && ros::WallTime::now() < end) {
    if (condition()) return true;
    ros::spinOnce();
    ros::WallDuration(0.02).sleep();
  }
  return condition();
}

Eigen::Isometry3d cameraTLidar() {
  Eigen::Matrix3d R;
  R << 0, -1, 0, 0, 0, -1, 1, 0, 0;  // LiDAR x forward, z up -> optical z forward, y down
  return makeTransform(R, Eigen::Vector3d(0.0, 0.1, 0.0));
}

}  // namespace

TEST(ProjectionNodelet, LazyOverlayAndColoredCloud) {
  ros::NodeHandle nh;
  ros::Publisher image_pub = nh.advertise<sensor_msgs::Image>("image", 2);
  ros::Publisher info_pub = nh.advertise<sensor_msgs::CameraInfo>("camera_info", 2);
  ros::Publisher cloud_pub = nh.advertise<sensor_msgs::PointCloud2>("points", 2);
  ros::Publisher result_pub = nh.advertise<CalibrationResult>("calibration_result", 1, true);

  CalibrationResult result;
  result.success = true;
  result.camera_frame = "camera";
  result.lidar_frame = "lidar";
  result.camera_T_lidar = toTransformMsg(cameraTLidar());
  result_pub.publish(result);

  // Lazy: nobody listens to the outputs, so the nodelet must not subscribe to its inputs.
  ros::WallDuration(2.0).sleep();
  ros::spinOnce();
  EXPECT_EQ(image_pub.getNumSubscribers(), 0u);
  EXPECT_EQ(cloud_pub.getNumSubscribers(), 0u);

  sensor_msgs::ImageConstPtr overlay;
  sensor_msgs::PointCloud2ConstPtr colored;
  ros::Subscriber overlay_sub =
      nh.subscribe<sensor_msgs::Image>("overlay", 1, [&](const sensor_msgs::ImageConstPtr& m) { overlay = m; });
  ros::Subscriber colored_sub = nh.subscribe<sensor_msgs::PointCloud2>(
      "colored_cloud", 1, [&](const sensor_msgs::PointCloud2ConstPtr& m) { colored = m; });
  ASSERT_TRUE(waitFor([&] { return image_pub.getNumSubscribers() > 0 && info_pub.getNumSubscribers() > 0 &&
                                   cloud_pub.getNumSubscribers() > 0; },
                      10.0))
      << "the nodelet did not subscribe to its inputs once its outputs had subscribers";

  CameraIntrinsics in;
  in.width = kWidth;
  in.height = kHeight;
  in.fx = in.fy = kFocal;
  in.cx = 319.5;
  in.cy = 239.5;
  sensor_msgs::CameraInfo info = toCameraInfo(in);
  LidarCloud cloud;
  cloud.frame_id = "lidar";
  cloud.has_intensity = true;
  for (int i = -5; i < 5; ++i)
    for (int j = -5; j < 5; ++j) {
      LidarPoint p;
      p.x = 5.0f;
      p.y = 0.2f * i;
      p.z = 0.15f * j;
      p.intensity = 100;
      cloud.points.push_back(p);
    }
  cloud.width = static_cast<int>(cloud.points.size());
  const cv::Mat image(kHeight, kWidth, CV_8UC3, cv::Scalar(kBackground[0], kBackground[1], kBackground[2]));

  // Publish until both outputs arrived (the subscriptions may take a moment to connect).
  const bool got = waitFor(
      [&] {
        const ros::Time stamp = ros::Time::now();
        std_msgs::Header header;
        header.stamp = stamp;
        header.frame_id = "camera";
        info.header = header;
        sensor_msgs::PointCloud2 cloud_msg = toPointCloud2(cloud);
        cloud_msg.header.stamp = stamp;
        image_pub.publish(imageToMsg(image, header).value());
        info_pub.publish(info);
        cloud_pub.publish(cloud_msg);
        ros::WallDuration(0.1).sleep();
        ros::spinOnce();
        return overlay && colored;
      },
      20.0);
  ASSERT_TRUE(got) << "no overlay / colored_cloud received";

  // Overlay: same size, the points drawn at their pinhole pixels, background elsewhere.
  const auto drawn = imageFromMsg(*overlay);
  ASSERT_TRUE(drawn.ok()) << drawn.error();
  ASSERT_EQ(drawn->cols, kWidth);
  ASSERT_EQ(drawn->rows, kHeight);
  const Eigen::Isometry3d T = cameraTLidar();
  for (const LidarPoint& p : cloud.points) {
    const Eigen::Vector3d pc = T * Eigen::Vector3d(p.x, p.y, p.z);
    const int u = static_cast<int>(std::lround(kFocal * pc.x() / pc.z() + 319.5));
    const int v = static_cast<int>(std::lround(kFocal * pc.y() / pc.z() + 239.5));
    ASSERT_TRUE(u >= 0 && u < kWidth && v >= 0 && v < kHeight);
    EXPECT_NE(drawn->at<cv::Vec3b>(v, u), kBackground) << "no point drawn at " << u << ", " << v;
  }
  EXPECT_EQ(drawn->at<cv::Vec3b>(5, 5), kBackground);

  // Coloured cloud: every point seen, carrying the image's colour.
  EXPECT_EQ(colored->header.frame_id, "lidar");
  ASSERT_EQ(colored->width * colored->height, cloud.points.size());
  sensor_msgs::PointCloud2ConstIterator<float> rgb(*colored, "rgb");
  for (size_t i = 0; i < cloud.points.size(); ++i, ++rgb) {
    uint32_t packed = 0;
    std::memcpy(&packed, &*rgb, sizeof(packed));
    EXPECT_EQ((packed >> 16) & 0xff, kBackground[2]);
    EXPECT_EQ((packed >> 8) & 0xff, kBackground[1]);
    EXPECT_EQ(packed & 0xff, kBackground[0]);
  }

  // Lazy again: outputs dropped -> inputs unsubscribed.
  overlay_sub.shutdown();
  colored_sub.shutdown();
  EXPECT_TRUE(waitFor([&] { return image_pub.getNumSubscribers() == 0 && cloud_pub.getNumSubscribers() == 0; }, 10.0));
}

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_projection_nodelet");
  ros::NodeHandle nh;  // keeps the node alive for the whole test
  return RUN_ALL_TESTS();
}
