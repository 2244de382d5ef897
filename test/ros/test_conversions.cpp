#include <board_calib/conversions.h>
#include <board_calib/core/transform.h>

#include <gtest/gtest.h>
#include <sensor_msgs/point_cloud2_iterator.h>

#include <cmath>

using namespace board_calib;

TEST(Conversions, CameraInfoRoundTrip) {
  CameraIntrinsics in;
  in.width = 800;
  in.height = 592;
  in.fx = 649.88;
  in.fy = 650.52;
  in.cx = 383.08;
  in.cy = 300.64;
  in.model = DistortionModel::kPlumbBob;
  in.coeffs = {-0.1, 0.02, 0.001, -0.002, 0.0};
  const auto back = fromCameraInfo(toCameraInfo(in));
  ASSERT_TRUE(back.ok()) << back.error();
  EXPECT_EQ(back->width, 800);
  EXPECT_DOUBLE_EQ(back->fy, 650.52);
  EXPECT_EQ(back->model, DistortionModel::kPlumbBob);
  EXPECT_EQ(back->coeffs.size(), 5u);

  sensor_msgs::CameraInfo bad = toCameraInfo(in);
  bad.distortion_model = "weird";
  const auto rejected = fromCameraInfo(bad);
  ASSERT_FALSE(rejected.ok());
  EXPECT_NE(rejected.error().find("weird"), std::string::npos);
  // Zero K is accepted here and rejected by CameraModel::create with a reason.
  sensor_msgs::CameraInfo zero = toCameraInfo(in);
  zero.K.fill(0.0);
  const auto zi = fromCameraInfo(zero);
  ASSERT_TRUE(zi.ok());
  EXPECT_FALSE(CameraModel::create(*zi).ok());
}

TEST(Conversions, OrganizedCloudWithRingRoundTrip) {
  LidarCloud cloud;
  cloud.frame_id = "os1_lidar";
  cloud.stamp = 12.5;
  cloud.width = 4;
  cloud.height = 3;
  cloud.has_ring = true;
  cloud.has_intensity = true;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 4; ++c) {
      LidarPoint p;
      p.x = static_cast<float>(c);
      p.y = static_cast<float>(r);
      p.z = (r == 1 && c == 2) ? std::nanf("") : 1.0f;
      p.intensity = static_cast<float>(10 * r + c);
      p.ring = r;
      cloud.points.push_back(p);
    }
  const auto msg = toPointCloud2(cloud);
  EXPECT_EQ(msg.height, 3u);
  EXPECT_EQ(msg.width, 4u);
  const auto back = fromPointCloud2(msg);
  ASSERT_TRUE(back.ok()) << back.error();
  EXPECT_TRUE(back->organized());
  EXPECT_TRUE(back->has_ring);
  ASSERT_EQ(back->points.size(), 12u);
  EXPECT_EQ(back->points[7].ring, 1);
  EXPECT_FLOAT_EQ(back->points[7].intensity, 13.0f);
  EXPECT_TRUE(std::isnan(back->points[6].z));
  EXPECT_DOUBLE_EQ(back->stamp, 12.5);
}

TEST(Conversions, RingAsUint8AndMissingFields) {
  sensor_msgs::PointCloud2 msg;
  msg.height = 1;
  msg.width = 2;
  sensor_msgs::PointCloud2Modifier mod(msg);
  mod.setPointCloud2Fields(4, "x", 1, sensor_msgs::PointField::FLOAT32, "y", 1, sensor_msgs::PointField::FLOAT32, "z",
                           1, sensor_msgs::PointField::FLOAT32, "ring", 1, sensor_msgs::PointField::UINT8);
  mod.resize(2);
  sensor_msgs::PointCloud2Iterator<uint8_t> ring(msg, "ring");
  *ring = 7;
  ++ring;
  *ring = 31;
  const auto cloud = fromPointCloud2(msg);
  ASSERT_TRUE(cloud.ok()) << cloud.error();
  EXPECT_EQ(cloud->points[1].ring, 31);
  EXPECT_FALSE(cloud->has_intensity);

  sensor_msgs::PointCloud2 no_xyz;
  no_xyz.height = 1;
  no_xyz.width = 1;
  sensor_msgs::PointCloud2Modifier m2(no_xyz);
  m2.setPointCloud2Fields(1, "intensity", 1, sensor_msgs::PointField::FLOAT32);
  m2.resize(1);
  const auto rejected = fromPointCloud2(no_xyz);
  ASSERT_FALSE(rejected.ok());
  EXPECT_NE(rejected.error().find("x/y/z"), std::string::npos);

  sensor_msgs::PointCloud2 truncated = msg;
  truncated.data.resize(3);
  EXPECT_FALSE(fromPointCloud2(truncated).ok());
  sensor_msgs::PointCloud2 empty;
  empty.fields = msg.fields;
  empty.point_step = msg.point_step;
  const auto e = fromPointCloud2(empty);
  ASSERT_TRUE(e.ok());
  EXPECT_EQ(e->size(), 0u);
}

TEST(Conversions, BoardFeaturesRoundTrip) {
  LidarBoardFeatures l;
  l.frame_id = "vlp32";
  l.stamp = 3.25;
  l.found = true;
  l.plane.normal = Eigen::Vector3d(1, 0.1, 0).normalized();
  l.plane.offset = 3.0;
  l.board_points = {{3, 0, 0}, {3, 0.1, 0.2}};
  l.edge_points[2] = {{3, 0.5, -0.1}};
  l.edge_valid = {true, false, true, true};
  l.corners[1] = {3, -0.7, 0};
  l.measured_size_m = {1.02, 1.01};
  const auto l2 = fromMsg(toMsg(l));
  EXPECT_EQ(l2.frame_id, "vlp32");
  EXPECT_DOUBLE_EQ(l2.stamp, 3.25);
  EXPECT_TRUE(l2.plane.normal.isApprox(l.plane.normal));
  EXPECT_EQ(l2.board_points.size(), 2u);
  EXPECT_EQ(l2.edge_points[2].size(), 1u);
  EXPECT_FALSE(l2.edge_valid[1]);
  EXPECT_TRUE(l2.corners[1].isApprox(l.corners[1]));
  EXPECT_DOUBLE_EQ(l2.measured_size_m.x(), 1.02);

  CameraBoardFeatures c;
  c.frame_id = "camera";
  c.stamp = 3.24;
  c.found = true;
  c.K << 700, 0, 400, 0, 700, 300, 0, 0, 1;
  c.image_width = 800;
  c.image_height = 600;
  c.camera_T_board = makeTransform(Eigen::Vector3d(0.1, 0.2, 3.0), Eigen::Vector4d(0.1, 0.2, 0.3, 0.9));
  c.edge_lines[0] = {0.6, 0.8, -100};
  c.edge_valid = {true, true, true, false};
  c.corners_px[3] = {-20, 310};
  c.pattern.push_back({5, {0.1, 0.2, 0}, {410.5, 299.25}});
  c.reprojection_rms_px = 0.12;
  const auto c2 = fromMsg(toMsg(c));
  EXPECT_TRUE(c2.K.isApprox(c.K));
  EXPECT_LT(rotationErrorDeg(c2.camera_T_board, c.camera_T_board), 1e-9);
  EXPECT_TRUE(c2.edge_lines[0].isApprox(c.edge_lines[0]));
  EXPECT_FALSE(c2.edge_valid[3]);
  EXPECT_TRUE(c2.corners_px[3].isApprox(c.corners_px[3]));
  ASSERT_EQ(c2.pattern.size(), 1u);
  EXPECT_EQ(c2.pattern[0].id, 5);
  EXPECT_DOUBLE_EQ(c2.pattern[0].pixel.y(), 299.25);
}

TEST(Conversions, TransformMessages) {
  const Eigen::Isometry3d T = makeTransform(Eigen::Vector3d(1, 2, 3), Eigen::Vector4d(0, 0, 0.7071, 0.7071));
  EXPECT_LT(rotationErrorDeg(fromTransformMsg(toTransformMsg(T)), T), 1e-9);
  EXPECT_LT(translationErrorM(fromPoseMsg(toPoseMsg(T)), T), 1e-12);
}
