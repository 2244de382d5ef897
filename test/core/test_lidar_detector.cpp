// LiDAR board detector: bad input gives a specific reason and no crash; options validation;
// the 2D helpers the edge fits rely on.
#include <board_calib/core/lidar_detection/lidar_board_detector.h>

#include "../../src/core/lidar_detection/geometry_2d.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>

namespace board_calib {
namespace {

Target plainBoard() {
  Target t;
  t.type = TargetType::kPlain;
  t.width = 1.016;
  t.height = 1.016;
  return t;
}

LidarCloud organized(int width, int height, float value) {
  LidarCloud c;
  c.frame_id = "lidar";
  c.width = width;
  c.height = height;
  c.has_ring = true;
  c.points.resize(static_cast<size_t>(width) * height);
  for (int r = 0; r < height; ++r)
    for (int k = 0; k < width; ++k) {
      auto& p = c.points[r * width + k];
      p.x = p.y = p.z = value;
      p.ring = r;
    }
  return c;
}

TEST(LidarDetectorBadInput, EmptyCloud) {
  LidarCloud c;
  c.frame_id = "lidar";
  c.stamp = 12.5;
  const auto d = detectLidarBoard(c, plainBoard());
  EXPECT_FALSE(d.features.found);
  EXPECT_EQ(d.code, LidarDetectionCode::kEmptyCloud);
  EXPECT_NE(d.features.reason.find("empty"), std::string::npos) << d.features.reason;
  // The output still carries the cloud's frame and stamp (the nodelet publishes it).
  EXPECT_EQ(d.features.frame_id, "lidar");
  EXPECT_DOUBLE_EQ(d.features.stamp, 12.5);
}

TEST(LidarDetectorBadInput, AllNaN) {
  const auto d =
      detectLidarBoard(organized(1024, 64, std::numeric_limits<float>::quiet_NaN()), plainBoard());
  EXPECT_FALSE(d.features.found);
  EXPECT_EQ(d.code, LidarDetectionCode::kNoValidPoints);
  EXPECT_NE(d.features.reason.find("no valid returns"), std::string::npos) << d.features.reason;
}

TEST(LidarDetectorBadInput, AllZeroIsNoReturn) {
  // Ouster drivers write (0, 0, 0) for no return.
  const auto d = detectLidarBoard(organized(1024, 64, 0.0f), plainBoard());
  EXPECT_EQ(d.code, LidarDetectionCode::kNoValidPoints) << d.features.reason;
}

TEST(LidarDetectorBadInput, InfiniteAndScatteredPointsDoNotCrash) {
  LidarCloud c = organized(64, 16, std::numeric_limits<float>::infinity());
  std::mt19937 rng(1);
  std::uniform_real_distribution<float> u(-20.f, 20.f);
  for (size_t i = 0; i < c.points.size(); i += 3) {
    c.points[i].x = u(rng);
    c.points[i].y = u(rng);
    c.points[i].z = u(rng);
  }
  const auto d = detectLidarBoard(c, plainBoard());
  EXPECT_FALSE(d.features.found);
  EXPECT_FALSE(d.features.reason.empty());
}

TEST(LidarDetectorBadInput, InvalidOptionsAndTarget) {
  LidarBoardDetectorOptions o;
  EXPECT_EQ(o.validate(), "");
  o.voxel_size_m = 0.0;
  EXPECT_NE(o.validate().find("voxel_size_m"), std::string::npos);
  const auto d = detectLidarBoard(organized(8, 2, 1.0f), plainBoard(), o);
  EXPECT_EQ(d.code, LidarDetectionCode::kInvalidOptions);
  EXPECT_NE(d.features.reason.find("voxel_size_m"), std::string::npos);

  Target bad = plainBoard();
  bad.width = -1;
  const auto e = detectLidarBoard(organized(8, 2, 1.0f), bad);
  EXPECT_EQ(e.code, LidarDetectionCode::kInvalidTarget) << e.features.reason;

  BackgroundModelOptions b;
  EXPECT_EQ(b.validate(), "");
  b.range_margin_m = 0;
  EXPECT_FALSE(b.validate().empty());
}

TEST(LidarDetectorBadInput, BackgroundRejectsMismatchedLayouts) {
  BackgroundModel model;
  EXPECT_FALSE(model.addFrame(LidarCloud{}).ok);
  ASSERT_TRUE(model.addFrame(organized(32, 4, 5.0f)).ok);
  EXPECT_FALSE(model.addFrame(organized(16, 4, 5.0f)).ok);
  // Same direction, 1 m closer than the background: new. At the background range: not new.
  EXPECT_EQ(model.foregroundMask(organized(32, 4, 4.0f))[0], 1);
  EXPECT_EQ(model.foregroundMask(organized(32, 4, 5.0f))[0], 0);
}

TEST(LidarDetectorGeometry, RobustLineIgnoresOutliers) {
  // Points on y = 0.5 x + 0.1 with 2 mm noise, plus 30 % gross outliers.
  std::mt19937 rng(2);
  std::normal_distribution<double> noise(0.0, 0.002);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  Points2 pts;
  for (int i = 0; i < 20; ++i) {
    const double x = u(rng);
    pts.emplace_back(x, 0.5 * x + 0.1 + noise(rng));
  }
  for (int i = 0; i < 9; ++i) pts.emplace_back(u(rng), u(rng) + 2.0);
  const auto fit = lidar_detail::fitLineRobust(pts, 0.01, 200, rng);
  ASSERT_TRUE(fit.ok);
  EXPECT_EQ(fit.num_inliers, 20);
  // Slope within 1 %: 20 points over 2 m with 2 mm noise fix it to ~0.2 %.
  EXPECT_NEAR(fit.direction.y() / fit.direction.x(), 0.5, 0.005);
  EXPECT_LT(fit.distance({0.0, 0.1}), 0.002);
}

TEST(LidarDetectorGeometry, HullAndRectangleOfARotatedRectangle) {
  Points2 pts;
  const double c = std::cos(0.6), s = std::sin(0.6);
  for (int i = 0; i <= 10; ++i)
    for (int j = 0; j <= 6; ++j) {
      const double x = 0.9 * i / 10 - 0.45, y = 0.6 * j / 6 - 0.3;
      pts.emplace_back(c * x - s * y, s * x + c * y);
    }
  const auto hull = lidar_detail::convexHull(pts);
  EXPECT_NEAR(lidar_detail::polygonArea(hull), 0.54, 1e-9);
  const auto rect = lidar_detail::minAreaRectangle(hull);
  EXPECT_NEAR(rect.x(), 0.9, 1e-9);
  EXPECT_NEAR(rect.y(), 0.6, 1e-9);
}

}  // namespace
}  // namespace board_calib
