#include <board_calib/conversions.h>
#include <board_calib/core/pipeline/rig_calibration.h>
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
  // Zero K (an uncalibrated camera) is refused with a reason naming K.
  sensor_msgs::CameraInfo zero = toCameraInfo(in);
  zero.K.fill(0.0);
  const auto zi = fromCameraInfo(zero);
  ASSERT_FALSE(zi.ok());
  EXPECT_NE(zi.error().find("K[0]"), std::string::npos) << zi.error();
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
  mod.setPointCloud2Fields(
      4, "x", 1, sensor_msgs::PointField::FLOAT32, "y", 1, sensor_msgs::PointField::FLOAT32, "z", 1,
      sensor_msgs::PointField::FLOAT32, "ring", 1, sensor_msgs::PointField::UINT8);
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
  c.camera_T_board =
      makeTransform(Eigen::Vector3d(0.1, 0.2, 3.0), Eigen::Vector4d(0.1, 0.2, 0.3, 0.9));
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
  const Eigen::Isometry3d T =
      makeTransform(Eigen::Vector3d(1, 2, 3), Eigen::Vector4d(0, 0, 0.7071, 0.7071));
  EXPECT_LT(rotationErrorDeg(fromTransformMsg(toTransformMsg(T)), T), 1e-9);
  EXPECT_LT(translationErrorM(fromPoseMsg(toPoseMsg(T)), T), 1e-12);
}

namespace {

// 2x2 cloud, x y z intensity float32 (16 bytes a point), x = point index.
sensor_msgs::PointCloud2 smallCloud() {
  sensor_msgs::PointCloud2 msg;
  msg.height = 2;
  msg.width = 2;
  sensor_msgs::PointCloud2Modifier mod(msg);
  mod.setPointCloud2Fields(
      4, "x", 1, sensor_msgs::PointField::FLOAT32, "y", 1, sensor_msgs::PointField::FLOAT32, "z", 1,
      sensor_msgs::PointField::FLOAT32, "intensity", 1, sensor_msgs::PointField::FLOAT32);
  mod.resize(4);
  msg.height = 2;
  msg.width = 2;
  msg.row_step = msg.width * msg.point_step;
  sensor_msgs::PointCloud2Iterator<float> x(msg, "x");
  for (int i = 0; i < 4; ++i, ++x) *x = static_cast<float>(i);
  return msg;
}

sensor_msgs::Image monoImage(const std::string& encoding, uint32_t width, uint32_t height,
                             uint32_t step) {
  sensor_msgs::Image msg;
  msg.encoding = encoding;
  msg.width = width;
  msg.height = height;
  msg.step = step;
  msg.data.assign(size_t(height) * step, 0);
  return msg;
}

}  // namespace

// Issue 15 crash 1: the size check and the read must use the same row_step.
TEST(ConversionsValidation, RowStepInconsistentWithWidth) {
  sensor_msgs::PointCloud2 huge = smallCloud();
  huge.row_step = 0x7fffffff;  // data still width*height*point_step: used to segfault
  const auto a = fromPointCloud2(huge);
  ASSERT_FALSE(a.ok());
  EXPECT_NE(a.error().find("row_step"), std::string::npos) << a.error();
  sensor_msgs::PointCloud2 slightly = smallCloud();
  slightly.row_step += 4;  // used to read 8 bytes past the buffer silently
  const auto b = fromPointCloud2(slightly);
  ASSERT_FALSE(b.ok());
  EXPECT_NE(b.error().find("height*row_step"), std::string::npos) << b.error();
  sensor_msgs::PointCloud2 small = smallCloud();
  small.row_step -= 4;
  EXPECT_FALSE(fromPointCloud2(small).ok());
  // Padding at the end of each row is legal when the data covers it.
  sensor_msgs::PointCloud2 padded = smallCloud();
  padded.row_step += 8;
  padded.data.resize(size_t(padded.row_step) * padded.height);
  EXPECT_TRUE(fromPointCloud2(padded).ok());
}

TEST(ConversionsValidation, FieldsOutsidePointStepAndUnknownTypes) {
  sensor_msgs::PointCloud2 msg = smallCloud();
  msg.fields[2].offset = 14;  // z (4 bytes) would end at 18 > point_step 16
  EXPECT_NE(fromPointCloud2(msg).error().find("'z'"), std::string::npos);
  msg = smallCloud();
  msg.fields[3].datatype = 42;
  EXPECT_NE(fromPointCloud2(msg).error().find("unknown datatype 42"), std::string::npos);
  msg = smallCloud();
  msg.fields[3].count = 0x40000000;  // count*size overflows 32 bits
  EXPECT_NE(fromPointCloud2(msg).error().find("outside point_step"), std::string::npos);
  msg = smallCloud();
  msg.point_step = 0;
  EXPECT_FALSE(fromPointCloud2(msg).ok());
  msg = smallCloud();
  msg.width = 0x10000;
  msg.height = 0x10000;  // width*height overflows 32 bits
  EXPECT_FALSE(fromPointCloud2(msg).ok());
}

// Issue 15: is_bigendian used to be ignored; the values must come out equal.
TEST(ConversionsValidation, BigEndianCloudIsConverted) {
  const sensor_msgs::PointCloud2 little = smallCloud();
  sensor_msgs::PointCloud2 big = little;
  big.is_bigendian = true;
  for (size_t p = 0; p + 4 <= big.data.size(); p += 4)
    std::reverse(big.data.begin() + p, big.data.begin() + p + 4);
  const auto a = fromPointCloud2(little);
  const auto b = fromPointCloud2(big);
  ASSERT_TRUE(a.ok() && b.ok());
  for (size_t i = 0; i < a->points.size(); ++i) EXPECT_EQ(a->points[i].x, b->points[i].x);
  EXPECT_EQ(b->points[3].x, 3.0f);
}

TEST(ConversionsValidation, RingOutOfRangeBecomesUnknown) {
  sensor_msgs::PointCloud2 msg = smallCloud();
  msg.fields[3].name = "ring";  // float32 ring
  sensor_msgs::PointCloud2Iterator<float> ring(msg, "ring");
  *ring = 1e30f;
  ++ring;
  *ring = std::nanf("");
  ++ring;
  *ring = 5.0f;
  const auto cloud = fromPointCloud2(msg);
  ASSERT_TRUE(cloud.ok());
  EXPECT_EQ(cloud->points[0].ring, -1);
  EXPECT_EQ(cloud->points[1].ring, -1);
  EXPECT_EQ(cloud->points[2].ring, 5);
}

// Issue 15 crash 2: mono8 16x65537 with step 65536 (height*step overflows 32 bits in cv_bridge).
TEST(ConversionsValidation, ImageStepAndOverflow) {
  sensor_msgs::Image msg = monoImage("mono8", 16, 4, 16);
  msg.height = 65537;
  msg.step = 65536;
  const auto a = imageFromMsg(msg);
  ASSERT_FALSE(a.ok());
  EXPECT_NE(a.error().find("65537"), std::string::npos) << a.error();
  msg = monoImage("bgr8", 100, 10, 299);  // step < 3*width
  EXPECT_NE(imageFromMsg(msg).error().find("step 299"), std::string::npos);
  msg = monoImage("mono8", 100, 10, 100);
  msg.data.resize(999);
  EXPECT_NE(imageFromMsg(msg).error().find("999 bytes"), std::string::npos);
  msg = monoImage("mono8", 4, 4, 4);
  msg.width = msg.height = msg.step = 60000;  // 3.6 GB claimed, 16 bytes held
  EXPECT_FALSE(imageFromMsg(msg).ok());
  msg = monoImage("32FC1", 4, 4, 16);
  EXPECT_NE(imageFromMsg(msg).error().find("unsupported image encoding '32FC1'"),
            std::string::npos);
  msg = monoImage("mono8", 4, 4, 4);
  EXPECT_TRUE(imageFromMsg(msg).ok());
}

// Issue 15: big-endian mono16 (documented as supported) used to fail with a raw type message.
TEST(ConversionsValidation, BigEndianMono16) {
  sensor_msgs::Image little = monoImage("mono16", 3, 2, 6);
  sensor_msgs::Image big = little;
  big.is_bigendian = true;
  const uint16_t values[6] = {0, 100, 1000, 4000, 20000, 40000};
  for (int i = 0; i < 6; ++i) {
    std::memcpy(&little.data[2 * i], &values[i], 2);
    big.data[2 * i] = static_cast<uint8_t>(values[i] >> 8);
    big.data[2 * i + 1] = static_cast<uint8_t>(values[i] & 0xff);
  }
  const auto a = imageFromMsg(little);
  const auto b = imageFromMsg(big);
  ASSERT_TRUE(a.ok()) << a.error();
  ASSERT_TRUE(b.ok()) << b.error();
  EXPECT_EQ(cv::norm(*a, *b, cv::NORM_INF), 0.0);
  EXPECT_EQ(b->at<uint8_t>(1, 2), 255);  // the maximum maps to 255
  EXPECT_EQ(b->at<uint8_t>(0, 1), 1);    // 100 * 255 / 40000 = 0.64 -> rounds to 1
}

TEST(ConversionsValidation, CameraInfoSanity) {
  CameraIntrinsics in;
  in.width = 640;
  in.height = 480;
  in.fx = in.fy = 500;
  in.cx = 320;
  in.cy = 240;
  const sensor_msgs::CameraInfo good = toCameraInfo(in);
  ASSERT_TRUE(fromCameraInfo(good).ok());
  sensor_msgs::CameraInfo bad = good;
  bad.K[2] = std::nan("");
  EXPECT_NE(fromCameraInfo(bad).error().find("K[2]"), std::string::npos);
  bad = good;
  bad.D.assign(100, 0.0);
  EXPECT_NE(fromCameraInfo(bad).error().find("100 coefficients"), std::string::npos);
  bad = good;
  bad.D[1] = INFINITY;
  EXPECT_NE(fromCameraInfo(bad).error().find("D[1]"), std::string::npos);
  bad = good;
  bad.width = 0x80000000u;  // negative as int
  EXPECT_NE(fromCameraInfo(bad).error().find("size"), std::string::npos);
}

TEST(ConversionsValidation, TransformSanity) {
  geometry_msgs::Transform t;
  t.rotation.w = 1.0;
  EXPECT_EQ(validateTransform(t), "");
  t.rotation.w = 0.0;  // zero quaternion
  EXPECT_NE(validateTransform(t).find("not unit"), std::string::npos);
  t.rotation.w = 1.0;
  t.translation.y = std::nan("");
  EXPECT_NE(validateTransform(t).find("non-finite"), std::string::npos);
}

// Solve results -> messages (result_conversions.cpp): the nodelets only publish what these build.
TEST(ResultConversions, PairSolutionTakesTheVerdictsUncertaintyAndFailure) {
  board_calib::CalibrationSolution s;
  s.success = true;
  s.method = board_calib::Method::kPbpc;
  s.camera_T_lidar.translation() = Eigen::Vector3d(0.1, -0.2, 0.3);
  s.views_used = 12;
  s.mlre_px = 1.5;
  s.plane_rms_mm = 4.0;
  s.stddev.translation_m = Eigen::Vector3d(0.001, 0.001, 0.001);
  s.covariance = board_calib::Matrix6d::Identity() * 1e-6;
  board_calib::ViewResidual skipped;
  skipped.view_id = 7;
  skipped.used = false;
  s.views.push_back(skipped);
  board_calib::VerdictReport verdict;
  verdict.verdict = board_calib::Verdict::kGood;
  verdict.stddev.translation_m = Eigen::Vector3d(0.004, 0.005, 0.006);
  verdict.covariance = board_calib::Matrix6d::Identity() * 4e-6;
  board_calib::ResultFile file;
  file.camera_frame = "cam";
  file.lidar_frame = "lidar";
  const ros::Time stamp(12.5);
  auto m = board_calib::toResultMsg(s, verdict, file, stamp);
  EXPECT_TRUE(m.success);
  EXPECT_EQ(m.header.stamp, stamp);
  EXPECT_EQ(m.header.frame_id, "lidar");
  EXPECT_EQ(m.method, "pbpc");
  EXPECT_EQ(m.verdict, "good");
  EXPECT_DOUBLE_EQ(m.camera_T_lidar.translation.y, -0.2);
  EXPECT_DOUBLE_EQ(m.stddev_translation_m[2], 0.006);  // the verdict's, not the solver's
  EXPECT_DOUBLE_EQ(m.covariance[0], 4e-6);
  EXPECT_DOUBLE_EQ(m.covariance[1], 0.0);
  ASSERT_EQ(m.view_ids.size(), 1u);
  EXPECT_TRUE(std::isnan(m.view_mlre_px[0]));  // a skipped view has no residual

  verdict.verdict = board_calib::Verdict::kFailed;
  verdict.reason = "too few views";
  m = board_calib::toResultMsg(s, verdict, file, stamp);
  EXPECT_FALSE(m.success);
  EXPECT_EQ(m.reason, "too few views");
}

TEST(ResultConversions, RigPairAndSensorPose) {
  board_calib::multi_sensor::MsgSolution s;
  s.poses_used = 9;
  board_calib::PairEntry entry;
  entry.camera_frame = "cam";
  entry.lidar_frame = "lidar";
  entry.camera_T_lidar.translation() = Eigen::Vector3d(0.5, 0.0, 0.0);
  entry.verdict = "good";
  board_calib::RigPairRun run;
  run.verdict.verdict = board_calib::Verdict::kGood;
  auto m = board_calib::toPairResultMsg(entry, run, s, ros::Time(3.0));
  EXPECT_TRUE(m.success);
  EXPECT_EQ(m.verdict, "good");
  EXPECT_EQ(m.method, "msg");
  EXPECT_EQ(m.views_used, 9u);
  EXPECT_DOUBLE_EQ(m.camera_T_lidar.translation.x, 0.5);
  EXPECT_TRUE(std::isnan(m.mlre_px));                  // no shared edges measured
  EXPECT_TRUE(std::isnan(m.stddev_translation_m[0]));  // no covariance: unknown, not zero
  run.verdict.covariance(5, 5) = 1e-5;
  run.verdict.covariance(5, 4) = 2e-6;
  run.verdict.stddev.rotation_deg = Eigen::Vector3d(0.1, 0.2, 0.3);
  m = board_calib::toPairResultMsg(entry, run, s, ros::Time(3.0));
  EXPECT_DOUBLE_EQ(m.stddev_rotation_deg[1], 0.2);
  EXPECT_DOUBLE_EQ(m.covariance[5 * 6 + 4], 2e-6);  // row-major
  run.verdict.verdict = board_calib::Verdict::kFailed;
  EXPECT_FALSE(
      board_calib::toPairResultMsg(entry, run, s, ros::Time(3.0)).success);  // failed: no success

  board_calib::multi_sensor::SensorEstimate sensor;
  sensor.frame = "os1";
  sensor.kind = board_calib::multi_sensor::SensorKind::kLidar;
  sensor.reference_T_sensor.translation() = Eigen::Vector3d(0.0, 0.0, 0.16);
  sensor.stddev.translation_m = Eigen::Vector3d(0.001, 0.002, 0.003);
  sensor.observations = 14;
  sensor.observations_rejected = -1;  // never a wrapped unsigned count
  const auto p = board_calib::toSensorPoseMsg(sensor);
  EXPECT_EQ(p.frame, "os1");
  EXPECT_EQ(p.kind, "lidar");
  EXPECT_DOUBLE_EQ(p.reference_T_sensor.translation.z, 0.16);
  EXPECT_DOUBLE_EQ(p.stddev_translation_m[1], 0.002);
  EXPECT_EQ(p.poses_used, 14u);
  EXPECT_EQ(p.poses_rejected, 0u);
}

// The calibrator's view markers: white before a solve; after it, the median view green and a
// view at 3x the median plane RMS red.
TEST(ResultConversions, ViewMarkersColouredByPlaneResidualRelativeToTheMedian) {
  std::vector<board_calib::View> views(3);
  for (int i = 0; i < 3; ++i) {
    views[i].id = 10 + i;
    views[i].lidar.frame_id = "lidar";
    views[i].lidar.board_points = {Eigen::Vector3d(1.0, 0.0, 0.0), Eigen::Vector3d(1.0, 0.1, 0.0)};
  }
  auto before = board_calib::toViewMarkers(views, nullptr);
  ASSERT_EQ(before.markers.size(), 4u);  // DELETEALL + one per view
  EXPECT_EQ(before.markers[0].action, visualization_msgs::Marker::DELETEALL);
  EXPECT_FLOAT_EQ(before.markers[1].color.b, 1.0f);
  EXPECT_EQ(before.markers[1].points.size(), 2u);
  board_calib::CalibrationSolution solution;
  const double rms[3] = {0.01, 0.01, 0.03};
  for (int i = 0; i < 3; ++i) {
    board_calib::ViewResidual r;
    r.view_id = 10 + i;
    r.used = true;
    r.plane.rms_m = rms[i];
    solution.views.push_back(r);
  }
  auto after = board_calib::toViewMarkers(views, &solution);
  EXPECT_FLOAT_EQ(after.markers[1].color.g, 1.0f);  // at the median
  EXPECT_FLOAT_EQ(after.markers[3].color.r, 1.0f);  // 3x the median
  EXPECT_FLOAT_EQ(after.markers[3].color.g, 0.0f);
}
