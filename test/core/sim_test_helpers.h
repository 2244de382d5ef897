// Small helpers of the simulator tests (test_sim.cpp, test_sim_scenes.cpp,
// test_lidar_detector_sim.cpp): a camera looking along the world x axis, a board facing it, a
// camera model, a target of config/targets.
#pragma once

#include <board_calib/core/camera_model.h>
#include <board_calib/core/target.h>
#include <board_calib/core/transform.h>

#include <gtest/gtest.h>

#include <string>
#include <vector>

namespace board_calib {
namespace sim {

// World z up; the camera looks along world +x (optical z), optical x = world -y, y = world -z.
inline Eigen::Isometry3d cameraLookingAlongX(const Eigen::Vector3d& position) {
  Eigen::Matrix3d R;
  R.col(0) = -Eigen::Vector3d::UnitY();
  R.col(1) = -Eigen::Vector3d::UnitZ();
  R.col(2) = Eigen::Vector3d::UnitX();
  return makeTransform(R, position);
}

// Board centred at `centre`, printed face towards the camera at the origin, rolled about the
// viewing direction by roll_deg (a diamond at 45) and turned by yaw_deg / pitch_deg.
inline Eigen::Isometry3d boardPose(const Target& target, const Eigen::Vector3d& centre,
                                   double roll_deg, double yaw_deg = 0, double pitch_deg = 0) {
  const Eigen::Matrix3d facing = cameraLookingAlongX(Eigen::Vector3d::Zero()).linear();
  const Eigen::Matrix3d R =
      Eigen::AngleAxisd(yaw_deg * kRadPerDeg, Eigen::Vector3d::UnitZ()).toRotationMatrix() *
      Eigen::AngleAxisd(pitch_deg * kRadPerDeg, Eigen::Vector3d::UnitY()).toRotationMatrix() *
      facing *
      Eigen::AngleAxisd(roll_deg * kRadPerDeg, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  return makeTransform(R, centre - R * target.center());
}

inline CameraModel makeCamera(int width, int height, double f, DistortionModel model,
                              std::vector<double> coeffs) {
  CameraIntrinsics in;
  in.width = width;
  in.height = height;
  in.fx = f;
  in.fy = f * 1.001;
  in.cx = width / 2.0 - 3.3;
  in.cy = height / 2.0 + 2.1;
  in.model = model;
  in.coeffs = std::move(coeffs);
  auto camera = CameraModel::create(in);
  EXPECT_TRUE(camera.ok()) << camera.error();
  return *camera;
}

inline Target loadConfigTarget(const std::string& name) {
  auto target = loadTarget(std::string(BOARD_CALIB_SOURCE_DIR) + "/config/targets/" + name);
  EXPECT_TRUE(target.ok()) << target.error();
  return *target;
}

}  // namespace sim
}  // namespace board_calib
