// Image board detector against the simulator's ground truth: plain board (edges, corners),
// checkerboard and AprilTag grid from 1.5 to 6 m on a distorted 1920x1200 camera, plus the
// failure reasons.
#include <board_calib/core/common/statistics.h>
#include <board_calib/core/image_detection/image_board_detector.h>
#include <board_calib/core/sim/simulator.h>
#include <board_calib/core/transform.h>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <functional>

namespace board_calib {
namespace {

using sim::RenderOptions;
using sim::SceneSpec;

CameraModel testCamera() {
  CameraIntrinsics in;
  in.width = 1920;
  in.height = 1200;
  in.fx = 1500;
  in.fy = 1502;
  in.cx = 963.5;
  in.cy = 597.2;
  in.model = DistortionModel::kPlumbBob;
  in.coeffs = {-0.13, -0.03, 0.002, 0.0008, 0.0};  // like the real Basler camera
  auto camera = CameraModel::create(in);
  EXPECT_TRUE(camera.ok()) << camera.error();
  return *camera;
}

Target configTarget(const std::string& name) {
  auto target = loadTarget(std::string(BOARD_CALIB_SOURCE_DIR) + "/config/targets/" + name);
  EXPECT_TRUE(target.ok()) << target.error();
  return *target;
}

// Camera optical frame in a world with z up, looking along world +x.
Eigen::Isometry3d worldTCamera() {
  Eigen::Matrix3d R;
  R << 0, 0, 1, -1, 0, 0, 0, -1, 0;
  return makeTransform(R, Eigen::Vector3d(0, 0, 0.2));
}

// Board centre at `centre` (camera frame), facing the camera, rolled about the view axis
// (45 deg = diamond with the board origin on top), then turned by yaw/pitch.
Eigen::Isometry3d cameraTBoard(const Target& t, const Eigen::Vector3d& centre, double roll_deg,
                               double yaw_deg, double pitch_deg) {
  const Eigen::Matrix3d R = (Eigen::AngleAxisd(yaw_deg * kRadPerDeg, Eigen::Vector3d::UnitY()) *
                             Eigen::AngleAxisd(pitch_deg * kRadPerDeg, Eigen::Vector3d::UnitX()) *
                             Eigen::AngleAxisd(roll_deg * kRadPerDeg, Eigen::Vector3d::UnitZ()))
                                .toRotationMatrix();
  return makeTransform(R, centre - R * t.center());
}

struct Rendered {
  cv::Mat image;
  Eigen::Isometry3d camera_T_board;
};

Rendered render(const CameraModel& camera, const Target& target,
                const Eigen::Isometry3d& camera_T_board, std::mt19937& rng, bool room = true,
                double board_grey = SceneSpec{}.board_grey,
                const Eigen::Vector3d& board_tint = Eigen::Vector3d::Ones()) {
  SceneSpec scene;
  scene.target = target;
  scene.room = room;
  scene.board_grey = board_grey;
  scene.board_tint = board_tint;
  const Eigen::Isometry3d world_T_camera = worldTCamera();
  RenderOptions options;  // default noise (2 grey levels) and vignetting
  return {sim::renderCameraImage(camera, world_T_camera, scene, world_T_camera * camera_T_board,
                                 options, rng),
          camera_T_board};
}

Eigen::Vector2d projectTruth(const Eigen::Isometry3d& camera_T_board,
                             const Eigen::Vector3d& p_board, const CameraModel& camera) {
  Eigen::Vector2d px;
  EXPECT_TRUE(camera.projectUndistorted(camera_T_board * p_board, &px));
  return px;
}

double normalErrorDeg(const CameraBoardFeatures& f, const Eigen::Isometry3d& truth) {
  return std::acos(std::clamp(f.plane.normal.dot(truth.linear().col(2)), -1.0, 1.0)) * kDegPerRad;
}

// px from the found edge line j to the true edge's midpoint.
double edgeOffPx(const CameraBoardFeatures& f, const Eigen::Isometry3d& truth, const Target& target,
                 const CameraModel& camera, int j) {
  const auto outer = target.outerCorners();
  const Eigen::Vector2d mid = 0.5 * (projectTruth(truth, outer[(j + 3) % 4], camera) +
                                     projectTruth(truth, outer[j], camera));
  const Eigen::Vector3d& l = f.edge_lines[j];
  return std::abs(l.head<2>().dot(mid) + l.z());
}

bool insideImage(const CameraModel& camera, const Eigen::Vector2d& undistorted) {
  const Eigen::Vector2d r = camera.distortPixel(undistorted);
  return r.x() >= 0 && r.y() >= 0 && r.x() <= camera.width() - 1 && r.y() <= camera.height() - 1;
}

// Set BOARD_CALIB_DEBUG_DIR to look at what the detector saw.
void writeDebug(const std::string& name, const cv::Mat& image, const CameraModel& camera,
                const ImageDetection& d) {
  if (const char* dir = std::getenv("BOARD_CALIB_DEBUG_DIR"))
    cv::imwrite(std::string(dir) + "/" + name + ".png", drawImageDetection(image, camera, d));
}

struct Pose {
  double distance, x, y, roll, yaw, pitch;
};
// 1.5 m: the diamond is cut by the top and bottom image borders; 6 m: ~250 px board.
const std::vector<Pose> kPoses = {{1.5, 0.05, 0.0, 45, 12, -8},
                                  {2.5, -0.3, 0.1, 40, -20, 10},
                                  {4.0, 0.4, -0.2, 50, 25, 5},
                                  {6.0, -0.5, 0.3, 45, -10, -15}};

TEST(ImageDetectorSim, PlainBoardCornersLinesAndPlane) {
  const CameraModel camera = testCamera();
  const Target target = configTarget("plain_1016.yaml");
  auto det = ImageBoardDetector::create(target, ImageBoardDetectorOptions{});
  ASSERT_TRUE(det.ok()) << det.error();
  std::mt19937 rng(7);
  for (const Pose& p : kPoses) {
    // No textured room: the simulated grey board matches the grey wall and floor tiles in
    // brightness along long stretches (a known limit of the segmentation, see the report).
    const Rendered r =
        render(camera, target, cameraTBoard(target, {p.x, p.y, p.distance}, p.roll, p.yaw, p.pitch),
               rng, false);
    const ImageDetection d = det->detect(r.image, camera);
    writeDebug("sim_plain_" + std::to_string(p.distance), r.image, camera, d);
    const CameraBoardFeatures& f = d.features;
    ASSERT_TRUE(f.found) << p.distance << " m: " << f.reason;
    const auto outer = target.outerCorners();
    for (int j = 0; j < kNumEdges; ++j) {
      // Corner j of the diamond is board outer corner j (documented correspondence).
      const Eigen::Vector2d truth = projectTruth(r.camera_T_board, outer[j], camera);
      const double err = (f.corners_px[j] - truth).norm();
      // Issue target 0.3 px for corners in the image. Corners outside it are extrapolated from
      // edges seen over a shorter length, so their error grows with the distance extrapolated.
      const double tol = insideImage(camera, truth) ? 0.3 : 1.0;
      EXPECT_LT(err, tol) << p.distance << " m, corner " << j;
      // Each true edge endpoint lies on the detected line (lines, not only corners, matter for
      // PBPC).
      const Eigen::Vector2d a = projectTruth(r.camera_T_board, outer[(j + 3) % 4], camera);
      const Eigen::Vector2d b = projectTruth(r.camera_T_board, outer[j], camera);
      const Eigen::Vector3d& l = f.edge_lines[j];
      const Eigen::Vector2d mid = 0.5 * (a + b);
      EXPECT_LT(std::abs(l.head<2>().dot(mid) + l.z()), 0.3)
          << p.distance << " m, edge " << edgeName(j);
    }
    // Issue target: plane normal within 0.3 deg.
    EXPECT_LT(normalErrorDeg(f, r.camera_T_board), 0.3) << p.distance << " m";
    EXPECT_NEAR(f.plane.offset,
                r.camera_T_board.linear().col(2).dot(r.camera_T_board.translation()),
                0.01 * p.distance)  // 1 % depth: a 0.3 px error on a ~250 px board at 6 m is 0.1 %
        << p.distance << " m";
  }
}

TEST(ImageDetectorSim, CheckerboardCornersAndPlane) {
  const CameraModel camera = testCamera();
  const Target target = configTarget("checkerboard_7x5.yaml");
  auto det = ImageBoardDetector::create(target, ImageBoardDetectorOptions{});
  ASSERT_TRUE(det.ok()) << det.error();
  std::mt19937 rng(11);
  for (const Pose& p : kPoses) {
    // Roll kept below 45 deg: the pattern is oriented with board x towards image +u.
    const Rendered r =
        render(camera, target,
               cameraTBoard(target, {p.x, p.y, p.distance}, p.roll - 25, p.yaw, p.pitch), rng);
    const ImageDetection d = det->detect(r.image, camera);
    const CameraBoardFeatures& f = d.features;
    ASSERT_TRUE(f.found) << p.distance << " m: " << f.reason;
    ASSERT_EQ(f.pattern.size(), 35u);
    double worst = 0;
    for (const auto& o : f.pattern)
      worst =
          std::max(worst, (o.pixel - projectTruth(r.camera_T_board, o.board_point, camera)).norm());
    EXPECT_LT(worst, 0.3) << p.distance << " m";  // issue target
    EXPECT_LT(normalErrorDeg(f, r.camera_T_board), 0.3) << p.distance << " m";
    EXPECT_LT(f.reprojection_rms_px, 0.3) << p.distance << " m";
    // Outer corners come from the pose: they must land on the true outer corners.
    const auto outer = target.outerCorners();
    for (int j = 0; j < 4; ++j) {
      double best = 1e9;
      for (int k = 0; k < 4; ++k)
        best = std::min(
            best, (f.corners_px[k] - projectTruth(r.camera_T_board, outer[j], camera)).norm());
      EXPECT_LT(best, 1.0) << p.distance << " m, outer corner "
                           << j;  // extrapolated past the pattern
    }
  }
}

TEST(ImageDetectorSim, AprilTagGridCornersAndPlane) {
  const CameraModel camera = testCamera();
  const Target target = configTarget("apriltag_grid_4x4.yaml");
  ImageBoardDetectorOptions options;
  options.tag_decimate = 1.0;  // full-resolution quads: 16 cm tags at 6 m are ~40 px
  auto det = ImageBoardDetector::create(target, options);
  ASSERT_TRUE(det.ok()) << det.error();
  std::mt19937 rng(13);
  for (const Pose& p : kPoses) {
    const Rendered r =
        render(camera, target,
               cameraTBoard(target, {p.x, p.y, p.distance}, p.roll - 30, p.yaw, p.pitch), rng);
    const ImageDetection d = det->detect(r.image, camera);
    const CameraBoardFeatures& f = d.features;
    ASSERT_TRUE(f.found) << p.distance << " m: " << f.reason;
    EXPECT_GE(d.details.tag_ids.size(), 12u) << p.distance << " m";  // 1.5 m cuts some tags off
    double worst = 0;
    for (const auto& o : f.pattern) {
      worst =
          std::max(worst, (o.pixel - projectTruth(r.camera_T_board, o.board_point, camera)).norm());
    }
    EXPECT_LT(worst, 0.5) << p.distance << " m";  // issue target for tags
    EXPECT_LT(normalErrorDeg(f, r.camera_T_board), 0.3) << p.distance << " m";
    EXPECT_EQ(d.details.pattern_errors_px.size(), f.pattern.size());
  }
}

TEST(ImageDetectorSim, WrongTagIdsAreReported) {
  const CameraModel camera = testCamera();
  const Target printed = configTarget("apriltag_grid_4x4.yaml");
  Target expected = printed;
  expected.apriltag_grid.first_id = 100;  // the detector expects other ids than the printed ones
  auto det = ImageBoardDetector::create(expected, ImageBoardDetectorOptions{});
  ASSERT_TRUE(det.ok()) << det.error();
  std::mt19937 rng(3);
  const Rendered r = render(camera, printed, cameraTBoard(printed, {0, 0, 2.5}, 10, 0, 0), rng);
  const ImageDetection d = det->detect(r.image, camera);
  EXPECT_FALSE(d.features.found);
  EXPECT_NE(d.features.reason.find("wrong ids"), std::string::npos) << d.features.reason;
}

TEST(ImageDetectorSim, FailuresGiveReasons) {
  const CameraModel camera = testCamera();
  const Target plain = configTarget("plain_1016.yaml");
  auto det = ImageBoardDetector::create(plain, ImageBoardDetectorOptions{});
  ASSERT_TRUE(det.ok());
  EXPECT_NE(det->detect(cv::Mat(), camera).features.reason.find("empty"), std::string::npos);
  EXPECT_NE(det->detect(cv::Mat(600, 800, CV_8UC1, cv::Scalar(0)), camera)
                .features.reason.find("does not match"),
            std::string::npos);
  EXPECT_NE(det->detect(cv::Mat(1200, 1920, CV_16UC1, cv::Scalar(0)), camera)
                .features.reason.find("unsupported"),
            std::string::npos);
  // A uniform image has no board; a noise image has no convex uniform region.
  const ImageDetection blank = det->detect(cv::Mat(1200, 1920, CV_8UC1, cv::Scalar(90)), camera);
  EXPECT_FALSE(blank.features.found);
  EXPECT_NE(blank.features.reason.find("not found"), std::string::npos) << blank.features.reason;
  cv::Mat noise(1200, 1920, CV_8UC1);
  cv::randu(noise, 0, 255);
  const ImageDetection noisy = det->detect(noise, camera);
  EXPECT_FALSE(noisy.features.found);
  EXPECT_FALSE(noisy.features.reason.empty());

  auto checker = ImageBoardDetector::create(configTarget("checkerboard_7x5.yaml"),
                                            ImageBoardDetectorOptions{});
  ASSERT_TRUE(checker.ok());
  const ImageDetection none =
      checker->detect(cv::Mat(1200, 1920, CV_8UC3, cv::Scalar(90, 90, 90)), camera);
  EXPECT_NE(none.features.reason.find("no 7x5 checkerboard"), std::string::npos)
      << none.features.reason;

  ImageBoardDetectorOptions bad;
  bad.fine_search_px = 20;  // wider than the coarse search
  EXPECT_FALSE(bad.validate().empty());
  EXPECT_FALSE(ImageBoardDetector::create(plain, bad).ok());
  ImageBoardDetectorOptions threads;
  threads.tag_threads = 100000;  // a thread each in libapriltag's pool
  EXPECT_NE(threads.validate().find("tag_threads"), std::string::npos);
  Target unknown_family = configTarget("apriltag_grid_4x4.yaml");
  unknown_family.apriltag_grid.family = "tag25h9";
  auto fam = ImageBoardDetector::create(unknown_family, ImageBoardDetectorOptions{});
  ASSERT_FALSE(fam.ok());
  EXPECT_NE(fam.error().find("tag25h9"), std::string::npos);
}

// A miss names the attempt its reason is from and where it was: in clutter that attempt may be
// another object, and a user reading only the reason would look at the wrong place. Here the
// only rectangle is 4:1, which no turn within max_board_tilt_deg makes a square board.
TEST(ImageDetectorSim, AMissNamesWhereItsBestAttemptWas) {
  const CameraModel camera = testCamera();
  auto det =
      ImageBoardDetector::create(configTarget("plain_1016.yaml"), ImageBoardDetectorOptions{});
  ASSERT_TRUE(det.ok());
  cv::Mat image(1200, 1920, CV_8UC1, cv::Scalar(90));
  const cv::Point2d centre(1300, 900);
  const cv::Size2d size(480, 120);
  cv::rectangle(
      image,
      cv::Rect2d(centre.x - size.width / 2, centre.y - size.height / 2, size.width, size.height),
      cv::Scalar(200), cv::FILLED);
  const ImageDetection d = det->detect(image, camera);
  ASSERT_FALSE(d.features.found);
  const ImageDetectionDetails& x = d.details;
  ASSERT_GE(x.best_attempt, 0) << d.features.reason;
  ASSERT_LT(x.best_attempt, static_cast<int>(x.hypothesis_reasons.size()));
  int index = -1, of = 0;
  double u = 0, v = 0;
  char source[64] = {};
  ASSERT_EQ(std::sscanf(d.features.reason.c_str(),
                        "best attempt #%d of %d (%63[^,], sides ~%*f px, centred at (%lf, %lf)",
                        &index, &of, source, &u, &v),
            5)
      << d.features.reason;
  EXPECT_EQ(index, x.best_attempt);
  EXPECT_EQ(of, static_cast<int>(x.hypotheses_px.size()));
  // The rest of the reason is that attempt's own rejection, as the hypothesis list gives it.
  const std::string& tried = x.hypothesis_reasons[static_cast<size_t>(index)];
  EXPECT_EQ(tried.substr(0, tried.find(':')), source);
  EXPECT_NE(d.features.reason.find(tried.substr(tried.find(": ") + 2)), std::string::npos)
      << d.features.reason << " / " << tried;
  // Where the rectangle is (raw px): within 5 % of its short side (the mean of the corners'
  // undistorted places, distorted back, is not quite the raw centre under the lens).
  EXPECT_NEAR(u, centre.x, 0.05 * size.height) << d.features.reason;
  EXPECT_NEAR(v, centre.y, 0.05 * size.height) << d.features.reason;
  // The debug image lists that attempt in orange (its sides are those drawn as the miss's
  // edges), the other hypotheses in blue.
  const cv::Mat debug = drawImageDetection(image, camera, d);
  cv::Mat orange;
  cv::inRange(debug, cv::Scalar(0, 140, 255), cv::Scalar(0, 140, 255), orange);
  const int thick = std::max(1, image.cols / 800), row = 18 * thick;  // drawImageDetection's
  const cv::Rect line(0, 30 * thick + index * row + row / 4, image.cols, row);
  EXPECT_GT(cv::countNonZero(orange(line)), 0) << "its line of the list";
  orange(line).setTo(0);
  const cv::Rect outline(
      cv::Point(static_cast<int>(centre.x - size.width / 2) - 8,
                static_cast<int>(centre.y - size.height / 2) - 8),
      cv::Size(static_cast<int>(size.width) + 16, static_cast<int>(size.height) + 16));
  orange(outline).setTo(0);
  EXPECT_EQ(cv::countNonZero(orange), 0) << "orange elsewhere than its line and its outline";
}

TEST(ImageDetectorSim, PlainBoardEdgeAlongBorderIsNotAnEdge) {
  // Board shifted so its right corner region leaves the image: the border segment must not be
  // reported as an edge, and every reported edge must still be a true board edge.
  const CameraModel camera = testCamera();
  const Target target = configTarget("plain_1016.yaml");
  auto det = ImageBoardDetector::create(target, ImageBoardDetectorOptions{});
  ASSERT_TRUE(det.ok());
  std::mt19937 rng(5);
  const Rendered r =
      render(camera, target, cameraTBoard(target, {0.75, 0.0, 2.0}, 45, 0, 0), rng, false);
  const ImageDetection d = det->detect(r.image, camera);
  writeDebug("sim_plain_border", r.image, camera, d);
  const auto outer = target.outerCorners();
  for (int j = 0; j < kNumEdges; ++j) {
    if (!d.features.edge_valid[j]) continue;
    const Eigen::Vector2d a = projectTruth(r.camera_T_board, outer[(j + 3) % 4], camera);
    const Eigen::Vector2d b = projectTruth(r.camera_T_board, outer[j], camera);
    const Eigen::Vector3d& l = d.features.edge_lines[j];
    EXPECT_LT(std::abs(l.head<2>().dot(0.5 * (a + b)) + l.z()), 0.5) << edgeName(j);
  }
  EXPECT_TRUE(d.features.found) << d.features.reason;
}

// A far board (12-15 m: 100-125 px across, in the lower left of the image) and `windows` frames
// of 4:1 windows, 300-700 px long, in the upper band and the right part, away from the board:
// each outline gives up to 8 edges longer than the board's sides, and rectangles whose lines end
// at their corners. A square board fits none of them (turned past max_board_tilt_deg). The
// frames' grey is scaled per channel by `tint` (BGR).
Rendered farBoardBehindWindows(const CameraModel& camera, const Target& target, unsigned seed,
                               int windows, const cv::Vec3d& tint = {1, 1, 1}) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> unit(-1.0, 1.0), u01(0.0, 1.0);
  const double z = 12.0 + 3.0 * u01(rng);
  const Eigen::Isometry3d truth =
      cameraTBoard(target, {-0.25 * z + 0.05 * z * unit(rng), 0.12 * z + 0.03 * z * unit(rng), z},
                   45 + 10 * unit(rng), 25 * unit(rng), 20 * unit(rng));
  Rendered r = render(camera, target, truth, rng, false);
  for (int k = 0; k < windows; ++k) {
    const double grey = 60 + 160 * u01(rng), len = 300 + 400 * u01(rng);
    const bool wide = k % 2 == 0;
    const cv::Point2d size = wide ? cv::Point2d(len, len / 4) : cv::Point2d(len / 4, len);
    const cv::Point2d at =
        wide ? cv::Point2d(40 + (1860 - len) * u01(rng), 30 + 200 * u01(rng))
             : cv::Point2d(1000 + (860 - len / 4) * u01(rng), 30 + (1150 - len) * u01(rng));
    cv::rectangle(r.image, cv::Rect2d(at, at + size),
                  cv::Scalar(tint[0] * grey, tint[1] * grey, tint[2] * grey),
                  3 + static_cast<int>(3 * u01(rng)), cv::LINE_AA);
  }
  return r;
}

// The worst of the found board's four lines against the truth (px; 0 when not found), printed.
double worstFoundEdgePx(const ImageDetection& d, const Rendered& r, const Target& target,
                        const CameraModel& camera, const std::string& name) {
  double off = 0;
  for (int j = 0; j < kNumEdges && d.features.found; ++j)
    off = std::max(off, edgeOffPx(d.features, r.camera_T_board, target, camera, j));
  std::printf("%s: %.1f m, %d lines, found %d (%s), worst edge %.2f px %s\n", name.c_str(),
              r.camera_T_board.translation().norm(), d.details.straight_lines, d.features.found,
              d.details.board_source.c_str(), off, d.features.reason.c_str());
  return off;
}

// Boards found in `frames` renders of scene(i), with the worst found edge against the truth and
// how many of the frames had the line stage keep as many lines as it may (200).
struct SceneTally {
  int found = 0, full_line_sets = 0;
  double worst_px = 0;
};
SceneTally detectEach(int frames, const std::function<Rendered(int)>& scene,
                      const std::string& name, const std::string& debug_name) {
  const CameraModel camera = testCamera();
  const Target target = configTarget("plain_1016.yaml");
  auto det = ImageBoardDetector::create(target, ImageBoardDetectorOptions{});
  EXPECT_TRUE(det.ok()) << det.error();
  SceneTally t;
  for (int i = 0; i < frames && det.ok(); ++i) {
    const Rendered r = scene(i);
    const ImageDetection d = det->detect(r.image, camera);
    writeDebug(debug_name + "_" + std::to_string(i), r.image, camera, d);
    t.found += d.features.found;
    t.full_line_sets += d.details.lines_px.size() >= 200;
    t.worst_px = std::max(t.worst_px,
                          worstFoundEdgePx(d, r, target, camera, name + " " + std::to_string(i)));
  }
  return t;
}

// A far board (~100 px, too small for a region proposal) in a scene of many longer lines: its
// sides rank behind the window frames' edges, so only the quadrilaterals of the lines past
// max_lines can outline it, and its segment support is far below that of the frames'
// rectangles. Ranked by the gradient along their sides, it is tried and found with its true
// lines; no window passes for it. The boards, windows and seeds vary.
TEST(ImageDetectorSim, AFarBoardBehindManyLongerLinesIsFoundByItsSides) {
  const CameraModel camera = testCamera();
  const Target target = configTarget("plain_1016.yaml");
  constexpr int kFrames = 12;
  const SceneTally t = detectEach(
      kFrames, [&](int i) { return farBoardBehindWindows(camera, target, 40 + i, 30); },
      "far board behind lines", "sim_plain_far_lines");
  // Measured: 12 of 12, lines within 0.03 px. Before the weak lines' quadrilaterals were ranked
  // by their sides' gradient (their segment score had to match the best quadrilaterals'), 4 of
  // 12: in the others no board was found (the attempt reported: a window frame's quadrilateral,
  // which fits no board).
  EXPECT_EQ(t.found, kFrames);
  EXPECT_LT(t.worst_px, 1.0);  // sub-pixel lines on a ~100 px board (issue 14)
}

// farBoardBehindWindows' board with a hand over one side: a disc of another grey hides 40 % of
// the side, at its middle or near its corner (the seed picks the side, the place and the grey).
Rendered farBoardWithAHandOverASide(const CameraModel& camera, const Target& target, unsigned seed,
                                    int windows) {
  Rendered r = farBoardBehindWindows(camera, target, seed, windows);
  const auto outer = target.outerCorners();
  const int j = static_cast<int>(seed % kNumEdges);
  const Eigen::Vector2d a = projectTruth(r.camera_T_board, outer[(j + 3) % 4], camera);
  const Eigen::Vector2d b = projectTruth(r.camera_T_board, outer[j], camera);
  const double at = (seed / kNumEdges) % 2 == 0 ? 0.5 : 0.25;  // of the side, from corner a
  const double radius = 0.2 * (b - a).norm();
  const Eigen::Vector2d centre = camera.distortPixel(a + at * (b - a));
  const double grey = 90.0 + 13.0 * (seed % 9);
  cv::circle(r.image,
             cv::Point(static_cast<int>(std::lround(centre.x())),
                       static_cast<int>(std::lround(centre.y()))),
             static_cast<int>(std::lround(radius)), cv::Scalar(grey, grey, grey), cv::FILLED,
             cv::LINE_AA);
  return r;
}

// A hand hides 40 % of one side of a far board in a scene of longer lines. The weak lines'
// quadrilaterals must show every side's edge along most of its length, and only a few are
// refined: the windows' rectangles, whose sides show their edges all along, took those places.
// Now only quadrilaterals that could be the declared board are ranked, and where the lines end
// at three corners one side need only show what every board side must (min_side_coverage).
// Measured: 14 of 16 found, lines within 0.07 px; before, 7 of 16.
TEST(ImageDetectorSim, AFarBoardWithAHandOverASideIsFoundByItsOtherSides) {
  const CameraModel camera = testCamera();
  const Target target = configTarget("plain_1016.yaml");
  constexpr int kFrames = 16;
  const SceneTally t = detectEach(
      kFrames, [&](int i) { return farBoardWithAHandOverASide(camera, target, 40 + i, 30); },
      "far board with a hand over a side", "sim_plain_far_hand");
  EXPECT_GE(t.found, 14);
  EXPECT_LT(t.worst_px, 1.0);
}

// farBoardBehindWindows' board with `strokes` straight strokes instead of windows, 400-1600 px
// long at any angle, in the same parts of the image: each gives two lines longer than the
// board's sides, and they cross rather than end at each other, as an office ceiling's and
// floor's lines do.
Rendered farBoardUnderCrossingLines(const CameraModel& camera, const Target& target, unsigned seed,
                                    int strokes) {
  Rendered r = farBoardBehindWindows(camera, target, seed, 0);
  std::mt19937 rng(seed + 1000);
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  const cv::Rect2d band(40, 30, 1840, 300), right(1000, 30, 880, 1140);
  for (int k = 0; k < strokes; ++k) {
    const cv::Rect2d& zone = k % 2 == 0 ? band : right;
    cv::Point2d a, b;
    do {
      a = {zone.x + zone.width * u01(rng), zone.y + zone.height * u01(rng)};
      b = {zone.x + zone.width * u01(rng), zone.y + zone.height * u01(rng)};
    } while (cv::norm(b - a) < 400 || cv::norm(b - a) > 1600);
    const double grey = 60 + 160 * u01(rng);
    cv::line(r.image, a, b, cv::Scalar(grey, grey, grey), 2 + static_cast<int>(3 * u01(rng)),
             cv::LINE_AA);
  }
  cv::cvtColor(r.image, r.image, cv::COLOR_BGR2GRAY);
  return r;
}

// Far boards under more long crossing lines than the search keeps (grey images: no colour part
// or stable region to fall back on). Ranked by support alone, the board's ~100 px sides fell
// past the 200 lines kept, as a far board's did in the rs16 office (augmented real frames); the
// lines past the first ones that end at a corner, as the board's do and crossing lines do not,
// now rank before the rest. The boards, strokes and seeds vary.
TEST(ImageDetectorSim, AFarBoardUnderManyLongerCrossingLinesIsFoundByItsCorners) {
  const CameraModel camera = testCamera();
  const Target target = configTarget("plain_1016.yaml");
  constexpr int kFrames = 8;
  const SceneTally t = detectEach(
      kFrames, [&](int i) { return farBoardUnderCrossingLines(camera, target, 80 + i, 160); },
      "far board under crossing lines", "sim_plain_far_crossing");
  EXPECT_EQ(t.full_line_sets, kFrames);  // the search kept as many lines as it may: the case
  EXPECT_EQ(t.found, kFrames);
  EXPECT_LT(t.worst_px, 1.0);
}

// A camera_T_board from {x, y, z, qw, qx, qy, qz}.
Eigen::Isometry3d poseOf(const double* p) {
  return makeTransform(Eigen::Quaterniond(p[3], p[4], p[5], p[6]).normalized().toRotationMatrix(),
                       Eigen::Vector3d(p[0], p[1], p[2]));
}

// Boards found in a render of `scene` with the board at camera_T_board (2 x 2 supersampling), and
// how many of them were another object (normal > 5 deg or centre > 0.3 m off the truth; printed).
struct FoundBoards {
  int found = 0, wrong = 0;
};
void detectInRender(const CameraModel& camera, const SceneSpec& scene, ImageBoardDetector& det,
                    const Eigen::Isometry3d& camera_T_board, std::mt19937& rng,
                    const std::string& name, FoundBoards* tally) {
  RenderOptions options;
  options.supersampling = 2;
  const cv::Mat image = sim::renderCameraImage(camera, worldTCamera(), scene,
                                               worldTCamera() * camera_T_board, options, rng);
  const ImageDetection d = det.detect(image, camera);
  writeDebug(name, image, camera, d);
  if (!d.features.found) return;
  ++tally->found;
  const Eigen::Vector3d centre = d.features.camera_T_board * scene.target.center();
  const double centre_off = (centre - camera_T_board * scene.target.center()).norm();
  const double normal_off = normalErrorDeg(d.features, camera_T_board);
  if (normal_off <= 5.0 && centre_off <= 0.3) return;
  ++tally->wrong;
  std::printf("%s: a board %.2f m and %.1f deg off, at %.1f m (%s)\n", name.c_str(), centre_off,
              normal_off, centre.norm(), d.details.board_source.c_str());
}

// A street's facade windows are as board-shaped as a 4:3 board 14 m away, and stable regions.
// With the real board near but heavily grained and missed, one of them was taken as the board
// (test_fuzz_detectors' hostile view sets, round 0, rig 2: poses 1, 6, 8 and 9 of 14, 10 m
// off; here 3 of these 6 frames before the rule). A region that stands in a row of alike ones
// is the scene's. That rig's camera, board and poses (camera_T_board: translation, quaternion
// w x y z).
TEST(ImageDetectorSim, AFacadesWindowsAreNeverTheBoard) {
  CameraIntrinsics in;
  in.width = 960;
  in.height = 600;
  in.fx = in.fy = 828.493;
  in.cx = 496.535;
  in.cy = 284.071;
  in.model = DistortionModel::kPlumbBob;
  in.coeffs = {-0.1891, 0.0073, 0, 0, 0};
  const CameraModel camera = *CameraModel::create(in);
  Target target;
  target.type = TargetType::kPlain;
  target.width = 0.8;
  target.height = 0.6;
  auto det = ImageBoardDetector::create(target, ImageBoardDetectorOptions{});
  ASSERT_TRUE(det.ok()) << det.error();
  SceneSpec scene;
  scene.target = target;
  scene.room = false;
  scene.outdoor = true;
  scene.board_grey = 0.562;
  scene.board_tint = Eigen::Vector3d(0.575, 0.991, 0.687);
  scene.board_texture = 0.337;
  const double poses[][7] = {{-0.7311, 0.0383, 3.9165, 0.83538, -0.14622, -0.20761, 0.48750},
                             {-0.7834, 0.3691, 3.4403, 0.52274, -0.20195, -0.11784, -0.81980},
                             {0.3398, 0.3618, 4.2007, 0.55717, 0.22093, -0.10340, -0.79376},
                             {0.9547, 0.0159, 3.8787, 0.54683, -0.07957, -0.19231, 0.81096},
                             {0.1109, 0.4001, 2.6236, 0.26366, 0.18477, -0.17142, 0.93111},
                             {-1.2113, -1.1166, 5.7447, 0.98618, -0.00379, -0.13456, 0.09658}};
  std::mt19937 rng(11);
  FoundBoards boards;
  for (size_t i = 0; i < std::size(poses); ++i)
    detectInRender(camera, scene, *det, poseOf(poses[i]), rng,
                   "sim_facade_windows_" + std::to_string(i), &boards);
  std::printf("facade windows: %d of %zu frames found, %d wrong\n", boards.found, std::size(poses),
              boards.wrong);
  EXPECT_EQ(boards.wrong, 0);
}

// A room of wall panels and floor tiles (the simulator's textured room) and a plain board before
// them: a 4:3 board darker than every panel and a square one of about their grey. The panels'
// long seams outscore the board's sides on segment support: the board's own quadrilateral ranked
// past the line search's first ones and was never tried (test_fuzz_detectors' view sets, round 1:
// 11 of 14 frames of a dark 4:3 board took a panel, normals 7-55 deg off). Measured here before
// the change: 3 of 20 found, 2 of them wrong; after: 12 found, none wrong. The room alone gives
// no board.
TEST(ImageDetectorSim, ATiledRoomsPanelsAndTilesAreNeverTheBoard) {
  CameraIntrinsics in;
  in.width = 960;
  in.height = 600;
  in.fx = in.fy = 1015.0;
  in.cx = 472.0;
  in.cy = 309.0;
  in.model = DistortionModel::kPlumbBob;
  in.coeffs = {-0.12, 0.02, 0, 0, 0};
  const CameraModel camera = *CameraModel::create(in);
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  FoundBoards boards;
  int frames = 0;
  for (int board = 0; board < 2; ++board) {
    Target target = configTarget("plain_1016.yaml");
    SceneSpec scene;
    if (board == 0) {
      target.width = 0.8;
      target.height = 0.6;
      scene.board_grey = 0.13;
    } else {
      scene.board_grey = 0.45;
      scene.board_tint = Eigen::Vector3d(0.8, 0.9, 0.85);
    }
    scene.target = target;
    scene.room = true;
    auto det = ImageBoardDetector::create(target, ImageBoardDetectorOptions{});
    ASSERT_TRUE(det.ok()) << det.error();
    for (int pose = 0; pose < 10; ++pose, ++frames) {
      const double distance = 2.0 + 4.0 * unit(rng);
      const Eigen::Vector3d centre =
          Eigen::Vector3d(0.5 * unit(rng) - 0.25, 0.3 * unit(rng) - 0.15, 1.0) * distance;
      const Eigen::Matrix3d R =
          (Eigen::AngleAxisd(1.2 * unit(rng) - 0.6, Eigen::Vector3d::UnitY()) *
           Eigen::AngleAxisd(1.0 * unit(rng) - 0.5, Eigen::Vector3d::UnitX()) *
           Eigen::AngleAxisd(2 * M_PI * unit(rng) - M_PI, Eigen::Vector3d::UnitZ()))
              .toRotationMatrix();
      detectInRender(camera, scene, *det, makeTransform(R, centre - R * target.center()), rng,
                     "sim_tiled_room_" + std::to_string(board) + "_" + std::to_string(pose),
                     &boards);
    }
  }
  std::printf("tiled room: %d of %d frames found, %d wrong\n", boards.found, frames, boards.wrong);
  EXPECT_EQ(boards.wrong, 0);
  EXPECT_GE(boards.found, frames / 2);
  // The room alone (the board behind the camera), looked at from other places: every board found
  // is a panel or a tile.
  int empty_found = 0;
  for (int view = 0; view < 8; ++view) {
    const Target target = configTarget("plain_1016.yaml");
    SceneSpec scene;
    scene.target = target;
    scene.room = true;
    scene.occluder = false;
    auto det = ImageBoardDetector::create(target, ImageBoardDetectorOptions{});
    ASSERT_TRUE(det.ok()) << det.error();
    const Eigen::Matrix3d look =
        (Eigen::AngleAxisd(1.6 * unit(rng) - 0.8, Eigen::Vector3d::UnitZ()) *
         Eigen::AngleAxisd(0.5 * unit(rng) - 0.1, Eigen::Vector3d::UnitY()))
            .toRotationMatrix();
    Eigen::Isometry3d world_T_camera = worldTCamera();
    world_T_camera.linear() = look * world_T_camera.linear();
    world_T_camera.translation() = Eigen::Vector3d(4.0 * unit(rng) - 2.0, 4.0 * unit(rng) - 2.0, 0);
    const Eigen::Isometry3d behind =
        world_T_camera * makeTransform(Eigen::Matrix3d::Identity(), Eigen::Vector3d(0, 0, -3));
    RenderOptions options;
    options.supersampling = 2;
    const cv::Mat image =
        sim::renderCameraImage(camera, world_T_camera, scene, behind, options, rng);
    const ImageDetection d = det->detect(image, camera);
    writeDebug("sim_tiled_room_empty_" + std::to_string(view), image, camera, d);
    if (d.features.found)
      std::printf("empty room view %d: a board found (%s)\n", view, d.details.board_source.c_str());
    empty_found += d.features.found;
  }
  EXPECT_EQ(empty_found, 0);
}

// A square board of about the floor tiles' grey, with print, in the textured room (a rig of
// test_fuzz_detectors' view sets, round 1): where its sides do not show, the square floor tiles
// and wall panels are stable regions that fit a square board as well as the board does (a tile
// 0.6 m across is a 1.016 m board 1.7 times as far), and their copies in their own plane are
// what gives them away. Measured before: 11 of 14 frames took a tile or a panel (the same floor
// tile in 8), normals 25-114 deg off; after: 8 found, 2 wrong. Those two are left: a square
// patch of a wall panel between the board and the person holding it, and a 3:2 panel at the
// image border fitted as a tilted square (its copies out of view); a session's consistency
// check drops such single views.
TEST(ImageDetectorSim, ASquareBoardIsSeldomASquareTile) {
  CameraIntrinsics in;
  in.width = 960;
  in.height = 600;
  in.fx = in.fy = 510.0697;
  in.cx = 482.1879;
  in.cy = 304.5324;
  in.model = DistortionModel::kPlumbBob;
  in.coeffs = {0.0145, 0.01508, 0, 0, 0};
  const CameraModel camera = *CameraModel::create(in);
  const Target target = configTarget("plain_1016.yaml");
  SceneSpec scene;
  scene.target = target;
  scene.board_grey = 0.3792;
  scene.board_tint = Eigen::Vector3d(0.6478, 0.9163, 0.8243);
  for (const auto& m : {std::array<double, 4>{0.7366, 0.5287, 1.0160, 0.6705},
                        std::array<double, 4>{0.8950, 0.4846, 1.0160, 0.7023},
                        std::array<double, 4>{0.1804, 0.2236, 0.2506, 0.2734},
                        std::array<double, 4>{0.6496, 0.5601, 0.6845, 0.6688}}) {
    sim::BoardMark mark;
    mark.min = Eigen::Vector2d(m[0], m[1]);
    mark.max = Eigen::Vector2d(m[2], m[3]);
    scene.board_marks.push_back(mark);
  }
  auto det = ImageBoardDetector::create(target, ImageBoardDetectorOptions{});
  ASSERT_TRUE(det.ok()) << det.error();
  const double poses[][7] = {{-0.1966, -0.2592, 5.9211, 0.86622, 0.01839, 0.19025, 0.46166},
                             {-0.1356, -0.3910, 3.0161, 0.93780, -0.14146, 0.29745, 0.10973},
                             {0.8060, -0.9509, 4.5897, 0.54999, 0.12375, 0.00275, 0.82595},
                             {1.2146, 1.2663, 5.8009, -0.20029, -0.09805, 0.21504, 0.95080},
                             {-0.7491, -0.3957, 5.3839, 0.87020, 0.17827, 0.11796, -0.44391},
                             {-0.2866, 0.2097, 4.7246, 0.97164, 0.19603, -0.09355, 0.09346},
                             {-0.4456, 0.4619, 4.9656, 0.86740, -0.30254, 0.12915, -0.37337},
                             {1.3055, 1.3858, 5.3826, -0.17401, -0.08888, 0.17475, 0.96503},
                             {1.4479, 0.7626, 5.3857, 0.07993, -0.01617, 0.24690, 0.96560},
                             {-0.3726, -1.0085, 2.7341, 0.88636, -0.13631, -0.20404, 0.39263},
                             {-0.1177, -0.0397, 4.4548, 0.96206, 0.08002, 0.21921, -0.14137},
                             {0.7426, 0.0711, 4.8834, 0.28845, -0.17174, 0.02631, 0.94160},
                             {-0.2939, 0.0917, 2.4729, 0.86767, -0.16238, 0.14932, -0.44551},
                             {-0.5348, 0.0718, 3.1423, 0.86696, -0.06373, -0.15713, -0.46865}};
  std::mt19937 rng(3);
  FoundBoards boards;
  for (size_t i = 0; i < std::size(poses); ++i)
    detectInRender(camera, scene, *det, poseOf(poses[i]), rng,
                   "sim_square_tiles_" + std::to_string(i), &boards);
  std::printf("square board among square tiles: %d of %zu frames found, %d wrong\n", boards.found,
              std::size(poses), boards.wrong);
  EXPECT_LE(boards.wrong, 2);
  EXPECT_GE(boards.found - boards.wrong, 6);
}

// max_line_hypotheses 0 (a setting rqt_reconfigure allows) with more lines than the search
// ranks: no line quadrilateral is kept, and the lines past the cap are judged without a least
// score (it read the first of none: a segfault, test_fuzz_detectors' settings test, round 1).
TEST(ImageDetectorSim, NoLineHypothesesAllowedIsNoCrash) {
  const CameraModel camera = testCamera();
  const Target target = configTarget("plain_1016.yaml");
  ImageBoardDetectorOptions options;
  options.max_line_hypotheses = 0;
  auto det = ImageBoardDetector::create(target, options);
  ASSERT_TRUE(det.ok()) << det.error();
  for (int i = 0; i < 3; ++i) {
    const Rendered r = farBoardBehindWindows(camera, target, 40 + i, 30);
    const ImageDetection d = det->detect(r.image, camera);
    if (d.features.found) {
      EXPECT_EQ(malformedFeatures(d.features), "");
    } else {
      EXPECT_FALSE(d.features.reason.empty());
    }
  }
}

// The same far board behind five times as many window frames, in colour: ~1200 edges longer than
// its sides, at the line search's width and at the finer one, so no line search ranks the
// board's sides. It is still a stable region (uniform, bounded by its own contrast at every
// threshold near its grey) and found as one, with its true lines; no window cell passes for it.
// Measured: 8 of 8, lines within 0.01 px; 0 of 8 without the stable regions. The same frames
// from a mono camera are not searched for them (no colour to challenge what they find).
TEST(ImageDetectorSim, AFarBoardBehindMoreLinesThanAnySearchRanksIsAStableRegion) {
  const CameraModel camera = testCamera();
  const Target target = configTarget("plain_1016.yaml");
  auto det = ImageBoardDetector::create(target, ImageBoardDetectorOptions{});
  ASSERT_TRUE(det.ok()) << det.error();
  int found = 0, stable = 0, mono_stable = 0;
  double worst_px = 0;
  constexpr int kFrames = 8;
  for (int i = 0; i < kFrames; ++i) {
    const Rendered r = farBoardBehindWindows(camera, target, 60 + i, 150, {0.5, 1.0, 0.9});
    const ImageDetection d = det->detect(r.image, camera);
    writeDebug("sim_plain_far_stable_" + std::to_string(i), r.image, camera, d);
    found += d.features.found;
    stable += d.details.board_source.find("stable regions") != std::string::npos;
    worst_px = std::max(
        worst_px,
        worstFoundEdgePx(d, r, target, camera, "far board behind 1200 lines " + std::to_string(i)));
    cv::Mat mono;
    cv::cvtColor(r.image, mono, cv::COLOR_BGR2GRAY);
    mono_stable += det->detect(mono, camera).details.board_source == "stable regions";
  }
  EXPECT_EQ(found, kFrames);
  // Measured 8 of 8 from the stable regions until the lines past the first ones were ranked by
  // their corners (session 46): 7 since, frame 6's own lines found it first.
  EXPECT_GE(stable, kFrames / 2);
  EXPECT_LT(worst_px, 1.0);
  EXPECT_EQ(mono_stable, 0);
}

// Plain board in the simulator's textured room (grey flat panels, tiles, a person behind the
// board): the board must be found in most frames where it is largely visible, as in
// config/scenarios/plain_*.yaml (1.5-6 m, held as a diamond, tilted both ways).
TEST(ImageDetectorSim, PlainBoardInTexturedRoom) {
  const CameraModel camera = testCamera();
  const Target target = configTarget("plain_1016.yaml");
  auto det = ImageBoardDetector::create(target, ImageBoardDetectorOptions{});
  ASSERT_TRUE(det.ok()) << det.error();
  std::mt19937 rng(21);
  std::uniform_real_distribution<double> distance(1.5, 6.0), unit(-1.0, 1.0);
  constexpr int kFrames = 30;
  int visible = 0, found = 0, edges_checked = 0, edges_off = 0;
  for (int i = 0; i < kFrames; ++i) {
    const double z = distance(rng);
    const Eigen::Vector3d centre(0.3 * z * unit(rng), 0.15 * z * unit(rng), z);
    const Eigen::Isometry3d truth =
        cameraTBoard(target, centre, 45 + 10 * unit(rng), 30 * unit(rng), 25 * unit(rng));
    const Rendered r = render(camera, target, truth, rng);
    // Visible part: fraction of a 21x21 grid of board points inside the image.
    int inside = 0;
    for (int a = 0; a <= 20; ++a)
      for (int b = 0; b <= 20; ++b)
        inside += insideImage(
            camera,
            projectTruth(truth, Eigen::Vector3d(target.width * a / 20, target.height * b / 20, 0),
                         camera));
    const double fraction = inside / 441.0;
    const ImageDetection d = det->detect(r.image, camera);
    writeDebug("sim_plain_room_" + std::to_string(i), r.image, camera, d);
    if (fraction < 0.7) continue;
    ++visible;
    found += d.features.found;
    double worst_px = 0;  // found edges vs truth at the true edge midpoint
    for (int j = 0; j < kNumEdges && d.features.found; ++j) {
      const double off = edgeOffPx(d.features, truth, target, camera, j);
      ++edges_checked;
      edges_off += off > 1.0;
      worst_px = std::max(worst_px, off);
    }
    std::printf("room frame %2d: %.1f m, visible %.2f, found %d, worst edge %.2f px, rms %.2f %s\n",
                i, z, fraction, d.features.found, worst_px, d.features.reprojection_rms_px,
                d.features.reason.c_str());
  }
  std::printf(
      "textured room: found %d of %d frames with >= 70 %% of the board visible; %d of %d edges off "
      "by > 1 px\n",
      found, visible, edges_off, edges_checked);
  // Measured 27 of 30 with the line hypotheses of issue 14 (28 with session 7's segment detector;
  // 25 of 30 with regions alone). Before: 0 of 30 (only the best-scored region was tried and the
  // bright ceiling cut by the image border won); 21 of 30 trying regions best first. The opening
  // of a rejected region separates a board whose top corner touches the ceiling band. Still
  // missed: boards overlapping the ceiling over a longer stretch (board and ceiling differ by ~5
  // grey levels) and boards at 1.6 m with an edge mostly outside the image. A found board must
  // never be a wrong one.
  EXPECT_GE(found, visible * 3 / 4);
  EXPECT_EQ(edges_off, 0);
}

// A faint board in the textured room: an opaque board whose grey is 8-16 levels from the median of
// the wall and floor behind it (brighter or darker; the tiles' own greys vary more than that, so
// parts of a side have more contrast and parts none), an edge blur of 1.2-1.8 px and a camera
// noise of 0.3-0.8 levels (what the real cameras measure, where the faint-line search runs).
// Boards at 2-6 m, tilted both ways. No scene rectangle may pass for the board. Measured: none
// found (a board of the tiles' median grey is not found at 16-32 levels either, and at 32-64
// only the 4 brighter ones, by their region: docs/BENCHMARKS.md, session 26), none wrong.
TEST(ImageDetectorSim, AFaintBoardInATexturedRoomIsNeverAWrongBoard) {
  const CameraModel camera = testCamera();
  const Target target = configTarget("plain_1016.yaml");
  auto det = ImageBoardDetector::create(target, ImageBoardDetectorOptions{});
  ASSERT_TRUE(det.ok()) << det.error();
  SceneSpec scene;
  scene.target = target;
  RenderOptions options;
  options.supersampling = 2;  // test time; edges still anti-aliased
  const Eigen::Isometry3d world_T_camera = worldTCamera();
  // The board 50 m behind the camera: the room alone.
  const cv::Mat room = sim::renderCameraRadiance(
      camera, world_T_camera, scene,
      world_T_camera * makeTransform(Eigen::Matrix3d::Identity(), Eigen::Vector3d(0, 0, -50)),
      options);
  ASSERT_FALSE(room.empty());
  const auto luminance = [](const cv::Vec3f& c) {
    return 0.114 * c[0] + 0.587 * c[1] + 0.299 * c[2];
  };
  std::mt19937 rng(61);
  std::uniform_real_distribution<double> distance(2.0, 6.0), unit(-1.0, 1.0), u01(0.0, 1.0);
  constexpr int kFrames = 16;
  int found = 0, wrong = 0;
  for (int i = 0; i < kFrames; ++i) {
    const double z = distance(rng);
    const Eigen::Vector3d centre(0.25 * z * unit(rng), 0.1 * z * unit(rng), z);
    const Eigen::Isometry3d truth =
        cameraTBoard(target, centre, 45 + 10 * unit(rng), 30 * unit(rng), 25 * unit(rng));
    // The board's radiance is its grey times its shading: one render gives the grey that puts
    // its median luminance the drawn contrast from the room's behind it.
    cv::Mat board =
        sim::renderCameraRadiance(camera, world_T_camera, scene, world_T_camera * truth, options);
    ASSERT_FALSE(board.empty());
    std::vector<double> on_board, behind;
    for (int v = 0; v < board.rows; v += 2)
      for (int u = 0; u < board.cols; u += 2) {
        const double b = luminance(board.at<cv::Vec3f>(v, u)),
                     r = luminance(room.at<cv::Vec3f>(v, u));
        if (std::abs(b - r) < 1e-4) continue;
        on_board.push_back(b);
        behind.push_back(r);
      }
    ASSERT_FALSE(on_board.empty());
    const double contrast = (8.0 + 8.0 * u01(rng)) * (i % 2 ? 1 : -1);  // grey levels
    SceneSpec faint = scene;
    faint.board_grey =
        scene.board_grey * (medianOf(behind) + contrast / 255.0) / medianOf(on_board);
    board =
        sim::renderCameraRadiance(camera, world_T_camera, faint, world_T_camera * truth, options);
    options.noise_sigma = 0.3 + 0.5 * u01(rng);
    options.blur_sigma_px = 1.2 + 0.6 * u01(rng);
    const cv::Mat image = sim::finishCameraImage(board, camera, options, rng);
    const ImageDetection d = det->detect(image, camera);
    writeDebug("sim_plain_faint_" + std::to_string(i), image, camera, d);
    double worst = 0;
    for (int j = 0; j < kNumEdges && d.features.found; ++j)
      worst = std::max(worst, edgeOffPx(d.features, truth, target, camera, j));
    found += d.features.found;
    wrong += d.features.found && worst > 1.0;
    std::printf(
        "faint frame %2d: %.1f m, contrast %+.0f, noise %.2f, blur %.1f px: %s %s %.2f px %s\n", i,
        z, contrast, options.noise_sigma, options.blur_sigma_px,
        d.features.found ? "found" : "miss", d.details.board_source.c_str(), worst,
        d.features.reason.c_str());
  }
  std::printf("faint board in the textured room: found %d of %d, %d wrong\n", found, kFrames,
              wrong);
  EXPECT_EQ(wrong, 0);
}

// A board of the room's grey but another colour (blue foam, brown cardboard), in single frames:
// the grey search misses it where it meets tiles of its grey; the chroma regions find it. The
// same frames with their colour removed show what the colour adds; a found board is never a
// wrong one (the room's coloured tiles are rectangles too).
TEST(ImageDetectorSim, PlainBoardOfTheRoomsGreyFoundByItsColour) {
  const CameraModel camera = testCamera();
  const Target target = configTarget("plain_1016.yaml");
  auto det = ImageBoardDetector::create(target, ImageBoardDetectorOptions{});
  ASSERT_TRUE(det.ok()) << det.error();
  std::mt19937 rng(33);
  std::uniform_real_distribution<double> distance(1.5, 6.0), unit(-1.0, 1.0);
  constexpr int kFrames = 24;
  int found_colour = 0, found_grey = 0, wrong = 0;
  for (int i = 0; i < kFrames; ++i) {
    const double z = distance(rng);
    const Eigen::Vector3d centre(0.25 * z * unit(rng), 0.1 * z * unit(rng), z);
    const Eigen::Isometry3d truth =
        cameraTBoard(target, centre, 45 + 10 * unit(rng), 30 * unit(rng), 25 * unit(rng));
    // Blue and brown at a mid grey (luminance ~0.4, the walls' range).
    const Eigen::Vector3d tint = i % 2 ? Eigen::Vector3d(1.9, 0.9, 0.45)  // b, g, r
                                       : Eigen::Vector3d(0.45, 0.9, 1.6);
    const Rendered r = render(camera, target, truth, rng, true, 0.45, tint);
    cv::Mat grey, no_colour;
    cv::cvtColor(r.image, grey, cv::COLOR_BGR2GRAY);
    cv::cvtColor(grey, no_colour, cv::COLOR_GRAY2BGR);
    for (const bool colour : {true, false}) {
      const ImageDetection d = det->detect(colour ? r.image : no_colour, camera);
      if (colour) writeDebug("sim_plain_tinted_" + std::to_string(i), r.image, camera, d);
      if (!d.features.found) continue;
      (colour ? found_colour : found_grey) += 1;
      double worst = 0;
      for (int j = 0; j < kNumEdges; ++j)
        worst = std::max(worst, edgeOffPx(d.features, truth, target, camera, j));
      wrong += worst > 1.0;
      std::printf("tinted frame %2d %s: %.1f m, worst edge %.2f px\n", i,
                  colour ? "colour" : "grey  ", z, worst);
    }
  }
  std::printf("tinted board: found %d of %d in colour, %d without it; %d wrong\n", found_colour,
              kFrames, found_grey, wrong);
  // Measured 24 of 24 in colour since the colour parts are also opened at a holder's width (23
  // before), 1 without (the search is deterministic for a seed; one frame of slack for another
  // platform's floating point).
  EXPECT_GE(found_colour, 23);
  EXPECT_EQ(wrong, 0);
}

// The single frame's colour search on colour images no camera should give (tiny, thin, one
// colour, colour noise, saturated blobs touching every border): a reason, never a crash (run
// under the sanitizers by scripts/test.sh --sanitize).
TEST(ImageDetectorSim, HostileColourImagesGiveReasons) {
  const Target plain = configTarget("plain_1016.yaml");
  auto det = ImageBoardDetector::create(plain, ImageBoardDetectorOptions{});
  ASSERT_TRUE(det.ok());
  std::mt19937 rng(5);
  const cv::Size sizes[] = {{1, 1},   {2, 3},   {7, 1},   {1, 9},
                            {40, 30}, {640, 4}, {3, 480}, {800, 600}};
  for (const cv::Size& size : sizes) {
    CameraIntrinsics in;
    in.width = size.width;
    in.height = size.height;
    in.fx = in.fy = std::max(size.width, size.height);
    in.cx = 0.5 * size.width;
    in.cy = 0.5 * size.height;
    auto camera = CameraModel::create(in);
    ASSERT_TRUE(camera.ok()) << camera.error();
    std::vector<cv::Mat> images;
    images.emplace_back(size, CV_8UC3, cv::Scalar(200, 40, 10));
    cv::Mat noise(size, CV_8UC3);
    cv::randu(noise, cv::Scalar::all(0), cv::Scalar::all(256));
    images.push_back(noise);
    cv::Mat blobs(size, CV_8UC3, cv::Scalar(128, 128, 128));
    for (int k = 0; k < 12; ++k) {
      const cv::Point a(static_cast<int>(rng() % (size.width + 1)) - size.width / 4,
                        static_cast<int>(rng() % (size.height + 1)) - size.height / 4);
      const cv::Point b = a + cv::Point(static_cast<int>(rng() % (size.width + 1)),
                                        static_cast<int>(rng() % (size.height + 1)));
      cv::rectangle(blobs, a, b, cv::Scalar(rng() % 256, rng() % 256, rng() % 256), cv::FILLED);
    }
    images.push_back(blobs);
    for (const cv::Mat& image : images) {
      const ImageDetection d = det->detect(image, *camera);
      if (!d.features.found) {
        EXPECT_FALSE(d.features.reason.empty()) << size;
      }
    }
  }
}

// Images a few pixels high or wide, for every board type: a reason, never a crash. libapriltag
// read out of bounds on a 22 x 1 image (test_fuzz_detectors, round 5): its thresholding needs
// more than 2 decimated rows, and 1-2 px wide images crash it at fractional decimations.
TEST(ImageDetectorSim, ImagesAFewPixelsAcrossGiveReasonsForEveryBoard) {
  const cv::Size sizes[] = {{1, 1}, {22, 1}, {300, 4}, {4, 300}, {2, 40}, {9, 9}, {40, 7}};
  for (const char* name : {"plain_1016.yaml", "checkerboard_7x5.yaml", "apriltag_grid_4x4.yaml"}) {
    for (const double decimate : {1.0, 1.5, 2.0, 4.0, 1e300}) {  // the last: no int overflow
      ImageBoardDetectorOptions options;
      options.tag_decimate = decimate;
      auto det = ImageBoardDetector::create(configTarget(name), options);
      ASSERT_TRUE(det.ok()) << det.error();
      for (const cv::Size& size : sizes) {
        CameraIntrinsics in;
        in.width = size.width;
        in.height = size.height;
        in.fx = in.fy = 100;
        in.cx = 0.5 * size.width;
        in.cy = 0.5 * size.height;
        auto camera = CameraModel::create(in);
        ASSERT_TRUE(camera.ok()) << camera.error();
        cv::Mat noise(size, CV_8UC1);
        cv::randu(noise, 0, 256);
        const ImageDetection d = det->detect(noise, *camera);
        EXPECT_FALSE(d.features.found) << name << " " << size;
        EXPECT_FALSE(d.features.reason.empty()) << name << " " << size;
      }
    }
  }
}

}  // namespace
}  // namespace board_calib
