// Grouping per-sensor streams by stamp into board poses, then solving the graph from them.
#include <board_calib/core/msg_graph/pose_grouping.h>
#include <board_calib/core/transform.h>
#include "support/synthetic_rig.h"

#include <gtest/gtest.h>

namespace board_calib {
namespace multi_sensor {
namespace {

// Splits a synthetic scene into per-sensor streams with stamp jitter, as detectors emit them.
struct Streams {
  std::map<int, std::vector<CameraBoardFeatures>> cameras;
  std::map<int, std::vector<LidarBoardFeatures>> lidars;
};

Streams split(const sim::RigScene& scene, double period_s, double jitter_s, std::mt19937& rng) {
  std::uniform_real_distribution<double> jitter(-jitter_s, jitter_s);
  Streams out;
  for (const auto& pose : scene.problem.poses) {
    const double t = pose.id * period_s;
    for (auto [s, f] : pose.cameras) {
      f.stamp = t + jitter(rng);
      out.cameras[s].push_back(f);
    }
    for (auto [s, f] : pose.lidars) {
      f.stamp = t + jitter(rng);
      out.lidars[s].push_back(f);
    }
  }
  return out;
}

TEST(MsgSession, GroupsJitteredStreamsIntoTheBoardPoses) {
  std::mt19937 rng(21);
  sim::RigSceneOptions so;
  so.num_poses = 30;
  auto scene = sim::generateRigScene(sim::defaultRig(), so, rng);
  ASSERT_TRUE(scene.ok()) << scene.error();
  // 1 s between board poses, +-20 ms jitter: a 50 ms tolerance separates them exactly.
  Streams streams = split(*scene, 1.0, 0.02, rng);
  // A lone LiDAR frame between two poses (nobody else saw that moment) must be dropped.
  LidarBoardFeatures lone = streams.lidars[2].front();
  lone.stamp = 5.5;
  streams.lidars[2].push_back(lone);
  GroupingOptions go;
  go.stamp_tolerance_s = 0.05;
  auto grouped = groupByStamp(scene->problem.sensors, streams.cameras, streams.lidars, go);
  ASSERT_TRUE(grouped.ok()) << grouped.error();
  ASSERT_EQ(grouped->poses.size(), 30u);
  EXPECT_EQ(grouped->groups_dropped, 1);
  for (const auto& pose : grouped->poses) {
    EXPECT_EQ(pose.cameras.size(), 2u);
    EXPECT_EQ(pose.lidars.size(), 2u);
  }
  // Solving from the grouped poses gives the same accuracy as from the scene itself.
  MsgProblem problem;
  problem.sensors = scene->problem.sensors;
  problem.poses = grouped->poses;
  const MsgSolution sol = solveMsgGraph(problem, MsgGraphOptions());
  ASSERT_TRUE(sol.success) << sol.reason;
  for (int s = 1; s < 4; ++s) {
    // Issue 9 target for every pair: 0.2 deg, 1 cm.
    EXPECT_LT(
        rotationErrorDeg(sol.sensors[s].reference_T_sensor, scene->sensors[s].reference_T_sensor),
        0.2);
    EXPECT_LT(
        translationErrorM(sol.sensors[s].reference_T_sensor, scene->sensors[s].reference_T_sensor),
        0.01);
  }
}

TEST(MsgSession, BadInputGivesReasons) {
  std::vector<SensorSpec> sensors(2);
  sensors[0].frame = "cam";
  sensors[0].kind = SensorKind::kCamera;
  sensors[1].frame = "lidar";
  sensors[1].kind = SensorKind::kLidar;
  std::map<int, std::vector<CameraBoardFeatures>> cameras;
  std::map<int, std::vector<LidarBoardFeatures>> lidars;
  cameras[1].push_back(CameraBoardFeatures());  // a camera stream on the LiDAR
  auto r = groupByStamp(sensors, cameras, lidars, GroupingOptions());
  EXPECT_FALSE(r.ok());
  EXPECT_NE(r.error().find("is a LiDAR"), std::string::npos) << r.error();
  cameras.clear();
  lidars[7].push_back(LidarBoardFeatures());
  r = groupByStamp(sensors, cameras, lidars, GroupingOptions());
  EXPECT_FALSE(r.ok());
  GroupingOptions bad;
  bad.min_sensors = 1;
  EXPECT_FALSE(groupByStamp(sensors, {}, {}, bad).ok());
  // Empty streams: no poses, no failure.
  auto empty = groupByStamp(sensors, {}, {}, GroupingOptions());
  ASSERT_TRUE(empty.ok());
  EXPECT_TRUE(empty->poses.empty());
}

}  // namespace
}  // namespace multi_sensor
}  // namespace board_calib
