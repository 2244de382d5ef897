#include <board_calib/core/camera_model.h>
#include <gtest/gtest.h>
#include <opencv2/calib3d.hpp>
#include "support/basler_camera.h"

#include <random>

using board_calib::CameraIntrinsics;
using board_calib::CameraModel;
using board_calib::DistortionModel;

namespace {

CameraIntrinsics makeIntrinsics(DistortionModel model) {
  CameraIntrinsics in = board_calib::sim::baslerIntrinsics(model);
  switch (model) {
    case DistortionModel::kPlumbBob: in.coeffs = {-0.1343, -0.0259, 0.00218, 0.00084, 0.012}; break;
    case DistortionModel::kRationalPolynomial:
      in.coeffs = {-0.21, 0.05, 0.001, -0.0005, 0.01, 0.12, -0.02, 0.004};
      break;
    case DistortionModel::kEquidistant:
      in.fx = in.fy = 700;
      in.coeffs = {-0.03, 0.004, -0.0012, 0.0002};
      break;
    case DistortionModel::kNone: break;
  }
  return in;
}

// Points in front of the camera whose projections stay inside (or near) the image.
std::vector<cv::Point3d> samplePoints(const CameraIntrinsics& in, int n, std::mt19937& rng) {
  std::uniform_real_distribution<double> u(0.0, in.width), v(0.0, in.height), z(0.5, 8.0);
  std::vector<cv::Point3d> pts;
  for (int i = 0; i < n; ++i) {
    const double depth = z(rng);
    pts.emplace_back((u(rng) - in.cx) / in.fx * depth, (v(rng) - in.cy) / in.fy * depth, depth);
  }
  return pts;
}

cv::Mat cameraMatrix(const CameraIntrinsics& in) {
  return (cv::Mat_<double>(3, 3) << in.fx, 0, in.cx, 0, in.fy, in.cy, 0, 0, 1);
}

class CameraModelVsOpenCV : public ::testing::TestWithParam<DistortionModel> {};

}  // namespace

TEST_P(CameraModelVsOpenCV, ProjectionMatchesOpenCV) {
  const CameraIntrinsics in = makeIntrinsics(GetParam());
  const auto model = CameraModel::create(in);
  ASSERT_TRUE(model.ok()) << model.error();
  std::mt19937 rng(42);
  const auto pts = samplePoints(in, 500, rng);
  std::vector<cv::Point2d> expected;
  const cv::Mat zero = cv::Mat::zeros(3, 1, CV_64F);
  if (GetParam() == DistortionModel::kEquidistant) {
    std::vector<cv::Point3d> pts_copy = pts;
    cv::fisheye::projectPoints(pts_copy, expected, cv::Affine3d(), cameraMatrix(in), in.coeffs);
  } else {
    cv::projectPoints(pts, zero, zero, cameraMatrix(in), in.coeffs, expected);
  }
  for (size_t i = 0; i < pts.size(); ++i) {
    Eigen::Vector2d px = Eigen::Vector2d::Zero();
    ASSERT_TRUE(model->project(Eigen::Vector3d(pts[i].x, pts[i].y, pts[i].z), &px));
    EXPECT_NEAR(px.x(), expected[i].x, 1e-6);
    EXPECT_NEAR(px.y(), expected[i].y, 1e-6);
  }
}

TEST_P(CameraModelVsOpenCV, UndistortInvertsProjectionAndMatchesOpenCV) {
  const CameraIntrinsics in = makeIntrinsics(GetParam());
  const auto model = CameraModel::create(in);
  ASSERT_TRUE(model.ok());
  std::mt19937 rng(7);
  const auto pts = samplePoints(in, 500, rng);
  std::vector<cv::Point2d> raw;
  for (const auto& p : pts) {
    Eigen::Vector2d px = Eigen::Vector2d::Zero();
    model->project(Eigen::Vector3d(p.x, p.y, p.z), &px);
    raw.emplace_back(px.x(), px.y());
  }
  // OpenCV's iterative undistortion with a tight criterion as the independent reference.
  std::vector<cv::Point2d> cv_undist;
  const cv::Mat K = cameraMatrix(in);
  if (GetParam() == DistortionModel::kEquidistant) {
    cv::fisheye::undistortPoints(
        raw, cv_undist, K, in.coeffs, cv::noArray(), K,
        cv::TermCriteria(cv::TermCriteria::COUNT + cv::TermCriteria::EPS, 100, 1e-14));
  } else {
    cv::undistortPoints(
        raw, cv_undist, K, in.coeffs, cv::noArray(), K,
        cv::TermCriteria(cv::TermCriteria::COUNT + cv::TermCriteria::EPS, 200, 1e-14));
  }
  for (size_t i = 0; i < pts.size(); ++i) {
    const Eigen::Vector2d ideal(in.fx * pts[i].x / pts[i].z + in.cx,
                                in.fy * pts[i].y / pts[i].z + in.cy);
    const Eigen::Vector2d u = model->undistortPixel({raw[i].x, raw[i].y});
    EXPECT_NEAR(u.x(), ideal.x(), 1e-6);
    EXPECT_NEAR(u.y(), ideal.y(), 1e-6);
    EXPECT_NEAR(u.x(), cv_undist[i].x, 1e-6);
    EXPECT_NEAR(u.y(), cv_undist[i].y, 1e-6);
    const Eigen::Vector2d back = model->distortPixel(u);
    EXPECT_NEAR(back.x(), raw[i].x, 1e-6);
    EXPECT_NEAR(back.y(), raw[i].y, 1e-6);
  }
}

INSTANTIATE_TEST_SUITE_P(AllModels, CameraModelVsOpenCV,
                         ::testing::Values(DistortionModel::kNone, DistortionModel::kPlumbBob,
                                           DistortionModel::kRationalPolynomial,
                                           DistortionModel::kEquidistant));

TEST(CameraModel, RejectsBadIntrinsics) {
  CameraIntrinsics in = makeIntrinsics(DistortionModel::kPlumbBob);
  in.fx = 0;
  EXPECT_FALSE(CameraModel::create(in).ok());
  in = makeIntrinsics(DistortionModel::kPlumbBob);
  in.width = 0;
  EXPECT_FALSE(CameraModel::create(in).ok());
  in = makeIntrinsics(DistortionModel::kPlumbBob);
  in.coeffs.push_back(0.1);
  in.coeffs.push_back(0.1);
  in.coeffs.push_back(0.1);
  EXPECT_FALSE(CameraModel::create(in).ok());
  in = makeIntrinsics(DistortionModel::kPlumbBob);
  in.coeffs[0] = std::nan("");
  EXPECT_FALSE(CameraModel::create(in).ok());
  EXPECT_FALSE(board_calib::parseDistortionModel("kannala_brandt_9").ok());
}

TEST(CameraModel, VisibilityCullsBehindAndFarOffAxis) {
  const auto model = CameraModel::create(makeIntrinsics(DistortionModel::kPlumbBob));
  ASSERT_TRUE(model.ok());
  EXPECT_TRUE(model->isVisible({0.0, 0.0, 3.0}));
  EXPECT_FALSE(model->isVisible({0.0, 0.0, -3.0}));
  // 80 degrees off axis: the polynomial could fold this back into the image; it must be culled.
  EXPECT_FALSE(model->isVisible({std::tan(80 * M_PI / 180.0), 0.0, 1.0}));
}

TEST(CameraModel, TemplatedProjectionMatchesDouble) {
  const auto model = CameraModel::create(makeIntrinsics(DistortionModel::kRationalPolynomial));
  ASSERT_TRUE(model.ok());
  const float p[3] = {0.3f, -0.2f, 2.0f};
  float px[2];
  ASSERT_TRUE(model->project(p, px));
  Eigen::Vector2d pd = Eigen::Vector2d::Zero();
  model->project(Eigen::Vector3d(0.3, -0.2, 2.0), &pd);
  EXPECT_NEAR(px[0], pd.x(), 1e-2);
  EXPECT_NEAR(px[1], pd.y(), 1e-2);
}
