// Rig report: every camera <- LiDAR pair judged at the graph's pose on the board poses both
// sensors saw (the pair report's figures per pair), and the report folder written.
#include <board_calib/core/pipeline/rig_report.h>
#include <board_calib/core/transform.h>
#include "support/synthetic_rig.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <iostream>

#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>

namespace board_calib {
namespace {

class RigReportTest : public ::testing::Test {
 protected:
  void SetUp() override {
    auto s = sim::defaultRigScene(12, 7);
    ASSERT_TRUE(s.ok()) << s.error();
    scene = *s;
    solution = multi_sensor::solveMsgGraph(scene.problem, multi_sensor::MsgGraphOptions{});
    ASSERT_TRUE(solution.success) << solution.reason;
    result = multi_sensor::msgResultFile(scene.problem, solution);
    rig = sim::rigConfigOf(scene);
  }
  sim::RigScene scene;
  multi_sensor::MsgSolution solution;
  ResultFile result;
  RigConfig rig;
};

TEST_F(RigReportTest, EveryPairIsJudgedOnThePosesBothSensorsSaw) {
  const auto pairs = evaluateRigPairs(scene.problem, solution, result);
  ASSERT_EQ(pairs.size(), result.pairs.size());
  ASSERT_EQ(pairs.size(), 4u) << "2 cameras x 2 LiDARs";
  // The figures at the true pairs: what the sensors' noise and sampling alone give (edge points
  // lie up to one column step inside the edge, a few px at these distances).
  ResultFile truth = result;
  for (auto& p : truth.pairs) {
    Eigen::Isometry3d ref_T_camera = Eigen::Isometry3d::Identity(),
                      ref_T_lidar = Eigen::Isometry3d::Identity();
    for (const auto& s : scene.sensors) {
      if (s.frame == p.camera_frame) ref_T_camera = s.reference_T_sensor;
      if (s.frame == p.lidar_frame) ref_T_lidar = s.reference_T_sensor;
    }
    p.camera_T_lidar = ref_T_camera.inverse() * ref_T_lidar;
  }
  const auto truth_pairs = evaluateRigPairs(scene.problem, solution, truth);
  // The same pairs with the camera turned by 0.5 deg about its y axis: every projected point moves
  // f tan(0.5 deg) = 9 px sideways (f = 1000 px), about 6 px across the diamond's 45 deg edges.
  ResultFile turned = result;
  for (auto& p : turned.pairs)
    p.camera_T_lidar.prerotate(Eigen::AngleAxisd(0.5 * M_PI / 180.0, Eigen::Vector3d::UnitY()));
  const auto turned_pairs = evaluateRigPairs(scene.problem, solution, turned);
  for (size_t i = 0; i < pairs.size(); ++i) {
    const auto& p = pairs[i];
    int both = 0;
    for (const auto& pose : scene.problem.poses) {
      const int c =
          static_cast<int>(std::find_if(solution.sensors.begin(), solution.sensors.end(),
                                        [&](const auto& s) { return s.frame == p.camera_frame; }) -
                           solution.sensors.begin());
      const int l =
          static_cast<int>(std::find_if(solution.sensors.begin(), solution.sensors.end(),
                                        [&](const auto& s) { return s.frame == p.lidar_frame; }) -
                           solution.sensors.begin());
      both += pose.cameras.count(c) && pose.lidars.count(l);
    }
    EXPECT_EQ(static_cast<int>(p.views.size()), both) << p.folder;
    ASSERT_TRUE(p.evaluation.success) << p.evaluation.reason;
    EXPECT_TRUE(p.evaluation.camera_T_lidar.isApprox(result.pairs[i].camera_T_lidar));
    ASSERT_TRUE(p.evaluation.mlre_px.has_value()) << p.folder;
    ASSERT_TRUE(turned_pairs[i].evaluation.mlre_px.has_value()) << p.folder;
    ASSERT_TRUE(truth_pairs[i].evaluation.mlre_px.has_value()) << p.folder;
    const double at_truth = *truth_pairs[i].evaluation.mlre_px;
    std::cout << p.folder << ": MLRE " << *p.evaluation.mlre_px << " px at the graph's pose, "
              << at_truth << " px at the truth, " << *turned_pairs[i].evaluation.mlre_px
              << " px turned by 0.5 deg\n";
    // The graph's pose is within about 0.1 deg / 5 mm of the truth (test_msg_graph): at 2-5 m that
    // moves edge points by at most ~2 px and mostly along the edge; 0.5 px of slack above the
    // floor.
    EXPECT_LT(*p.evaluation.mlre_px, at_truth + 0.5) << p.folder;
    EXPECT_GT(*turned_pairs[i].evaluation.mlre_px, at_truth + 3.0) << p.folder;
    // The graph's 1 sigma travels with the pair.
    EXPECT_GT(p.evaluation.stddev.translation_m.maxCoeff(), 0.0) << p.folder;
  }
}

TEST_F(RigReportTest, WritesTheRigPageAndOnePagePerPairWithItsFigures) {
  const std::string dir = ::testing::TempDir() + "/rig_report_test";
  std::filesystem::remove_all(dir);
  RigReportInputs inputs;
  inputs.source = "synthetic rig";
  inputs.input_lines = {"camera `left`: board in 12/12 images"};
  const Status st = writeRigReport(dir, rig, scene.problem, solution, result, inputs);
  ASSERT_TRUE(st) << st.reason;
  std::ifstream in(dir + "/report.md");
  std::stringstream md;
  md << in.rdbuf();
  EXPECT_NE(md.str().find("loop consistency"), std::string::npos);
  EXPECT_NE(md.str().find("board in 12/12 images"), std::string::npos);
  EXPECT_TRUE(std::filesystem::exists(dir + "/result.yaml"));
  for (const auto& p : evaluateRigPairs(scene.problem, solution, result)) {
    EXPECT_NE(md.str().find("(" + p.folder + "/report.md)"), std::string::npos) << p.folder;
    EXPECT_TRUE(std::filesystem::exists(dir + "/" + p.folder + "/report.md")) << p.folder;
    EXPECT_GT(std::filesystem::file_size(dir + "/" + p.folder + "/edge_errors.png"), 1000u)
        << p.folder;
    EXPECT_GT(std::filesystem::file_size(dir + "/" + p.folder + "/pose_coverage.png"), 1000u)
        << p.folder;
  }
  // An unwritable folder is a reason, not a crash.
  EXPECT_FALSE(
      writeRigReport("/proc/no_such_dir/report", rig, scene.problem, solution, result, inputs));
}

}  // namespace
}  // namespace board_calib
