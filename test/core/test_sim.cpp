// Simulator tests: rendered edges and patterns land where the ground truth projects, LiDAR
// returns lie on the true board plane, ring organisation matches the preset.
#include <board_calib/core/sim/simulator.h>
#include <board_calib/core/transform.h>
#include "sim_test_helpers.h"

#include <gtest/gtest.h>
#include <Eigen/Eigenvalues>

#include <apriltag/apriltag.h>
#include <apriltag/tag36h11.h>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>

namespace board_calib {
namespace sim {
namespace {

double bilinear(const cv::Mat& grey, double u, double v) {
  const int u0 = static_cast<int>(std::floor(u)), v0 = static_cast<int>(std::floor(v));
  if (u0 < 0 || v0 < 0 || u0 + 1 >= grey.cols || v0 + 1 >= grey.rows) return std::nan("");
  const double a = u - u0, b = v - v0;
  auto at = [&](int x, int y) { return static_cast<double>(grey.at<float>(y, x)); };
  return (at(u0, v0) * (1 - a) + at(u0 + 1, v0) * a) * (1 - b) +
         (at(u0, v0 + 1) * (1 - a) + at(u0 + 1, v0 + 1) * a) * b;
}

// Measures each board edge in the image independently of the truth's position estimate: along
// the projected edge, the 50 % crossing of the intensity profile across it (local levels from
// 3 px either side), undistorted, then a total-least-squares line per edge; corners are the
// intersections. Returns the four measured corners in undistorted pixels.
std::array<Eigen::Vector2d, 4> measureBoardCorners(
    const cv::Mat& image, const CameraModel& camera,
    const std::array<Eigen::Vector3d, 4>& corners_camera) {
  cv::Mat grey;
  cv::cvtColor(image, grey, cv::COLOR_BGR2GRAY);
  grey.convertTo(grey, CV_32F);
  std::array<Eigen::Vector3d, 4> lines;  // a u + b v + c = 0 in undistorted pixels
  for (int e = 0; e < 4; ++e) {
    const Eigen::Vector3d& A = corners_camera[e];
    const Eigen::Vector3d& B = corners_camera[(e + 1) % 4];
    std::vector<Eigen::Vector2d> points;
    constexpr int kSamples = 200;
    for (int s = 0; s < kSamples; ++s) {
      const double t = 0.1 + 0.8 * s / (kSamples - 1);
      const Eigen::Vector3d P = A + t * (B - A);
      const Eigen::Vector3d Q = A + (t + 1e-3) * (B - A);
      Eigen::Vector2d p, q;
      camera.project(P, &p);
      camera.project(Q, &q);
      const Eigen::Vector2d along = (q - p).normalized();
      const Eigen::Vector2d normal(-along.y(), along.x());
      const double inside_probe = bilinear(grey, p.x() + 3 * normal.x(), p.y() + 3 * normal.y());
      const double outside_probe = bilinear(grey, p.x() - 3 * normal.x(), p.y() - 3 * normal.y());
      if (std::isnan(inside_probe) || std::isnan(outside_probe)) continue;
      const double mid = 0.5 * (inside_probe + outside_probe);
      double prev = bilinear(grey, p.x() - 2 * normal.x(), p.y() - 2 * normal.y());
      constexpr double kStep = 0.02;
      for (double x = -2 + kStep; x <= 2; x += kStep) {
        const double cur = bilinear(grey, p.x() + x * normal.x(), p.y() + x * normal.y());
        if ((prev - mid) * (cur - mid) <= 0 && prev != cur) {
          const double x0 = x - kStep + kStep * (mid - prev) / (cur - prev);
          points.push_back(camera.undistortPixel(p + x0 * normal));
          break;
        }
        prev = cur;
      }
    }
    EXPECT_GT(points.size(), kSamples / 2u) << "edge " << e;
    Eigen::Vector2d mean = Eigen::Vector2d::Zero();
    for (const auto& p : points) mean += p;
    mean /= points.size();
    Eigen::Matrix2d cov = Eigen::Matrix2d::Zero();
    for (const auto& p : points) cov += (p - mean) * (p - mean).transpose();
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig(cov);
    const Eigen::Vector2d n = eig.eigenvectors().col(0);
    lines[e] = Eigen::Vector3d(n.x(), n.y(), -n.dot(mean));
  }
  std::array<Eigen::Vector2d, 4> out;
  for (int e = 0; e < 4; ++e) {
    const Eigen::Vector3d x = lines[(e + 3) % 4].cross(lines[e]);  // corner e joins edges e-1 and e
    out[e] = x.head<2>() / x.z();
  }
  return out;
}

SceneSpec boardOnly(const Target& target) {
  SceneSpec scene;
  scene.target = target;
  scene.room = false;  // dark background: the edge profile is a clean step
  scene.occluder = false;
  return scene;
}

struct CornerCase {
  DistortionModel model;
  std::vector<double> coeffs;
};

TEST(SimCamera, BoardCornersLandOnProjectedTruth) {
  const Target target = loadConfigTarget("plain_1016.yaml");
  const SceneSpec scene = boardOnly(target);
  const std::vector<CornerCase> cases = {
      {DistortionModel::kPlumbBob, {-0.28, 0.09, 0.0008, -0.0005, -0.01}},
      {DistortionModel::kEquidistant, {-0.02, 0.004, -0.001, 0.0002}},
  };
  std::mt19937 rng(42);
  double worst = 0;
  for (const auto& c : cases) {
    const CameraModel camera = makeCamera(1280, 720, 900, c.model, c.coeffs);
    const Eigen::Isometry3d world_T_camera = cameraLookingAlongX(Eigen::Vector3d::Zero());
    for (double roll : {35.0, 52.0}) {
      const Eigen::Isometry3d world_T_board = boardPose(target, {3.0, 0.3, -0.1}, roll, 15, -10);
      RenderOptions options;  // default noise and vignetting on
      const cv::Mat image =
          renderCameraImage(camera, world_T_camera, scene, world_T_board, options, rng);
      ASSERT_EQ(image.type(), CV_8UC3);
      const Eigen::Isometry3d camera_T_board = world_T_camera.inverse() * world_T_board;
      std::array<Eigen::Vector3d, 4> corners_camera;
      const auto outer = target.outerCorners();
      for (int i = 0; i < 4; ++i) corners_camera[i] = camera_T_board * outer[i];
      const auto measured = measureBoardCorners(image, camera, corners_camera);
      for (int i = 0; i < 4; ++i) {
        Eigen::Vector2d truth;
        ASSERT_TRUE(camera.projectUndistorted(corners_camera[i], &truth));
        // 0.2 px: the bound for sub-pixel true edges (16 samples per edge pixel plus
        // 2-level noise averaged over ~160 edge points leaves ~0.05 px).
        worst = std::max(worst, (measured[i] - truth).norm());
        EXPECT_LT((measured[i] - truth).norm(), 0.2)
            << distortionModelName(c.model) << " roll " << roll << " corner " << i << " measured "
            << measured[i].transpose() << " truth " << truth.transpose();
      }
    }
  }
  RecordProperty("worst_board_corner_error_px", std::to_string(worst));
}

// A mono camera (render.mono) gives one 8-bit channel: the colour render's luminance, the board
// where it was, and its noise on that channel.
TEST(SimCamera, MonoCameraGivesTheLuminanceInOneChannel) {
  const Target target = loadConfigTarget("plain_1016.yaml");
  const SceneSpec scene = boardOnly(target);
  const CameraModel camera = makeCamera(640, 480, 500, DistortionModel::kNone, {});
  const Eigen::Isometry3d world_T_camera = cameraLookingAlongX(Eigen::Vector3d::Zero());
  const Eigen::Isometry3d world_T_board = boardPose(target, {3.0, 0.0, 0.0}, 45, 10, 0);
  RenderOptions options;
  options.noise_sigma = 0.0;
  std::mt19937 rng(3);
  const cv::Mat colour =
      renderCameraImage(camera, world_T_camera, scene, world_T_board, options, rng);
  options.mono = true;
  const cv::Mat mono =
      renderCameraImage(camera, world_T_camera, scene, world_T_board, options, rng);
  ASSERT_EQ(colour.type(), CV_8UC3);
  ASSERT_EQ(mono.type(), CV_8UC1);
  cv::Mat grey, diff;
  cv::cvtColor(colour, grey, cv::COLOR_BGR2GRAY);
  cv::absdiff(grey, mono, diff);
  double worst = 0;
  cv::minMaxLoc(diff, nullptr, &worst);
  EXPECT_LE(worst, 1.0);  // one rounding step apart
  // Noise on the one channel: sigma 4 measured on the difference of two renders (sigma * sqrt 2),
  // where 8 bits do not clip it.
  options.noise_sigma = 4.0;
  cv::Mat a, b, unclipped;
  cv::inRange(mono, 30, 225, unclipped);
  ASSERT_GT(cv::countNonZero(unclipped), 1000);
  renderCameraImage(camera, world_T_camera, scene, world_T_board, options, rng)
      .convertTo(a, CV_32F);
  renderCameraImage(camera, world_T_camera, scene, world_T_board, options, rng)
      .convertTo(b, CV_32F);
  cv::Scalar mean, stddev;
  cv::meanStdDev(a - b, mean, stddev, unclipped);
  EXPECT_NEAR(stddev[0] / std::sqrt(2.0), 4.0, 0.3);
}

TEST(SimCamera, OpenCvFindsCheckerboardAtTruth) {
  const Target target = loadConfigTarget("checkerboard_7x5.yaml");
  SceneSpec scene;
  scene.target = target;
  const CameraModel camera =
      makeCamera(1280, 720, 1000, DistortionModel::kPlumbBob, {-0.2, 0.05, 0, 0, 0});
  const Eigen::Isometry3d world_T_camera = cameraLookingAlongX(Eigen::Vector3d::Zero());
  const Eigen::Isometry3d world_T_board = boardPose(target, {2.5, -0.2, 0.1}, 20, -20, 10);
  std::mt19937 rng(7);
  const cv::Mat image =
      renderCameraImage(camera, world_T_camera, scene, world_T_board, RenderOptions(), rng);
  cv::Mat grey;
  cv::cvtColor(image, grey, cv::COLOR_BGR2GRAY);
  const cv::Size pattern(target.checkerboard.cols, target.checkerboard.rows);
  std::vector<cv::Point2f> found;
  ASSERT_TRUE(cv::findChessboardCorners(
      grey, pattern, found, cv::CALIB_CB_ADAPTIVE_THRESH | cv::CALIB_CB_NORMALIZE_IMAGE));
  cv::cornerSubPix(grey, found, cv::Size(5, 5), cv::Size(-1, -1),
                   cv::TermCriteria(cv::TermCriteria::EPS + cv::TermCriteria::COUNT, 50, 1e-3));
  const Points3 truth3 = target.checkerboardCorners();
  ASSERT_EQ(found.size(), truth3.size());
  // OpenCV may report the grid from either end; compare with the better of both orders.
  double err_fwd = 0, err_rev = 0, max_fwd = 0, max_rev = 0;
  for (size_t i = 0; i < truth3.size(); ++i) {
    Eigen::Vector2d truth;
    ASSERT_TRUE(camera.project(world_T_camera.inverse() * world_T_board * truth3[i], &truth));
    const auto& f = found[i];
    const auto& r = found[found.size() - 1 - i];
    const double ef = (Eigen::Vector2d(f.x, f.y) - truth).norm(),
                 er = (Eigen::Vector2d(r.x, r.y) - truth).norm();
    err_fwd += ef;
    err_rev += er;
    max_fwd = std::max(max_fwd, ef);
    max_rev = std::max(max_rev, er);
  }
  const double mean = std::min(err_fwd, err_rev) / truth3.size();
  const double max_err = err_fwd < err_rev ? max_fwd : max_rev;
  // cornerSubPix itself is good to ~0.05 px on clean corners; 0.2 px bounds every corner with
  // the default noise, lens distortion (the saddle is slightly curved) and a tilted board.
  EXPECT_LT(mean, 0.1);
  EXPECT_LT(max_err, 0.2);
  RecordProperty("mean_checker_corner_error_px", std::to_string(mean));
  RecordProperty("worst_checker_corner_error_px", std::to_string(max_err));
}

TEST(SimCamera, AprilTagFindsEveryTagAtTruth) {
  const Target target = loadConfigTarget("apriltag_grid_4x4.yaml");
  SceneSpec scene;
  scene.target = target;
  const CameraModel camera =
      makeCamera(1600, 1200, 1300, DistortionModel::kPlumbBob, {-0.15, 0.03, 0, 0, 0});
  const Eigen::Isometry3d world_T_camera = cameraLookingAlongX(Eigen::Vector3d::Zero());
  const Eigen::Isometry3d world_T_board = boardPose(target, {2.6, 0.2, 0.0}, 38, 15, -8);
  std::mt19937 rng(11);
  const cv::Mat image =
      renderCameraImage(camera, world_T_camera, scene, world_T_board, RenderOptions(), rng);
  cv::Mat grey;
  cv::cvtColor(image, grey, cv::COLOR_BGR2GRAY);

  apriltag_family_t* family = tag36h11_create();
  apriltag_detector_t* detector = apriltag_detector_create();
  apriltag_detector_add_family(detector, family);
  detector->quad_decimate = 1.0;
  detector->nthreads = 1;
  image_u8_t frame = {grey.cols, grey.rows, static_cast<int32_t>(grey.step), grey.data};
  zarray_t* detections = apriltag_detector_detect(detector, &frame);
  std::map<int, std::array<Eigen::Vector2d, 4>> found;
  for (int i = 0; i < zarray_size(detections); ++i) {
    apriltag_detection_t* det = nullptr;
    zarray_get(detections, i, &det);
    std::array<Eigen::Vector2d, 4> corners;
    // libapriltag's pixel centres sit at integer + 0.5 (libapriltag's convention): shift to
    // OpenCV's.
    for (int k = 0; k < 4; ++k)
      corners[k] = Eigen::Vector2d(det->p[k][0] - 0.5, det->p[k][1] - 0.5);
    found[det->id] = corners;
  }
  apriltag_detections_destroy(detections);
  apriltag_detector_destroy(detector);
  tag36h11_destroy(family);

  const Eigen::Isometry3d camera_T_board = world_T_camera.inverse() * world_T_board;
  const auto tags = target.aprilTagCorners();
  ASSERT_EQ(found.size(), tags.size()) << "every tag id, no extra ids";
  double worst = 0;
  for (const auto& tag : tags) {
    ASSERT_TRUE(found.count(tag.id)) << "tag " << tag.id;
    for (int k = 0; k < 4; ++k) {
      Eigen::Vector2d truth;
      ASSERT_TRUE(camera.project(camera_T_board * tag.corners[k], &truth));
      const double err = (found[tag.id][k] - truth).norm();
      worst = std::max(worst, err);
      // 0.5 px: the bound; libapriltag's quad refinement is good to a few tenths of a
      // pixel on sharp, anti-aliased edges with 2-level noise.
      EXPECT_LT(err, 0.5) << "tag " << tag.id << " corner " << k;
    }
  }
  RecordProperty("worst_tag_corner_error_px", std::to_string(worst));
}

// ---------------------------------------------------------------------------------------------
// LiDAR
// ---------------------------------------------------------------------------------------------
TEST(SimLidar, BoardReturnsLieOnTruePlaneWithinNoise) {
  const Target target = loadConfigTarget("plain_1016.yaml");
  SceneSpec scene;
  scene.target = target;
  std::mt19937 rng(3);
  for (const char* preset : {"VLP-16", "VLP-32C", "OS1-64"}) {
    auto spec = lidarPreset(preset);
    ASSERT_TRUE(spec.ok()) << spec.error();
    const Eigen::Isometry3d world_T_lidar =
        makeTransform(Eigen::Matrix3d::Identity(), Eigen::Vector3d(0, 0, 0.1));
    const Eigen::Isometry3d world_T_board = boardPose(target, {3.5, 0.4, 0.2}, 45, 20);
    std::vector<ReturnOrigin> origins;
    const LidarCloud cloud =
        simulateLidarScan(*spec, world_T_lidar, scene, world_T_board, rng, &origins);
    ASSERT_EQ(origins.size(), cloud.points.size());
    const Plane plane_lidar = [&] {
      Plane p;
      p.normal = Eigen::Vector3d::UnitZ();
      p.offset = 0;
      return p.transformed(world_T_lidar.inverse() * world_T_board);
    }();
    EXPECT_GT(plane_lidar.offset, 0) << "plane normal points away from the sensor";
    int board = 0, mixed = 0;
    double sum2 = 0, worst = 0;
    for (size_t i = 0; i < cloud.points.size(); ++i) {
      if (origins[i] == ReturnOrigin::kMixed) ++mixed;
      if (origins[i] != ReturnOrigin::kBoard) continue;
      const auto& p = cloud.points[i];
      const double d = plane_lidar.signedDistance(Eigen::Vector3d(p.x, p.y, p.z));
      sum2 += d * d;
      worst = std::max(worst, std::abs(d));
      ++board;
      EXPECT_GT(p.intensity, 0.5 * (scene.board_intensity + scene.background_intensity));
    }
    ASSERT_GT(board, 30) << preset;
    const double rms = std::sqrt(sum2 / board);
    // Range noise is along the ray; its component along the normal is at most sigma. The rms
    // must not exceed sigma by more than sampling slack (20 %), and no point beyond 5 sigma.
    EXPECT_LT(rms, 1.2 * spec->range_noise_m) << preset;
    EXPECT_GT(rms, 0.3 * spec->range_noise_m) << preset << ": noise missing";
    EXPECT_LT(worst, 5 * spec->range_noise_m) << preset;
    EXPECT_GT(mixed, 0) << preset << ": the board's edges produce mixed returns";
  }
}

TEST(SimLidar, PersonNeverHidesTheBoard) {
  // The person stands behind the board: for boards leaning forward or back, the LiDAR sees
  // exactly the same board returns with and without the occluder.
  const Target target = loadConfigTarget("plain_1016.yaml");
  SceneSpec with, without;
  with.target = without.target = target;
  without.occluder = false;
  auto spec = lidarPreset("VLP-32C");
  ASSERT_TRUE(spec.ok());
  spec->range_noise_m = 0;
  for (double pitch : {-25.0, 0.0, 25.0}) {
    const Eigen::Isometry3d world_T_board = boardPose(target, {2.0, 0.0, -0.3}, 45, 10, pitch);
    std::mt19937 rng_a(1), rng_b(1);
    std::vector<ReturnOrigin> a, b;
    simulateLidarScan(*spec, Eigen::Isometry3d::Identity(), with, world_T_board, rng_a, &a);
    simulateLidarScan(*spec, Eigen::Isometry3d::Identity(), without, world_T_board, rng_b, &b);
    const auto board_count = [](const std::vector<ReturnOrigin>& v) {
      return std::count(v.begin(), v.end(), ReturnOrigin::kBoard);
    };
    EXPECT_GT(board_count(b), 100);
    EXPECT_EQ(board_count(a), board_count(b)) << "pitch " << pitch;
  }
}

TEST(SimLidar, OrganizationAndRingsMatchPreset) {
  const Target target = loadConfigTarget("plain_1016.yaml");
  SceneSpec scene;
  scene.target = target;
  std::mt19937 rng(5);
  for (const char* preset : {"VLP-16", "VLP-32C", "OS1-64"}) {
    auto spec = lidarPreset(preset);
    ASSERT_TRUE(spec.ok());
    const LidarCloud cloud = simulateLidarScan(*spec, Eigen::Isometry3d::Identity(), scene,
                                               boardPose(target, {3, 0, 0}, 40), rng);
    ASSERT_EQ(cloud.height, static_cast<int>(spec->elevations_deg.size())) << preset;
    ASSERT_EQ(cloud.width, spec->columns()) << preset;
    EXPECT_TRUE(cloud.has_ring);
    EXPECT_TRUE(cloud.organized());
    ASSERT_EQ(cloud.points.size(), static_cast<size_t>(cloud.width * cloud.height));
    int finite = 0;
    for (int r = 0; r < cloud.height; ++r) {
      for (int c = 0; c < cloud.width; ++c) {
        const LidarPoint& p = cloud.points[static_cast<size_t>(r) * cloud.width + c];
        EXPECT_EQ(p.ring, r);
        if (!std::isfinite(p.x)) continue;
        ++finite;
        // The elevation of each return is its ring's elevation (the room is closed: all return).
        const double el = std::atan2(p.z, std::hypot(p.x, p.y)) / kRadPerDeg;
        EXPECT_NEAR(el, spec->elevations_deg[static_cast<size_t>(r)], 1e-3)
            << preset << " ring " << r;
        const double az = std::atan2(p.y, p.x);
        EXPECT_NEAR(std::remainder(az - spec->azimuthRad(r, c), 2 * M_PI), 0.0, 1e-5);
      }
    }
    // Inside a closed room nearly every beam returns (minus min-range cuts).
    EXPECT_GT(finite, 0.95 * cloud.points.size()) << preset;
  }
  // OS1-64 ring 0 is the top beam; Velodyne ring 0 the bottom beam.
  EXPECT_GT(lidarPreset("OS1-64")->elevations_deg.front(), 0);
  EXPECT_LT(lidarPreset("VLP-16")->elevations_deg.front(), 0);
  EXPECT_FALSE(lidarPreset("HDL-1").ok());
}

TEST(SimLidar, UnorganizedWithoutRingAndDropouts) {
  const Target target = loadConfigTarget("plain_1016.yaml");
  SceneSpec scene;
  scene.target = target;
  auto spec = lidarPreset("VLP-32C");
  ASSERT_TRUE(spec.ok());
  spec->organized = false;
  spec->with_ring = false;
  std::mt19937 rng(9);
  const LidarCloud full = simulateLidarScan(*spec, Eigen::Isometry3d::Identity(), scene,
                                            boardPose(target, {3, 0, 0}, 40), rng);
  EXPECT_FALSE(full.organized());
  EXPECT_FALSE(full.has_ring);
  EXPECT_EQ(full.height, 1);
  EXPECT_EQ(full.width, static_cast<int>(full.points.size()));
  for (const auto& p : full.points) {
    ASSERT_TRUE(std::isfinite(p.x));
    ASSERT_EQ(p.ring, -1);
  }
  spec->dropout_probability = 0.3;
  const LidarCloud dropped = simulateLidarScan(*spec, Eigen::Isometry3d::Identity(), scene,
                                               boardPose(target, {3, 0, 0}, 40), rng);
  const double kept = static_cast<double>(dropped.points.size()) / full.points.size();
  // ~36k returns: the binomial spread of the kept fraction is ~0.003.
  EXPECT_NEAR(kept, 0.7, 0.02);
}

}  // namespace
}  // namespace sim
}  // namespace board_calib
