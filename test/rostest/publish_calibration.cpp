// publish_calibration broadcasts saved result files as static TF: every transform found in TF
// must equal the file's (pair: lidar -> camera child; rig: reference -> every sensor + suffix).
#include <board_calib/core/result_io.h>
#include <board_calib/core/transform.h>

#include <gtest/gtest.h>
#include <ros/ros.h>
#include <tf2_eigen/tf2_eigen.h>
#include <tf2_ros/transform_listener.h>

#include <optional>

namespace {

// parent_T_child from TF (waits up to 10 s of wall time); nullopt when it never arrives.
std::optional<Eigen::Isometry3d> lookup(tf2_ros::Buffer& buffer, const std::string& parent,
                                        const std::string& child) {
  const ros::WallTime deadline = ros::WallTime::now() + ros::WallDuration(10.0);
  while (!buffer.canTransform(parent, child, ros::Time(0)) && ros::WallTime::now() < deadline)
    ros::WallDuration(0.05).sleep();
  try {
    return tf2::transformToEigen(buffer.lookupTransform(parent, child, ros::Time(0)));
  } catch (const tf2::TransformException&) {
    return std::nullopt;
  }
}

// Sub-micrometre / micro-degree: the file's values pass through the TF message unchanged.
void expectSame(const Eigen::Isometry3d& got, const Eigen::Isometry3d& expected,
                const std::string& what) {
  EXPECT_LT(board_calib::rotationErrorDeg(got, expected), 1e-6) << what;
  EXPECT_LT(board_calib::translationErrorM(got, expected), 1e-7) << what;
}

}  // namespace

TEST(PublishCalibration, PairAndRigResultsAreBroadcast) {
  std::string pair_file, rig_file;
  ros::param::get("~pair_file", pair_file);
  ros::param::get("~rig_file", rig_file);
  auto pair = board_calib::loadResultFile(pair_file);
  auto rig = board_calib::loadResultFile(rig_file);
  ASSERT_TRUE(pair.ok()) << pair.error();
  ASSERT_TRUE(rig.ok()) << rig.error();
  tf2_ros::Buffer buffer;
  tf2_ros::TransformListener listener(buffer);

  const auto camera = lookup(buffer, pair->lidar_frame, "camera_calibrated");
  ASSERT_TRUE(camera.has_value()) << "no TF " << pair->lidar_frame << " -> camera_calibrated";
  expectSame(*camera, pair->camera_T_lidar.inverse(), "pair");

  ASSERT_EQ(rig->sensors.size(), 4u);
  int checked = 0;
  for (const auto& s : rig->sensors) {
    if (s.frame == rig->reference_frame) continue;
    const auto got = lookup(buffer, rig->reference_frame, s.frame + "_calib");
    ASSERT_TRUE(got.has_value()) << "no TF " << rig->reference_frame << " -> " << s.frame
                                 << "_calib";
    expectSame(*got, s.reference_T_sensor, s.frame);
    ++checked;
  }
  EXPECT_EQ(checked, 3);
}

int main(int argc, char** argv) {
  ::testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "publish_calibration_test");
  ros::NodeHandle nh;
  return RUN_ALL_TESTS();
}
