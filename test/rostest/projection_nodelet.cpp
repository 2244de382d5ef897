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

CameraIntrinsics testIntrinsics() {
  CameraIntrinsics in;
  in.width = kWidth;
  in.height = kHeight;
  in.fx = in.fy = kFocal;
  in.cx = 319.5;
  in.cy = 239.5;
  return in;
}

cv::Mat backgroundImage() {
  return cv::Mat(kHeight, kWidth, CV_8UC3,
                 cv::Scalar(kBackground[0], kBackground[1], kBackground[2]));
}

struct FramePublishers {
  explicit FramePublishers(ros::NodeHandle& nh)
      : image(nh.advertise<sensor_msgs::Image>("image", 2)),
        info(nh.advertise<sensor_msgs::CameraInfo>("camera_info", 2)),
        cloud(nh.advertise<sensor_msgs::PointCloud2>("points", 2)) {}
  ros::Publisher image, info, cloud;
};

// One synchronised frame (image, camera_info, cloud) at `stamp`, then a moment to answer.
void publishFrame(FramePublishers& pubs, const cv::Mat& image, sensor_msgs::CameraInfo info,
                  const LidarCloud& cloud, const ros::Time& stamp) {
  std_msgs::Header header;
  header.stamp = stamp;
  header.frame_id = "camera";
  info.header = header;
  sensor_msgs::PointCloud2 cloud_msg = toPointCloud2(cloud);
  cloud_msg.header.stamp = stamp;
  pubs.image.publish(imageToMsg(image, header).value());
  pubs.info.publish(info);
  pubs.cloud.publish(cloud_msg);
  ros::WallDuration(0.1).sleep();
  ros::spinOnce();
}

// Overlay: same size, the points drawn at their pinhole pixels, background elsewhere.
void expectPointsDrawn(const sensor_msgs::Image& overlay, const LidarCloud& cloud) {
  const auto drawn = imageFromMsg(overlay);
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
}

// Coloured cloud: every point seen, carrying the image's colour.
void expectColouredFromImage(const sensor_msgs::PointCloud2& colored, const LidarCloud& cloud) {
  EXPECT_EQ(colored.header.frame_id, "lidar");
  ASSERT_EQ(colored.width * colored.height, cloud.points.size());
  sensor_msgs::PointCloud2ConstIterator<float> rgb(colored, "rgb");
  for (size_t i = 0; i < cloud.points.size(); ++i, ++rgb) {
    uint32_t packed = 0;
    std::memcpy(&packed, &*rgb, sizeof(packed));
    EXPECT_EQ((packed >> 16) & 0xff, kBackground[2]);
    EXPECT_EQ((packed >> 8) & 0xff, kBackground[1]);
    EXPECT_EQ(packed & 0xff, kBackground[0]);
  }
}

// The detected image line, white (zero-residual) edge points on it and the MLRE text.
void expectEdgeCheckDrawn(const cv::Mat& drawn, double line_u) {
  // The line (LineStyle default colour, BGR 255 255 0) runs down the whole image at u = 200.
  int line_rows = 0;
  for (int v = 0; v < kHeight; v += 10)
    if (drawn.at<cv::Vec3b>(v, static_cast<int>(line_u)) != kBackground) ++line_rows;
  EXPECT_GE(line_rows, kHeight / 10 - 2);
  // Edge points: residual 0 px -> white discs (black rim) centred on the line.
  const cv::Vec3b zero_residual(255, 255, 255);
  int zero_residual_points = 0;
  for (int k = 0; k < 8; ++k) {
    const int v = static_cast<int>(60.0 + 45.0 * k + 0.5);
    if (drawn.at<cv::Vec3b>(v, static_cast<int>(line_u) + 3) == zero_residual)
      ++zero_residual_points;
  }
  EXPECT_GE(zero_residual_points, 7);
  // The MLRE annotation: white text in the top-left corner.
  int white = 0;
  for (int v = 10; v < 50; ++v)
    for (int u = 10; u < 150; ++u)
      if (drawn.at<cv::Vec3b>(v, u) == cv::Vec3b(255, 255, 255)) ++white;
  EXPECT_GT(white, 50);
}

}  // namespace

TEST(ProjectionNodelet, LazyOverlayAndColoredCloud) {
  ros::NodeHandle nh;
  FramePublishers pubs(nh);
  ros::Publisher &image_pub = pubs.image, &info_pub = pubs.info, &cloud_pub = pubs.cloud;
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
  ros::Subscriber overlay_sub = nh.subscribe<sensor_msgs::Image>(
      "overlay", 1, [&](const sensor_msgs::ImageConstPtr& m) { overlay = m; });
  ros::Subscriber colored_sub = nh.subscribe<sensor_msgs::PointCloud2>(
      "colored_cloud", 1, [&](const sensor_msgs::PointCloud2ConstPtr& m) { colored = m; });
  ASSERT_TRUE(waitFor(
      [&] {
        return image_pub.getNumSubscribers() > 0 && info_pub.getNumSubscribers() > 0 &&
               cloud_pub.getNumSubscribers() > 0;
      },
      10.0))
      << "the nodelet did not subscribe to its inputs once its outputs had subscribers";

  const CameraIntrinsics in = testIntrinsics();
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
  const cv::Mat image = backgroundImage();

  // Publish until both outputs arrived (the subscriptions may take a moment to connect).
  const bool got = waitFor(
      [&] {
        publishFrame(pubs, image, info, cloud, ros::Time::now());
        return overlay && colored;
      },
      20.0);
  ASSERT_TRUE(got) << "no overlay / colored_cloud received";

  expectPointsDrawn(*overlay, cloud);
  expectColouredFromImage(*colored, cloud);

  // Lazy again: outputs dropped -> inputs unsubscribed.
  overlay_sub.shutdown();
  colored_sub.shutdown();
  EXPECT_TRUE(waitFor(
      [&] { return image_pub.getNumSubscribers() == 0 && cloud_pub.getNumSubscribers() == 0; },
      10.0));
}

// Edge-check mode: the detected image line is drawn (bent by no distortion here: straight),
// the LiDAR edge points land on it (residual 0 -> white) and the MLRE text is written.
TEST(ProjectionNodelet, EdgeCheckOverlay) {
  ros::NodeHandle nh;
  FramePublishers pubs(nh);
  ros::Publisher& image_pub = pubs.image;
  ros::Publisher camera_board_pub = nh.advertise<CameraBoard>("camera_board", 2);
  ros::Publisher lidar_board_pub = nh.advertise<LidarBoard>("lidar_board", 2);
  sensor_msgs::ImageConstPtr overlay;
  ros::Subscriber overlay_sub = nh.subscribe<sensor_msgs::Image>(
      "overlay", 1, [&](const sensor_msgs::ImageConstPtr& m) { overlay = m; });
  ASSERT_TRUE(waitFor(
      [&] {
        return camera_board_pub.getNumSubscribers() > 0 &&
               lidar_board_pub.getNumSubscribers() > 0 && image_pub.getNumSubscribers() > 0;
      },
      10.0))
      << "edge_check is on: the nodelet should subscribe to the board topics";

  const CameraIntrinsics in = testIntrinsics();
  sensor_msgs::CameraInfo info = toCameraInfo(in);
  // Image edge UL: the vertical line u = 200 (outward normal -u: the board lies at u > 200).
  constexpr double kLineU = 200.0;
  CameraBoardFeatures image_board;
  image_board.found = true;
  image_board.K = CameraModel::create(in).value().K();
  image_board.image_width = kWidth;
  image_board.image_height = kHeight;
  image_board.edge_lines[0] = Eigen::Vector3d(-1.0, 0.0, kLineU);
  image_board.edge_valid[0] = true;
  // LiDAR edge UL: points 4 m ahead whose pinhole projection lies on that line.
  LidarBoardFeatures lidar_board;
  lidar_board.found = true;
  lidar_board.edge_valid[0] = true;
  const Eigen::Isometry3d lidar_T_camera = cameraTLidar().inverse();
  for (int k = 0; k < 8; ++k) {
    const double z = 4.0, v = 60.0 + 45.0 * k;
    const Eigen::Vector3d pc((kLineU - 319.5) / kFocal * z, (v - 239.5) / kFocal * z, z);
    lidar_board.edge_points[0].push_back(lidar_T_camera * pc);
  }
  LidarCloud cloud;  // an empty scene apart from the edge points
  cloud.frame_id = "lidar";
  for (const auto& p : lidar_board.edge_points[0]) {
    LidarPoint lp;
    lp.x = static_cast<float>(p.x());
    lp.y = static_cast<float>(p.y());
    lp.z = static_cast<float>(p.z());
    cloud.points.push_back(lp);
  }
  cloud.width = static_cast<int>(cloud.points.size());
  const cv::Mat image = backgroundImage();

  const bool got = waitFor(
      [&] {
        const ros::Time stamp = ros::Time::now();
        image_board.stamp = lidar_board.stamp = stamp.toSec();
        image_board.frame_id = "camera";
        lidar_board.frame_id = "lidar";
        camera_board_pub.publish(toMsg(image_board));
        lidar_board_pub.publish(toMsg(lidar_board));
        ros::WallDuration(0.05).sleep();  // boards first: the overlay uses the latest ones
        publishFrame(pubs, image, info, cloud, stamp);
        if (!overlay) return false;
        // Wait for an overlay that carries the edge check (the first ones may predate the boards).
        const auto drawn = imageFromMsg(*overlay);
        return drawn.ok() && drawn->at<cv::Vec3b>(20, static_cast<int>(kLineU)) != kBackground;
      },
      20.0);
  ASSERT_TRUE(got) << "no edge-check overlay received";
  expectEdgeCheckDrawn(imageFromMsg(*overlay).value(), kLineU);
}

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_projection_nodelet");
  ros::NodeHandle nh;  // keeps the node alive for the whole test
  return RUN_ALL_TESTS();
}
