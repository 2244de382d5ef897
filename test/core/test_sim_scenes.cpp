// Simulator scenes: board-sized clutter seen by both sensors, the outdoor street, the default
// scene unchanged against its recorded sums, option validation.
#include <board_calib/core/sim/simulator.h>
#include <board_calib/core/transform.h>
#include "sim_test_helpers.h"

#include <gtest/gtest.h>

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>

namespace board_calib {
namespace sim {
namespace {

// Recorded from the simulator before scene clutter / outdoor options existed (commit fa5623f).
constexpr double kGoldenCloudSum = 121780.279637;
constexpr double kGoldenImageSum = 415207394.0;

// Board-sized clutter: a poster a little off a wall and a free-standing panel. The LiDAR sees
// both as planes at their true places with their intensity; the camera sees them with their
// albedo against the wall around them.
TEST(SimClutter, PanelsAreSeenByLidarAndCamera) {
  const Target target = loadConfigTarget("plain_1016.yaml");
  SceneSpec scene;
  scene.target = target;
  scene.occluder = false;
  Panel poster;  // on the wall ahead (x = +10), 0.15 m off it, facing the rig
  poster.world_T_panel = makeTransform(cameraLookingAlongX(Eigen::Vector3d::Zero()).linear(),
                                       Eigen::Vector3d(9.85, 2.0, 0.5));
  poster.width_m = 1.0;
  poster.height_m = 1.3;
  poster.grey = 0.1;
  poster.intensity = 150;
  Panel stand = poster;  // free-standing behind the rig, turned and rolled like a held board
  stand.world_T_panel =
      makeTransform(Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitZ()).toRotationMatrix() *
                        cameraLookingAlongX(Eigen::Vector3d::Zero()).linear() *
                        Eigen::AngleAxisd(M_PI / 4, Eigen::Vector3d::UnitZ()).toRotationMatrix(),
                    Eigen::Vector3d(-4.0, 0.0, 0.3));
  stand.grey = 0.9;
  stand.intensity = 220;
  scene.panels = {poster, stand};
  ASSERT_TRUE(scene.validate().empty()) << scene.validate();
  auto spec = lidarPreset("VLP-32C");
  ASSERT_TRUE(spec.ok());
  spec->range_noise_m = 0;
  spec->intensity_noise = 0;
  std::mt19937 rng(2);
  // The board far away, out of the room: only room and panels remain.
  const Eigen::Isometry3d board_away = boardPose(target, {40, 0, 0}, 45);
  const LidarCloud cloud =
      simulateLidarScan(*spec, Eigen::Isometry3d::Identity(), scene, board_away, rng);
  for (size_t k = 0; k < scene.panels.size(); ++k) {
    const Panel& panel = scene.panels[k];
    const Eigen::Isometry3d panel_T_world = panel.world_T_panel.inverse();
    int on = 0;
    for (const auto& p : cloud.points) {
      if (!std::isfinite(p.x)) continue;
      const Eigen::Vector3d q = panel_T_world * Eigen::Vector3d(p.x, p.y, p.z);
      // Inside the panel (0.05 m from its rim, away from mixed returns) and on its plane.
      if (std::abs(q.x()) < 0.5 * panel.width_m - 0.05 &&
          std::abs(q.y()) < 0.5 * panel.height_m - 0.05 && std::abs(q.z()) < 0.2) {
        ++on;
        EXPECT_LT(std::abs(q.z()), 1e-4) << "panel " << k;  // noise-free: exactly on the plane
        EXPECT_NEAR(p.intensity, panel.intensity, 1e-3) << "panel " << k;
      }
    }
    EXPECT_GT(on, 30) << "panel " << k;
  }
  // Camera at the origin looking at the poster: its centre is dark, the wall beside it is not.
  const CameraModel camera = makeCamera(640, 480, 500, DistortionModel::kNone, {});
  RenderOptions render;
  render.noise_sigma = 0;
  render.vignetting = 0;
  const cv::Mat image = renderCameraImage(camera, cameraLookingAlongX(Eigen::Vector3d::Zero()),
                                          scene, board_away, render, rng);
  ASSERT_FALSE(image.empty());
  auto greyAt = [&](const Eigen::Vector3d& world) {
    Eigen::Vector2d px(0, 0);
    EXPECT_TRUE(
        camera.project(cameraLookingAlongX(Eigen::Vector3d::Zero()).inverse() * world, &px));
    const cv::Vec3b c = image.at<cv::Vec3b>(static_cast<int>(std::lround(px.y())),
                                            static_cast<int>(std::lround(px.x())));
    return (c[0] + c[1] + c[2]) / 3.0;
  };
  const double inside = greyAt(Eigen::Vector3d(9.85, 2.0, 0.5));
  const double wall = greyAt(Eigen::Vector3d(10.0, 2.0 - 1.3, 0.5));
  EXPECT_LT(inside, 0.15 * 255);  // albedo 0.1 times the shading (<= 1)
  EXPECT_GT(wall - inside, 40) << "the poster must contrast with the wall";
}

// Outdoors: ground returns at the ground's height, facades at their distance, nothing above
// (no ceiling), the sky bright in the image; the board keeps its grey, tint and marks.
TEST(SimOutdoor, GroundFacadesSkyAndBoardLook) {
  const Target target = loadConfigTarget("plain_1016.yaml");
  SceneSpec scene;
  scene.target = target;
  scene.occluder = false;
  scene.outdoor = true;
  scene.floor_z_m = -1.7;
  scene.street_half_width_m = 10;
  scene.facade_distance_m = 45;
  scene.ground_grey = 0.6;
  scene.board_grey = 0.6;
  scene.board_tint = Eigen::Vector3d(0.6, 0.82, 1.0);  // cardboard (b, g, r)
  scene.board_marks = {{Eigen::Vector2d(0.4, 0.3), Eigen::Vector2d(0.6, 0.7)}};
  ASSERT_TRUE(scene.validate().empty()) << scene.validate();
  auto spec = lidarPreset("VLP-16");
  ASSERT_TRUE(spec.ok());
  spec->range_noise_m = 0;
  std::mt19937 rng(4);
  const Eigen::Isometry3d board = boardPose(target, {8, 0, 0}, 0);  // upright, facing the LiDAR
  std::vector<ReturnOrigin> origins;
  const LidarCloud cloud =
      simulateLidarScan(*spec, Eigen::Isometry3d::Identity(), scene, board, rng, &origins);
  int ground = 0, facade = 0, above = 0, mark = 0, board_plain = 0;
  for (size_t i = 0; i < cloud.points.size(); ++i) {
    const auto& p = cloud.points[i];
    if (!std::isfinite(p.x)) continue;
    const Eigen::Vector3d q(p.x, p.y, p.z);
    if (std::abs(q.z() - scene.floor_z_m) < 1e-3) ++ground;
    if (std::abs(std::abs(q.y()) - scene.street_half_width_m) < 1e-3 ||
        std::abs(std::abs(q.x()) - scene.facade_distance_m) < 1e-3)
      ++facade;
    if (q.z() > 16.0 + scene.floor_z_m) ++above;
    if (origins[i] == ReturnOrigin::kBoard) {
      const Eigen::Vector3d b = board.inverse() * q;
      if (b.x() > 0.42 && b.x() < 0.58 && b.y() > 0.32 && b.y() < 0.68) {
        ++mark;
        EXPECT_LT(p.intensity,
                  0.5 * scene.board_intensity);  // printed: the black print's reflectivity
      } else if (std::abs(b.x() - 0.5) > 0.15) {
        ++board_plain;
        EXPECT_GT(p.intensity, 0.8 * scene.board_intensity);
      }
    }
  }
  EXPECT_GT(ground, 1000);
  EXPECT_GT(facade, 1000);
  EXPECT_EQ(above, 0) << "no ceiling and facades end";
  EXPECT_GT(board_plain, 20);
  EXPECT_GT(mark, 0);
  const CameraModel camera = makeCamera(640, 480, 500, DistortionModel::kNone, {});
  RenderOptions render;
  render.noise_sigma = 0;
  render.vignetting = 0;
  const Eigen::Isometry3d cam = cameraLookingAlongX(Eigen::Vector3d::Zero());
  const cv::Mat image = renderCameraImage(camera, cam, scene, board, render, rng);
  ASSERT_FALSE(image.empty());
  auto colourAt = [&](const Eigen::Vector3d& world) {
    Eigen::Vector2d px(0, 0);
    EXPECT_TRUE(camera.project(cam.inverse() * world, &px));
    return image.at<cv::Vec3b>(static_cast<int>(std::lround(px.y())),
                               static_cast<int>(std::lround(px.x())));
  };
  const cv::Vec3b sky =
      colourAt(Eigen::Vector3d(45, 0, 20));  // above the facade ahead (top at 13.3 m)
  EXPECT_GT(sky[0], 150);                    // bright, blue-ish
  EXPECT_GT(sky[0], sky[2]);
  const cv::Vec3b face = colourAt(board * Eigen::Vector3d(0.2, 0.2, 0));
  EXPECT_GT(face[2], face[0] + 30) << "cardboard: red well above blue";
  EXPECT_NEAR(face[2], 255 * 0.6, 255 * 0.6 * 0.16);  // albedo x shading (0.85..1) x facing
  const cv::Vec3b printed = colourAt(board * Eigen::Vector3d(0.5, 0.5, 0));
  EXPECT_LT(printed[2], 40);
  const cv::Vec3b pavement = colourAt(Eigen::Vector3d(6, 0.5, scene.floor_z_m));
  EXPECT_NEAR((pavement[0] + pavement[1] + pavement[2]) / 3.0, 255 * 0.6, 255 * 0.6 * 0.5)
      << "pavement about as bright as the board";
}

// Existing scenes must render and cast exactly as before the clutter / outdoor options (same
// seed -> same frames): checksums recorded with the simulator before those options existed.
TEST(SimRegression, DefaultSceneUnchanged) {
  const Target target = loadConfigTarget("plain_1016.yaml");
  SceneSpec scene;
  scene.target = target;
  auto spec = lidarPreset("VLP-16");
  ASSERT_TRUE(spec.ok());
  std::mt19937 rng(21);
  const Eigen::Isometry3d board = boardPose(target, {3, 0.3, 0}, 40, 10, 5);
  const LidarCloud cloud =
      simulateLidarScan(*spec, Eigen::Isometry3d::Identity(), scene, board, rng);
  double cloud_sum = 0;
  for (size_t i = 0; i < cloud.points.size(); ++i) {
    const auto& p = cloud.points[i];
    if (std::isfinite(p.x))
      cloud_sum += (i % 7 + 1) * (p.x + 2 * p.y + 3 * p.z + 0.01 * p.intensity);
  }
  const CameraModel camera =
      makeCamera(320, 240, 250, DistortionModel::kPlumbBob, {-0.1, 0.02, 0, 0, 0});
  RenderOptions render;
  const cv::Mat image = renderCameraImage(camera, cameraLookingAlongX(Eigen::Vector3d(0, 0.1, 0)),
                                          scene, board, render, rng);
  double image_sum = 0;
  for (int v = 0; v < image.rows; ++v)
    for (int u = 0; u < image.cols; ++u) {
      const cv::Vec3b c = image.at<cv::Vec3b>(v, u);
      image_sum += ((u * 31 + v * 17) % 13 + 1) * (c[0] + 2.0 * c[1] + 3.0 * c[2]);
    }
  std::printf("checksums: cloud %.6f image %.1f\n", cloud_sum, image_sum);
  EXPECT_NEAR(cloud_sum, kGoldenCloudSum, 1e-6 * std::abs(kGoldenCloudSum));
  EXPECT_EQ(image_sum, kGoldenImageSum);
}

TEST(SimOptions, ValidationReasons) {
  LidarSpec spec;
  EXPECT_FALSE(spec.validate().empty());  // no rings
  spec = *lidarPreset("VLP-16");
  EXPECT_TRUE(spec.validate().empty());
  spec.dropout_probability = 2;
  EXPECT_NE(spec.validate().find("dropout"), std::string::npos);
  RenderOptions render;
  EXPECT_TRUE(render.validate().empty());
  render.supersampling = 0;
  EXPECT_FALSE(render.validate().empty());
}

}  // namespace
}  // namespace sim
}  // namespace board_calib
