// A single frame's colour part searched in its window (issue 14): the board found there is given in
// whole-frame pixels (corners, lines, pose) through a distorting lens, and a colour board's every
// side must part its colour from its surroundings'. Synthetic frames rendered at 2x through the
// distortion and area-averaged, so the truth is the board's corners projected.
#include "../../src/core/image_detection/plain_internal.h"

#include <board_calib/core/transform.h>
#include "sim_test_helpers.h"

#include <gtest/gtest.h>
#include <opencv2/imgproc.hpp>

#include <cmath>
#include <random>

namespace board_calib {
namespace {

using image_detection::detectPlainInColourWindow;
using image_detection::sidesPartColours;

constexpr int kWidth = 1920, kHeight = 1080, kSuper = 2;

CameraModel lens() {
  return sim::makeCamera(kWidth, kHeight, 1300, DistortionModel::kPlumbBob,
                         {-0.12, 0.05, 0.0004, -0.0003, 0.0});
}

// Gaussian noise of `sigma` grey levels on an 8-bit image of any channel count.
void addNoise(double sigma, cv::Mat* image) {
  const int depth16 = CV_MAKETYPE(CV_16S, image->channels());
  cv::Mat noise(image->size(), depth16);
  cv::randn(noise, 0, sigma);
  cv::Mat wide;
  image->convertTo(wide, depth16);
  wide += noise;
  wide.convertTo(*image, image->type());
}

Target board() {
  Target t;
  t.type = TargetType::kPlain;
  t.width = 0.8;
  t.height = 0.6;
  return t;
}

// Corners (undistorted px) of the board at this pose.
std::array<Eigen::Vector2d, kNumEdges> projectedCorners(const CameraModel& camera,
                                                        const Eigen::Isometry3d& camera_T_board) {
  std::array<Eigen::Vector2d, kNumEdges> out;
  const auto corners = board().outerCorners();
  for (int k = 0; k < kNumEdges; ++k)
    EXPECT_TRUE(camera.projectUndistorted(camera_T_board * corners[k], &out[k]));
  return out;
}

bool insideQuad(const std::array<Eigen::Vector2d, kNumEdges>& q, const Eigen::Vector2d& p) {
  int sign = 0;
  for (int k = 0; k < kNumEdges; ++k) {
    const Eigen::Vector2d e = q[(k + 1) % 4] - q[k], r = p - q[k];
    const int s = e.x() * r.y() - e.y() * r.x() > 0 ? 1 : -1;
    if (sign != 0 && s != sign) return false;
    sign = s;
  }
  return true;
}

// A grey, noisy scene with grey rectangles, and the board in blue.
cv::Mat render(const CameraModel& camera, const std::array<Eigen::Vector2d, kNumEdges>& quad,
               std::mt19937& rng) {
  cv::Mat big(kHeight * kSuper, kWidth * kSuper, CV_8UC3, cv::Scalar(118, 120, 122));
  std::uniform_int_distribution<int> x(0, big.cols - 300), y(0, big.rows - 300), g(60, 190);
  for (int k = 0; k < 25; ++k) {
    const int level = g(rng);
    cv::rectangle(big, cv::Rect(x(rng), y(rng), 60 + x(rng) % 240, 60 + y(rng) % 240),
                  cv::Scalar(level, level, level), cv::FILLED);
  }
  for (int v = 0; v < big.rows; ++v)
    for (int u = 0; u < big.cols; ++u) {
      const Eigen::Vector2d raw((u + 0.5) / kSuper - 0.5, (v + 0.5) / kSuper - 0.5);
      if (insideQuad(quad, camera.undistortPixel(raw)))
        big.at<cv::Vec3b>(v, u) = cv::Vec3b(170, 110, 60);
    }
  cv::Mat image;
  cv::resize(big, image, cv::Size(kWidth, kHeight), 0, 0, cv::INTER_AREA);
  addNoise(2.0, &image);
  return image;
}

// A colour part as chromaDeparture gives it: a rough rectangle around the board.
ExpectedBoard roughPlace(const std::array<Eigen::Vector2d, kNumEdges>& quad) {
  ExpectedBoard place;
  place.inside = true;
  double perimeter = 0;
  for (int k = 0; k < kNumEdges; ++k) {
    place.corners_px[k] = quad[k] + Eigen::Vector2d(k % 2 ? 5.0 : -4.0, k < 2 ? -3.0 : 6.0);
    perimeter += (quad[(k + 1) % 4] - quad[k]).norm();
  }
  place.tolerance_px = 0.25 * perimeter / kNumEdges + 2.0;
  return place;
}

TEST(ColourWindow, BoardFoundInItsWindowIsGivenInWholeFramePixels) {
  const CameraModel camera = lens();
  std::mt19937 rng(15);
  // Boards near the centre and near the corners, where the lens distorts most.
  const Eigen::Vector3d places[] = {
      {-0.3, -0.2, 4.0}, {1.1, 0.3, 3.6}, {-1.9, 0.5, 4.2}, {1.0, -1.0, 3.2}};
  int k = 0;
  for (const Eigen::Vector3d& at : places) {
    const Eigen::Isometry3d camera_T_board =
        makeTransform(fromRollPitchYaw({0.15 * (k % 3), -0.2 + 0.1 * k, 0.3 * k}), at);
    const auto truth = projectedCorners(camera, camera_T_board);
    for (const auto& t : truth) {
      const Eigen::Vector2d raw = camera.distortPixel(t);
      ASSERT_TRUE(raw.x() > 20 && raw.y() > 20 && raw.x() < kWidth - 20 && raw.y() < kHeight - 20)
          << "board " << k << " leaves the image";
    }
    const cv::Mat image = render(camera, truth, rng);
    ImageDetection d;
    detectPlainInColourWindow(image, camera, board(), ImageBoardDetectorOptions{},
                              roughPlace(truth), nullptr, &d);
    ASSERT_TRUE(d.features.found) << "board " << k << ": " << d.features.reason;
    // Whole-frame pixels and intrinsics: the corners, the lines through them, the pose.
    EXPECT_EQ(d.features.image_width, kWidth);
    EXPECT_EQ(d.features.image_height, kHeight);
    EXPECT_TRUE(d.features.K.isApprox(camera.K()));
    // The same board as the whole frame's colour contrast gives (the window's pixels are
    // processed as the frame's: measured identical to 1e-4 px), and at the truth: measured
    // within 0.27 px (the contrast image's noise); a window shifted by one pixel is off by one.
    const ExpectedBoard place = roughPlace(truth);
    ImageDetection whole;
    whole.features.K = camera.K();
    image_detection::detectPlain(image_detection::boardContrastImage(image, camera, place), camera,
                                 board(), ImageBoardDetectorOptions{}, &whole, &place, nullptr);
    ASSERT_TRUE(whole.features.found) << "board " << k << ": " << whole.features.reason;
    for (int c = 0; c < kNumEdges; ++c) {
      EXPECT_LT((d.features.corners_px[c] - whole.features.corners_px[c]).norm(), 1e-3)
          << "board " << k << " corner " << c;
      double nearest = 1e9;
      for (const auto& t : truth)
        nearest = std::min(nearest, (d.features.corners_px[c] - t).norm());
      EXPECT_LT(nearest, 0.5) << "board " << k << " corner " << c;
      for (const auto& l : {d.features.edge_lines[c], d.features.edge_lines[(c + 1) % 4]})
        EXPECT_LT(std::abs(l.head<2>().dot(d.features.corners_px[c]) + l.z()), 1e-6);
    }
    const Eigen::Vector3d centre = camera_T_board * board().center();
    EXPECT_LT((d.features.camera_T_board * board().center() - centre).norm(), 0.01 * at.norm())
        << "board " << k;
    // The debug outline is in whole-frame raw pixels too: near the board.
    for (const auto& p : d.details.edge_points_raw[0])
      EXPECT_LT(std::abs(d.features.edge_lines[0].head<2>().dot(camera.undistortPixel(p)) +
                         d.features.edge_lines[0].z()),
                1.0);
    ++k;
  }
}

// The colour contrast as boardContrastImage maps it: board at 177.5, surroundings at 77.5.
cv::Mat contrastOf(const std::array<Eigen::Vector2d, kNumEdges>& board_quad) {
  cv::Mat c(600, 800, CV_8U, cv::Scalar(78));
  std::vector<cv::Point> poly;
  for (const auto& p : board_quad)
    poly.emplace_back(int(std::lround(p.x())), int(std::lround(p.y())));
  cv::fillConvexPoly(c, poly, cv::Scalar(178), cv::LINE_AA);
  addNoise(6.0, &c);
  return c;
}

CameraModel plainCamera() { return sim::makeCamera(800, 600, 800, DistortionModel::kNone, {}); }

CameraBoardFeatures quadFeatures(const std::array<Eigen::Vector2d, kNumEdges>& q) {
  CameraBoardFeatures f;
  f.found = true;
  // Corner j ends side j; side j runs from corner j-1 (clockwise, image v down).
  const Eigen::Vector2d centre = 0.25 * (q[0] + q[1] + q[2] + q[3]);
  for (int j = 0; j < kNumEdges; ++j) {
    f.corners_px[j] = q[j];
    f.edge_lines[j] = lineThrough(q[(j + 3) % 4], q[j], centre);
    f.edge_valid[j] = true;
  }
  return f;
}

TEST(ColourWindow, EverySideMustPartTheBoardsColourFromItsSurroundings) {
  const CameraModel camera = plainCamera();
  const std::array<Eigen::Vector2d, kNumEdges> board_quad = {
      Eigen::Vector2d(200, 150), {600, 170}, {590, 450}, {210, 430}};
  const cv::Mat contrast = contrastOf(board_quad);
  // The board itself.
  CameraBoardFeatures f = quadFeatures(board_quad);
  EXPECT_TRUE(sidesPartColours(contrast, camera, &f)) << f.reason;
  // The board with a same-coloured occluder over a third of its right side: medians decide.
  cv::Mat occluded = contrast.clone();
  cv::circle(occluded, cv::Point(600, 240), 45, cv::Scalar(178), cv::FILLED);
  f = quadFeatures(board_quad);
  EXPECT_TRUE(sidesPartColours(occluded, camera, &f)) << f.reason;
  // A quadrilateral whose right side (LR: corner j ends side j, clockwise from the left side)
  // runs inside the board (printed marks, a leg in front):
  // board on both sides of it.
  const std::array<Eigen::Vector2d, kNumEdges> inner = {
      Eigen::Vector2d(200, 150), {470, 163}, {463, 440}, {210, 430}};
  f = quadFeatures(inner);
  EXPECT_FALSE(sidesPartColours(contrast, camera, &f));
  EXPECT_FALSE(f.found);
  EXPECT_NE(f.reason.find("side LR does not part"), std::string::npos) << f.reason;
  // A scene rectangle of the board's colour's opposite: inside darker than outside.
  cv::Mat inverted = 255 - contrast;
  f = quadFeatures(board_quad);
  EXPECT_FALSE(sidesPartColours(inverted, camera, &f));
}

// A cardboard board held as a diamond by a person 0.5 m across the shoulders (the street
// board, 0.89 x 1.20 m, at 7 m): in the frame's colour parts the board and the person's dark
// blue clothes depart from the grey street as one part, too concave to be a board. The openings
// up to half the board's inradius leave the shoulders on it; the holder's opening, sized from
// the declared board, cuts them off, and the board's part is among the places tried.
TEST(ColourWindow, ThePersonHoldingTheBoardIsCutOffItsColourPart) {
  const CameraModel camera = sim::makeCamera(1280, 960, 1000, DistortionModel::kNone, {});
  Target target;
  target.type = TargetType::kPlain;
  target.width = 0.89;
  target.height = 1.2;
  const double z = 7.0;
  const Eigen::Vector3d centre(0.3, -0.2, z);
  const Eigen::Isometry3d camera_T_board =
      makeTransform(fromRollPitchYaw({0.0, 0.0, M_PI / 4}),
                    centre - fromRollPitchYaw({0.0, 0.0, M_PI / 4}) * target.center());
  std::array<Eigen::Vector2d, kNumEdges> truth;
  const auto corners = target.outerCorners();
  for (int k = 0; k < kNumEdges; ++k)
    ASSERT_TRUE(camera.projectUndistorted(camera_T_board * corners[k], &truth[k]));
  Eigen::Vector2d centre_px;
  ASSERT_TRUE(camera.projectUndistorted(centre, &centre_px));
  std::mt19937 rng(5);
  cv::Mat image(960, 1280, CV_8UC3, cv::Scalar(120, 121, 122));
  // Grey clutter without corners (a single frame cannot tell a lone grey rectangle of the
  // board's shape from a plain board).
  std::uniform_int_distribution<int> x(0, 1280), y(0, 960), r(15, 90), g(70, 180);
  for (int k = 0; k < 30; ++k) {
    const int level = g(rng);
    cv::circle(image, cv::Point(x(rng), y(rng)), r(rng), cv::Scalar(level, level, level),
               cv::FILLED, cv::LINE_AA);
  }
  // The person stands 0.2 m behind the board, from its centre down to the image's bottom.
  const double shoulders_px = 0.5 * 1000 / (z + 0.2);
  cv::rectangle(image,
                cv::Rect(static_cast<int>(centre_px.x() - shoulders_px / 2),
                         static_cast<int>(centre_px.y()), static_cast<int>(shoulders_px), 960),
                cv::Scalar(90, 40, 30), cv::FILLED);
  std::vector<cv::Point> poly;
  for (const auto& c : truth)
    poly.emplace_back(static_cast<int>(std::lround(c.x())), static_cast<int>(std::lround(c.y())));
  cv::fillConvexPoly(image, poly, cv::Scalar(60, 110, 170), cv::LINE_AA);
  addNoise(2.0, &image);

  EXPECT_GT(image_detection::holderOpeningFraction(target), 0.5);
  const auto places =
      image_detection::colourPartBoards(image, camera, target, ImageBoardDetectorOptions{});
  double best = 1e9;
  for (const ExpectedBoard& p : places)
    best = std::min(best, image_detection::worstCornerOffset(truth, p.corners_px) /
                              std::max(1.0, p.tolerance_px));
  // Within the place's own tolerance (a quarter of its side): the window search starts there.
  EXPECT_LE(best, 1.0) << places.size() << " places";
  // And the detector finds the board there, to a pixel.
  auto det = ImageBoardDetector::create(target, ImageBoardDetectorOptions{});
  ASSERT_TRUE(det.ok()) << det.error();
  const ImageDetection d = det->detect(image, camera);
  ASSERT_TRUE(d.features.found) << d.features.reason;
  EXPECT_LT(image_detection::worstCornerOffset(d.features.corners_px, truth), 1.0);
}

}  // namespace
}  // namespace board_calib
