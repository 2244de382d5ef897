// Projection maths against CameraModel::project, culling, z-buffer, drawing and the
// projected-edges check on exact synthetic geometry.
#include <board_calib/core/projection/projection.h>
#include <board_calib/core/target.h>
#include <board_calib/core/transform.h>
#include <gtest/gtest.h>
#include <opencv2/imgproc.hpp>
#include "support/basler_camera.h"

#include <cmath>
#include <random>

using namespace board_calib;

namespace {

CameraModel makeCamera(DistortionModel model = DistortionModel::kPlumbBob) {
  return CameraModel::create(sim::baslerIntrinsics(model)).value();
}

// A wide-angle camera with strong barrel distortion: far off-axis points fold back into the
// image through the polynomial, the case culling must catch.
CameraModel makeWideCamera() {
  CameraIntrinsics in;
  in.width = 800;
  in.height = 600;
  in.fx = in.fy = 700;
  in.cx = 400;
  in.cy = 300;
  in.model = DistortionModel::kPlumbBob;
  // Radial factor 1 - 0.2 r^2 turns negative beyond r = 2.24 (66 deg off-axis).
  in.coeffs = {-0.2, 0.0, 0.0, 0.0, 0.0};
  return CameraModel::create(in).value();
}

// LiDAR x forward, y left, z up; camera optical z forward, x right, y down; small offset.
Eigen::Isometry3d cameraTLidar() {
  Eigen::Matrix3d R;
  R << 0, -1, 0, 0, 0, -1, 1, 0, 0;
  const Eigen::Matrix3d tilt = fromRollPitchYaw(Eigen::Vector3d(0.02, -0.03, 0.015));
  return makeTransform(tilt * R, Eigen::Vector3d(0.05, -0.12, 0.08));
}

LidarPoint lidarPoint(const Eigen::Vector3d& p, float intensity = 100.f) {
  LidarPoint lp;
  lp.x = static_cast<float>(p.x());
  lp.y = static_cast<float>(p.y());
  lp.z = static_cast<float>(p.z());
  lp.intensity = intensity;
  return lp;
}

// A LiDAR-frame point that lands at raw pixel (u, v) at camera depth z.
Eigen::Vector3d lidarPointAtPixel(const CameraModel& camera,
                                  const Eigen::Isometry3d& camera_T_lidar, double u, double v,
                                  double z) {
  const Eigen::Vector3d ray = camera.unprojectRay(Eigen::Vector2d(u, v));
  return camera_T_lidar.inverse() * (ray * (z / ray.z()));
}

}  // namespace

TEST(Projection, MatchesCameraModelProjectAndCountsCulledPoints) {
  const CameraModel camera = makeCamera();
  const Eigen::Isometry3d T = cameraTLidar();
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(0, 1919), v(0, 1199), z(1.0, 20.0);
  LidarCloud cloud;
  cloud.frame_id = "lidar";
  const int kVisible = 300;
  for (int i = 0; i < kVisible; ++i)
    cloud.points.push_back(lidarPoint(lidarPointAtPixel(camera, T, u(rng), v(rng), z(rng))));
  // Behind the camera, beyond max depth, off to the side, NaN and zero-range.
  cloud.points.push_back(lidarPoint(T.inverse() * Eigen::Vector3d(0.1, 0.1, -3.0)));
  cloud.points.push_back(lidarPoint(T.inverse() * Eigen::Vector3d(0.1, 0.1, 45.0)));
  cloud.points.push_back(lidarPoint(T.inverse() * Eigen::Vector3d(8.0, 0.0, 3.0)));
  LidarPoint nan_point;
  nan_point.x = std::numeric_limits<float>::quiet_NaN();
  cloud.points.push_back(nan_point);
  cloud.points.push_back(LidarPoint());

  ProjectionOptions options;
  options.zbuffer_cell_px = 0;  // culling only here
  const auto projected = projectCloud(cloud, camera, T, options);
  ASSERT_TRUE(projected.ok()) << projected.error();
  EXPECT_EQ(projected->invalid, 2);
  EXPECT_EQ(projected->out_of_range, 2);
  EXPECT_EQ(projected->outside_image, 1);
  ASSERT_EQ(static_cast<int>(projected->points.size()), kVisible);
  for (const ProjectedPoint& p : projected->points) {
    const LidarPoint& lp = cloud.points[p.index];
    const Eigen::Vector3d pc = T * Eigen::Vector3d(lp.x, lp.y, lp.z);
    Eigen::Vector2d expected;
    ASSERT_TRUE(camera.project(pc, &expected));
    // float storage of the LiDAR point and the pixel: ~1e-3 px at 20 m.
    EXPECT_NEAR(p.u, expected.x(), 2e-3);
    EXPECT_NEAR(p.v, expected.y(), 2e-3);
    EXPECT_NEAR(p.depth, pc.z(), 1e-5);
  }
}

TEST(Projection, CullsPointsThatFoldBackThroughTheDistortion) {
  const CameraModel camera = makeWideCamera();
  // A point 66.5 degrees off-axis: the raw polynomial maps it back inside the image.
  const Eigen::Vector3d off_axis(2.3, 0.0, 1.0);
  Eigen::Vector2d folded;
  ASSERT_TRUE(camera.project(off_axis, &folded));
  ASSERT_TRUE(folded.x() >= 0 && folded.x() < camera.width())
      << "the test camera must fold this point back, got " << folded.transpose();
  LidarCloud cloud;
  cloud.points.push_back(lidarPoint(off_axis));
  cloud.points.push_back(lidarPoint(Eigen::Vector3d(0.1, 0.05, 2.0)));
  ProjectionOptions options;
  const auto projected = projectCloud(cloud, camera, Eigen::Isometry3d::Identity(), options);
  ASSERT_TRUE(projected.ok()) << projected.error();
  EXPECT_EQ(projected->outside_image, 1);
  ASSERT_EQ(projected->points.size(), 1u);
  EXPECT_EQ(projected->points[0].index, 1);
}

TEST(Projection, ZBufferDropsPointsHiddenBehindNearerOnes) {
  const CameraModel camera = makeCamera();
  const Eigen::Isometry3d T = cameraTLidar();
  LidarCloud cloud;
  cloud.points.push_back(lidarPoint(lidarPointAtPixel(camera, T, 500.0, 400.0, 3.0)));  // board
  cloud.points.push_back(
      lidarPoint(lidarPointAtPixel(camera, T, 501.0, 401.0, 9.0)));  // wall behind it
  cloud.points.push_back(
      lidarPoint(lidarPointAtPixel(camera, T, 502.0, 400.0, 3.1)));  // board, within tolerance
  cloud.points.push_back(
      lidarPoint(lidarPointAtPixel(camera, T, 900.0, 400.0, 9.0)));  // wall elsewhere
  ProjectionOptions options;
  options.zbuffer_cell_px = 6;
  options.occlusion_tolerance_m = 0.3;
  auto projected = projectCloud(cloud, camera, T, options);
  ASSERT_TRUE(projected.ok()) << projected.error();
  EXPECT_EQ(projected->occluded, 1);
  std::vector<int> kept;
  for (const auto& p : projected->points) kept.push_back(p.index);
  EXPECT_EQ(kept, (std::vector<int>{0, 2, 3}));

  options.zbuffer_cell_px = 0;
  projected = projectCloud(cloud, camera, T, options);
  ASSERT_TRUE(projected.ok());
  EXPECT_EQ(projected->points.size(), 4u);
}

TEST(Projection, RejectsBadOptionsAndInputsWithReasons) {
  const CameraModel camera = makeCamera();
  LidarCloud cloud;
  ProjectionOptions bad;
  bad.max_depth_m = 0.1;
  const auto r = projectCloud(cloud, camera, Eigen::Isometry3d::Identity(), bad);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().find("max_depth_m"), std::string::npos);

  Eigen::Isometry3d nan_T = Eigen::Isometry3d::Identity();
  nan_T.translation().x() = std::numeric_limits<double>::quiet_NaN();
  EXPECT_FALSE(projectCloud(cloud, camera, nan_T, ProjectionOptions()).ok());
  EXPECT_FALSE(
      projectCloud(cloud, CameraModel(), Eigen::Isometry3d::Identity(), ProjectionOptions()).ok());

  cv::Mat float_image(10, 10, CV_32FC1, cv::Scalar(0));
  ProjectedCloud empty;
  EXPECT_FALSE(drawProjectedCloud(empty, OverlayOptions(), &float_image).ok);
  OverlayOptions bad_overlay;
  bad_overlay.alpha = 1.5;
  cv::Mat image(10, 10, CV_8UC3, cv::Scalar(0, 0, 0));
  EXPECT_FALSE(drawProjectedCloud(empty, bad_overlay, &image).ok);
  EXPECT_FALSE(colorCloud(cloud, empty, cv::Mat()).ok());
  EXPECT_FALSE(parseColorMode("rainbow").ok());
  EXPECT_EQ(parseColorMode("intensity").value(), ColorMode::kIntensity);
}

TEST(Overlay, DrawsDepthColoursNearestOnTop) {
  const CameraModel camera = makeCamera();
  ProjectedCloud projected;
  ProjectedPoint near_point, far_point;
  near_point.u = far_point.u = 100.2f;
  near_point.v = far_point.v = 50.4f;
  near_point.depth = 1.0f;
  far_point.depth = 20.0f;
  // Far point listed last: drawing order must still put the near one on top.
  projected.points = {near_point, far_point};
  cv::Mat image(camera.height(), camera.width(), CV_8UC1, cv::Scalar(0));
  OverlayOptions options;
  options.depth_min_m = 0.0;
  options.depth_max_m = 20.0;
  options.point_radius_px = 2;
  ASSERT_TRUE(drawProjectedCloud(projected, options, &image).ok);
  ASSERT_EQ(image.type(), CV_8UC3);  // mono input converted
  const auto& table = colorTable();
  const cv::Vec3b expected_near = table[255 - static_cast<int>(1.0 / 20.0 * 255 + 0.5)];
  EXPECT_EQ(image.at<cv::Vec3b>(50, 100), expected_near);
  EXPECT_EQ(image.at<cv::Vec3b>(52, 100), expected_near);  // radius 2
  EXPECT_EQ(image.at<cv::Vec3b>(55, 100), cv::Vec3b(0, 0, 0));

  // Half transparency blends with the background.
  cv::Mat grey(20, 20, CV_8UC3, cv::Scalar(100, 100, 100));
  ProjectedCloud one;
  ProjectedPoint p;
  p.u = p.v = 10;
  p.depth = 5;
  one.points = {p};
  OverlayOptions flat;
  flat.color_mode = ColorMode::kFlat;
  flat.flat_color = cv::Vec3b(0, 200, 0);
  flat.alpha = 0.5;
  ASSERT_TRUE(drawProjectedCloud(one, flat, &grey).ok);
  EXPECT_EQ(grey.at<cv::Vec3b>(10, 10), cv::Vec3b(50, 150, 50));
}

TEST(Overlay, UndistortedLineIsDrawnAlongItsDistortedImage) {
  const CameraModel camera = makeCamera();
  // A steep line through the image away from the centre, where distortion bends it by
  // several pixels.
  Eigen::Vector3d line(0.9, -0.3, 0.0);
  line.head<2>().normalize();
  line.z() = -(line.x() * 1500.0 + line.y() * 300.0);
  cv::Mat image(camera.height(), camera.width(), CV_8UC3, cv::Scalar(0, 0, 0));
  LineStyle style;
  style.thickness_px = 1;
  style.sample_step_px = 4.0;
  ASSERT_GT(drawUndistortedLine(line, camera, style, &image), 100);
  int drawn = 0;
  double worst = 0;
  double straight_worst = 0;
  for (int y = 0; y < image.rows; ++y)
    for (int x = 0; x < image.cols; ++x) {
      const cv::Vec3b c = image.at<cv::Vec3b>(y, x);
      if (c[0] < 128) continue;  // anti-aliased fringe
      ++drawn;
      const Eigen::Vector2d u = camera.undistortPixel(Eigen::Vector2d(x, y));
      worst = std::max(worst, std::abs(line.dot(Eigen::Vector3d(u.x(), u.y(), 1.0))));
      straight_worst = std::max(straight_worst, std::abs(line.dot(Eigen::Vector3d(x, y, 1.0))));
    }
  EXPECT_GT(drawn, 800);  // the line crosses the full image height
  // Pixels of a 1 px anti-aliased line lie within ~1 px of the true curve; chords between
  // 4 px samples add < 0.01 px.
  EXPECT_LT(worst, 1.2);
  // The same line drawn straight would miss by several px: the test is sensitive to distortion.
  EXPECT_GT(straight_worst, 4.0);
}

TEST(Overlay, ColorCloudSamplesTheImageBilinearly) {
  const CameraModel camera = makeCamera(DistortionModel::kNone);
  cv::Mat image(camera.height(), camera.width(), CV_8UC3);
  for (int y = 0; y < image.rows; ++y)
    for (int x = 0; x < image.cols; ++x)
      image.at<cv::Vec3b>(y, x) =
          cv::Vec3b(static_cast<uint8_t>(x % 256), static_cast<uint8_t>(y % 256), 77);
  LidarCloud cloud;
  cloud.frame_id = "lidar";
  cloud.stamp = 12.5;
  const Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  cloud.points.push_back(lidarPoint(lidarPointAtPixel(camera, T, 100.5, 20.25, 4.0)));
  cloud.points.push_back(lidarPoint(lidarPointAtPixel(camera, T, 30.0, 200.0, 4.0)));
  ProjectionOptions options;
  options.zbuffer_cell_px = 0;
  const auto projected = projectCloud(cloud, camera, T, options);
  ASSERT_TRUE(projected.ok());
  const auto colored = colorCloud(cloud, *projected, image);
  ASSERT_TRUE(colored.ok()) << colored.error();
  ASSERT_EQ(colored->points.size(), 2u);
  EXPECT_EQ(colored->frame_id, "lidar");
  EXPECT_DOUBLE_EQ(colored->stamp, 12.5);
  // Blue = x, green = y, bilinear: 100.5 -> 100.5 rounds to 101; 20.25 -> 20.
  EXPECT_NEAR(colored->points[0].b, 100.5, 0.6);
  EXPECT_NEAR(colored->points[0].g, 20.25, 0.6);
  EXPECT_EQ(colored->points[0].r, 77);
  EXPECT_EQ(colored->points[1].b, 30);
  EXPECT_EQ(colored->points[1].g, 200);
  EXPECT_FLOAT_EQ(colored->points[1].x, cloud.points[1].x);
}

namespace {

// Exact board features for a board pose: image lines from the projected true corners, LiDAR
// edge points sampled on the true 3D edges (as seen from the LiDAR, same edge order).
struct SyntheticView {
  LidarBoardFeatures lidar;
  CameraBoardFeatures image;
};

SyntheticView makeView(const CameraModel& camera, const Eigen::Isometry3d& camera_T_lidar) {
  Target target;
  target.width = target.height = 1.0;
  // Board as a diamond 3 m in front of the camera, facing it.
  const Eigen::Matrix3d R_face = fromRollPitchYaw(Eigen::Vector3d(0.1, -0.15, 45.0 * kRadPerDeg));
  Eigen::Isometry3d camera_T_board = makeTransform(R_face, Eigen::Vector3d(-0.2, 0.1, 3.0));
  camera_T_board.translation() -= R_face * target.center();
  const auto corners_board = target.outerCorners();
  std::array<Eigen::Vector3d, 4> corners_cam;
  std::array<Eigen::Vector2d, 4> corners_px;
  for (int i = 0; i < 4; ++i) {
    corners_cam[i] = camera_T_board * corners_board[i];
    camera.projectUndistorted(corners_cam[i], &corners_px[i]);
  }
  SyntheticView view;
  view.image.found = true;
  view.lidar.found = true;
  const Eigen::Vector2d centre =
      (corners_px[0] + corners_px[1] + corners_px[2] + corners_px[3]) / 4;
  for (int j = 0; j < 4; ++j) {
    const Eigen::Vector2d a = corners_px[j], b = corners_px[(j + 1) % 4];
    Eigen::Vector3d l(b.y() - a.y(), a.x() - b.x(), 0.0);
    l /= l.head<2>().norm();
    l.z() = -l.head<2>().dot(a);
    if (l.head<2>().dot(centre) + l.z() > 0) l = -l;  // interior negative
    view.image.edge_lines[j] = l;
    view.image.edge_valid[j] = true;
    view.lidar.edge_valid[j] = true;
    for (int n = 1; n < 20; ++n) {
      const double s = n / 20.0;
      const Eigen::Vector3d p_cam =
          corners_cam[j] + s * (corners_cam[(j + 1) % 4] - corners_cam[j]);
      view.lidar.edge_points[j].push_back(camera_T_lidar.inverse() * p_cam);
    }
  }
  return view;
}

}  // namespace

TEST(EdgeCheck, ExactGeometryScoresZeroAndAPerturbationScoresItsPixelShift) {
  const CameraModel camera = makeCamera();
  const Eigen::Isometry3d T = cameraTLidar();
  const SyntheticView view = makeView(camera, T);
  EdgeCheckOptions options;
  const auto exact = checkProjectedEdges(view.lidar, view.image, camera, T, options);
  ASSERT_TRUE(exact.ok()) << exact.error();
  EXPECT_LT(exact->mlre_px, 1e-6);
  EXPECT_EQ(exact->num_points, 4 * 19);
  for (int j = 0; j < 4; ++j) EXPECT_EQ(exact->image_edge[j], j);

  // 0.1 deg of yaw about the camera's y axis shifts points by ~fx * 0.1 deg = 4.9 px
  // horizontally; edges at ~45 deg see about 0.7 of it perpendicular to the line.
  Eigen::Isometry3d rotated = T;
  rotated.linear() = expSO3(Eigen::Vector3d(0, 0.1 * kRadPerDeg, 0)) * T.linear();
  const auto off = checkProjectedEdges(view.lidar, view.image, camera, rotated, options);
  ASSERT_TRUE(off.ok());
  const double shift_px = camera.intrinsics().fx * 0.1 * kRadPerDeg;
  EXPECT_NEAR(off->mlre_px, shift_px * std::sqrt(0.5), 0.25 * shift_px);

  cv::Mat image(camera.height(), camera.width(), CV_8UC3, cv::Scalar(0, 0, 0));
  ASSERT_TRUE(drawEdgeCheck(view.image, *off, camera, options, &image).ok);
  EXPECT_GT(cv::countNonZero(image.reshape(1)), 1000);
}

TEST(EdgeCheck, ReassociatesEdgesNamedDifferentlyAndReportsFailures) {
  const CameraModel camera = makeCamera();
  const Eigen::Isometry3d T = cameraTLidar();
  SyntheticView view = makeView(camera, T);
  // The LiDAR names its edges one step rotated.
  std::rotate(view.lidar.edge_points.begin(), view.lidar.edge_points.begin() + 1,
              view.lidar.edge_points.end());
  EdgeCheckOptions options;
  auto check = checkProjectedEdges(view.lidar, view.image, camera, T, options);
  ASSERT_TRUE(check.ok());
  EXPECT_LT(check->mlre_px, 1e-6);
  for (int j = 0; j < 4; ++j) EXPECT_EQ(check->image_edge[j], (j + 1) % 4);
  options.reassociate = false;
  check = checkProjectedEdges(view.lidar, view.image, camera, T, options);
  ASSERT_TRUE(check.ok());
  EXPECT_GT(check->mlre_px, 50.0);  // wrong pairs are far apart

  // Behind the camera: a specific reason, no crash.
  Eigen::Isometry3d flipped = T;
  flipped.linear() = expSO3(Eigen::Vector3d(0, M_PI, 0)) * T.linear();
  const auto behind =
      checkProjectedEdges(view.lidar, view.image, camera, flipped, EdgeCheckOptions());
  ASSERT_FALSE(behind.ok());
  EXPECT_NE(behind.error().find("in front of the camera"), std::string::npos);
  view.lidar.found = false;
  view.lidar.reason = "no plane";
  EXPECT_FALSE(checkProjectedEdges(view.lidar, view.image, camera, T, EdgeCheckOptions()).ok());
}

TEST(Frustum, CornersProjectToTheImageCorners) {
  const CameraModel camera = makeCamera();
  const auto corners = frustumCorners(camera, 2.0);
  const Eigen::Vector2d expected[4] = {
      {-0.5, -0.5}, {1919.5, -0.5}, {1919.5, 1199.5}, {-0.5, 1199.5}};
  for (int i = 0; i < 4; ++i) {
    EXPECT_NEAR(corners[i].z(), 2.0, 1e-12);
    Eigen::Vector2d px;
    ASSERT_TRUE(camera.project(corners[i], &px));
    EXPECT_NEAR((px - expected[i]).norm(), 0.0, 1e-6);
  }
}
