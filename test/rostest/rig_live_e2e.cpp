// Rig-mode end-to-end rostest: once the simulated rig bag has played through the detectors into
// the calibrator (rig mode), ~calibrate solves the MSG graph; every sensor's broadcast static TF
// (from the reference frame) and every camera <- LiDAR pair must match the simulator's ground
// truth, the result file must list every sensor and pair, and a saved rig session must reload to
// the same poses. ~sensors, ~pairs and ~min_poses describe the rig under test.
#include <board_calib/Calibrate.h>
#include <board_calib/SessionFile.h>
#include <board_calib/calibrator_status.h>
#include <board_calib/conversions.h>
#include <board_calib/core/result_io.h>
#include <board_calib/core/transform.h>

#include "wait_for_bag_end.h"

#include <diagnostic_msgs/DiagnosticArray.h>
#include <gtest/gtest.h>
#include <ros/ros.h>
#include <tf2_eigen/tf2_eigen.h>
#include <tf2_ros/transform_listener.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <optional>
#include <sstream>

namespace {

// reference_T_sensor of the truth file by frame.
std::map<std::string, Eigen::Isometry3d> truthPoses(const board_calib::ResultFile& truth) {
  std::map<std::string, Eigen::Isometry3d> out;
  for (const auto& s : truth.sensors) out[s.frame] = s.reference_T_sensor;
  return out;
}

struct Limits {
  int sensors = 4, pairs = 4, min_poses = 15;
  double rotation_tol_deg = 0.2, translation_tol_m = 0.01;
};

// Every camera <- LiDAR pair of the reply within the limits of the truth, with a finite 1 sigma.
void expectPairsNearTruth(const board_calib::Calibrate::Response& response,
                          const board_calib::ResultFile& truth, const Limits& limits) {
  const double rotation_tol_deg = limits.rotation_tol_deg,
               translation_tol_m = limits.translation_tol_m;
  for (const auto& r : response.all_results) {
    // Every pair says how good it is: a finite, positive 1 sigma from the graph covariance.
    for (int i = 0; i < 3; ++i) {
      EXPECT_TRUE(std::isfinite(r.stddev_translation_m[i]) && r.stddev_translation_m[i] > 0.0)
          << r.camera_frame;
      EXPECT_TRUE(std::isfinite(r.stddev_rotation_deg[i]) && r.stddev_rotation_deg[i] > 0.0)
          << r.camera_frame;
    }
    EXPECT_LT(r.stddev_translation_m[0], 0.01) << r.camera_frame << " <- " << r.lidar_frame;
    // The target: every camera <- LiDAR pair within 0.2 deg / 1 cm of the truth.
    const auto truth_pair =
        std::find_if(truth.pairs.begin(), truth.pairs.end(), [&](const auto& p) {
          return p.camera_frame == r.camera_frame && p.lidar_frame == r.lidar_frame;
        });
    if (truth_pair == truth.pairs.end()) {
      ADD_FAILURE() << "no truth for the pair " << r.camera_frame << " <- " << r.lidar_frame;
      continue;
    }
    const Eigen::Isometry3d got = board_calib::fromTransformMsg(r.camera_T_lidar);
    const double rot = board_calib::rotationErrorDeg(got, truth_pair->camera_T_lidar);
    const double trans = board_calib::translationErrorM(got, truth_pair->camera_T_lidar);
    std::cout << "[rig_live_e2e] pair " << r.camera_frame << " <- " << r.lidar_frame << ": " << rot
              << " deg, " << trans * 1e3 << " mm from truth" << std::endl;
    EXPECT_LT(rot, rotation_tol_deg) << r.camera_frame << " <- " << r.lidar_frame;
    EXPECT_LT(trans, translation_tol_m) << r.camera_frame << " <- " << r.lidar_frame;
  }
}

// Every sensor's broadcast static TF from the reference frame within the limits of the truth.
void expectTfsNearTruth(tf2_ros::Buffer& buffer, const board_calib::Calibrate::Response& response,
                        const std::map<std::string, Eigen::Isometry3d>& truth_poses,
                        const Limits& limits) {
  const double rotation_tol_deg = limits.rotation_tol_deg,
               translation_tol_m = limits.translation_tol_m;
  const int min_poses = limits.min_poses;
  const std::string reference = response.reference_frame;
  ASSERT_TRUE(truth_poses.count(reference)) << reference;
  const Eigen::Isometry3d truth_ref = truth_poses.at(reference);
  for (const auto& s : response.sensors) {
    // The capture must have used most of the simulated board poses.
    EXPECT_GE(s.poses_used, static_cast<uint32_t>(min_poses)) << s.frame;
    if (s.frame == reference) continue;
    ASSERT_TRUE(truth_poses.count(s.frame)) << s.frame;
    const Eigen::Isometry3d expected = truth_ref.inverse() * truth_poses.at(s.frame);
    // The broadcast static TF: parent = reference frame, child = the sensor.
    const ros::WallTime deadline = ros::WallTime::now() + ros::WallDuration(10.0);
    while (!buffer.canTransform(reference, s.frame, ros::Time(0)) &&
           ros::WallTime::now() < deadline)
      ros::WallDuration(0.05).sleep();
    geometry_msgs::TransformStamped tf;
    try {
      tf = buffer.lookupTransform(reference, s.frame, ros::Time(0));
    } catch (const tf2::TransformException& e) {
      ADD_FAILURE() << "no static TF " << reference << " -> " << s.frame << ": " << e.what();
      continue;
    }
    const Eigen::Isometry3d got = tf2::transformToEigen(tf);
    const double rot = board_calib::rotationErrorDeg(got, expected);
    const double trans = board_calib::translationErrorM(got, expected);
    std::cout << "[rig_live_e2e] " << reference << " -> " << s.frame << ": " << rot << " deg, "
              << trans * 1e3 << " mm from truth (" << s.poses_used << " poses)" << std::endl;
    // The target for the simulated rig: every pair within 0.2 deg / 1 cm.
    EXPECT_LT(rot, rotation_tol_deg) << s.frame;
    EXPECT_LT(trans, translation_tol_m) << s.frame;
  }
}

// The calibrator's newest status on /diagnostics names, per sensor, the poses it joined.
void expectHealthPerSensor(std::optional<diagnostic_msgs::DiagnosticStatus>& health,
                           const board_calib::Calibrate::Response& response) {
  health.reset();
  const ros::WallTime diagnostics_deadline = ros::WallTime::now() + ros::WallDuration(5.0);
  while (!health && ros::WallTime::now() < diagnostics_deadline) {
    ros::spinOnce();
    ros::WallDuration(0.05).sleep();
  }
  ASSERT_TRUE(health) << "no calibrator status on /diagnostics";
  for (const auto& s : response.sensors) {
    const auto kv = std::find_if(health->values.begin(), health->values.end(), [&](const auto& v) {
      return v.key.rfind("sensor ", 0) == 0 && v.key.find("(" + s.frame + ")") != std::string::npos;
    });
    ASSERT_NE(kv, health->values.end()) << "no diagnostics line for " << s.frame;
    EXPECT_NE(kv->value.find(" poses: "), std::string::npos) << kv->key << ": " << kv->value;
  }
}

// The result file lists every sensor and pair; the rig report has its pages and says why a live
// report has no overlays.
void expectFiles(const std::string& output_dir, const Limits& limits) {
  const int sensors = limits.sensors, pairs = limits.pairs;
  auto written = board_calib::loadResultFile(output_dir + "/msg_rig_result.yaml");
  ASSERT_TRUE(written.ok()) << written.error();
  EXPECT_EQ(written->sensors.size(), static_cast<size_t>(sensors));
  EXPECT_EQ(written->pairs.size(), static_cast<size_t>(pairs));
  // The rig report: the rig page and one page per pair with its figures
  // (core/pipeline/rig_report.h).
  EXPECT_TRUE(std::filesystem::exists(output_dir + "/report/report.md"));
  for (const auto& p : written->pairs) {
    const std::string page = output_dir + "/report/" + p.camera_frame + "__" + p.lidar_frame;
    EXPECT_TRUE(std::filesystem::exists(page + "/report.md")) << page;
    EXPECT_TRUE(std::filesystem::exists(page + "/edge_errors.png")) << page;
  }

  std::ifstream report(output_dir + "/report/report.md");
  std::stringstream text;
  text << report.rdbuf();
  EXPECT_NE(text.str().find("No overlays in a live report"), std::string::npos)
      << "the live report says why it has no overlay images";
}

// Save, reset, reload: the same number of poses comes back.
void expectSessionReloads(ros::NodeHandle& nh, const std::string& output_dir, int min_poses) {
  ros::ServiceClient save = nh.serviceClient<board_calib::SessionFile>("calibrator/save_session");
  ros::ServiceClient load = nh.serviceClient<board_calib::SessionFile>("calibrator/load_session");
  board_calib::SessionFile saved, loaded;
  saved.request.path = output_dir + "/rig_session.yaml";
  ASSERT_TRUE(save.call(saved));
  ASSERT_TRUE(saved.response.success) << saved.response.message;
  loaded.request.path = saved.request.path;
  ASSERT_TRUE(load.call(loaded));
  ASSERT_TRUE(loaded.response.success) << loaded.response.message;
  EXPECT_EQ(loaded.response.views, saved.response.views);
  EXPECT_GE(saved.response.views, static_cast<uint32_t>(min_poses));
}

}  // namespace

TEST(RigLiveEndToEnd, EverySensorTfMatchesGroundTruth) {
  ros::NodeHandle nh;
  std::string truth_file, output_dir;
  ros::param::get("~truth_file", truth_file);
  ros::param::get("~output_dir", output_dir);
  double timeout_s = 240;
  Limits limits;
  ros::param::param("~timeout", timeout_s, timeout_s);
  ros::param::param("~sensors", limits.sensors, limits.sensors);
  ros::param::param("~pairs", limits.pairs, limits.pairs);
  ros::param::param("~min_poses", limits.min_poses, limits.min_poses);
  auto truth = board_calib::loadResultFile(truth_file);
  ASSERT_TRUE(truth.ok()) << truth.error();
  const auto truth_poses = truthPoses(*truth);

  tf2_ros::Buffer buffer;
  tf2_ros::TransformListener listener(buffer);
  // The calibrator's per-sensor health on /diagnostics (the newest status, read after the solve).
  std::optional<diagnostic_msgs::DiagnosticStatus> health;
  ros::Subscriber diagnostics = nh.subscribe<diagnostic_msgs::DiagnosticArray>(
      "/diagnostics", 10, [&](const diagnostic_msgs::DiagnosticArrayConstPtr& a) {
        for (const auto& s : a->status)
          if (s.hardware_id == board_calib::calibrator_status::kHardwareId) health = s;
      });
  ASSERT_TRUE(board_calib_test::waitForBagEnd(nh, timeout_s))
      << "the bag did not play to its end within " << timeout_s << " s";

  ros::ServiceClient client = nh.serviceClient<board_calib::Calibrate>("calibrator/calibrate");
  ASSERT_TRUE(client.waitForExistence(ros::Duration(30.0)));
  board_calib::Calibrate wrong;
  wrong.request.method = "pbpc";
  ASSERT_TRUE(client.call(wrong));
  EXPECT_FALSE(wrong.response.success);
  EXPECT_NE(wrong.response.message.find("rig mode"), std::string::npos) << wrong.response.message;

  board_calib::Calibrate srv;
  srv.request.method = "msg";
  ASSERT_TRUE(client.call(srv));
  ASSERT_TRUE(srv.response.success) << srv.response.message;
  std::cout << "[rig_live_e2e]\n" << srv.response.message << std::endl;
  ASSERT_EQ(srv.response.sensors.size(), static_cast<size_t>(limits.sensors));
  EXPECT_EQ(srv.response.all_results.size(), static_cast<size_t>(limits.pairs))
      << "every camera x every LiDAR";
  expectPairsNearTruth(srv.response, *truth, limits);
  expectTfsNearTruth(buffer, srv.response, truth_poses, limits);
  expectHealthPerSensor(health, srv.response);
  expectFiles(output_dir, limits);
  expectSessionReloads(nh, output_dir, limits.min_poses);
}

int main(int argc, char** argv) {
  ::testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "rig_live_e2e_test");
  ros::NodeHandle nh;  // keeps the node alive for the whole test
  return RUN_ALL_TESTS();
}
