// MSG graph on simulated rigs at known ground truth: a stereo pair, a VLP-32C-like and an
// OS1-64-like LiDAR, 40 board poses of a 1 m AprilTag grid (issue 9 targets). The covariance
// against the spread over many scenes is test_msg_graph_covariance.
#include <board_calib/core/msg_graph/msg_graph.h>
#include <board_calib/core/transform.h>
#include "support/synthetic_rig.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <iostream>
#include <map>
#include <string>
#include <vector>

namespace board_calib {
namespace multi_sensor {
namespace {

// Issue 9 targets: every pair within 0.2 deg and 1 cm; with a 3x-noise sensor in the graph the
// other pairs within 0.3 deg and 1.5 cm.
constexpr double kPairRotationTolDeg = 0.2;
constexpr double kPairTranslationTolM = 0.01;
constexpr double kNoisyRotationTolDeg = 0.3;
constexpr double kNoisyTranslationTolM = 0.015;

sim::RigScene makeScene(const std::vector<sim::RigSensor>& rig, unsigned seed, int poses = 40) {
  auto scene = sim::rigScene(rig, poses, seed);
  EXPECT_TRUE(scene.ok()) << scene.error();
  return *scene;
}

struct PairError {
  double rotation_deg = 0, translation_m = 0;
};

PairError pairError(const MsgSolution& sol, const sim::RigScene& scene, int a, int b) {
  const Eigen::Isometry3d truth =
      scene.sensors[a].reference_T_sensor.inverse() * scene.sensors[b].reference_T_sensor;
  const Eigen::Isometry3d est = *sensorTSensor(sol, a, b);
  return {rotationErrorDeg(est, truth), translationErrorM(est, truth)};
}

// Every pair among `sensors` within the tolerances.
void expectPairsWithin(const MsgSolution& sol, const sim::RigScene& scene,
                       const std::vector<int>& sensors, double rot_tol_deg, double trans_tol_m) {
  for (size_t i = 0; i < sensors.size(); ++i)
    for (size_t j = i + 1; j < sensors.size(); ++j) {
      const PairError e = pairError(sol, scene, sensors[i], sensors[j]);
      EXPECT_LT(e.rotation_deg, rot_tol_deg)
          << scene.sensors[sensors[i]].frame << "<->" << scene.sensors[sensors[j]].frame;
      EXPECT_LT(e.translation_m, trans_tol_m)
          << scene.sensors[sensors[i]].frame << "<->" << scene.sensors[sensors[j]].frame;
    }
}

double maxPairRotationDeg(const MsgSolution& sol, const sim::RigScene& scene,
                          const std::vector<int>& sensors) {
  double m = 0;
  for (size_t i = 0; i < sensors.size(); ++i)
    for (size_t j = i + 1; j < sensors.size(); ++j)
      m = std::max(m, pairError(sol, scene, sensors[i], sensors[j]).rotation_deg);
  return m;
}
double maxPairTranslationM(const MsgSolution& sol, const sim::RigScene& scene,
                           const std::vector<int>& sensors) {
  double m = 0;
  for (size_t i = 0; i < sensors.size(); ++i)
    for (size_t j = i + 1; j < sensors.size(); ++j)
      m = std::max(m, pairError(sol, scene, sensors[i], sensors[j]).translation_m);
  return m;
}

TEST(MsgGraph, FourSensorRigEveryPairWithinTolerance) {
  const sim::RigScene scene = makeScene(sim::defaultRig(), 1);
  const MsgSolution sol = solveMsgGraph(scene.problem, MsgGraphOptions());
  ASSERT_TRUE(sol.success) << sol.reason;
  EXPECT_TRUE(sol.used_pairwise_init);
  EXPECT_EQ(sol.poses_used, 40);
  expectPairsWithin(sol, scene, {0, 1, 2, 3}, kPairRotationTolDeg, kPairTranslationTolM);
  // Every triangle of the 4 sensors has pairwise estimates: 4 loops, consistent to the pairwise
  // accuracy (about twice the per-pair tolerance, three links composed).
  EXPECT_EQ(sol.loops.size(), 4u);
  EXPECT_LT(sol.loop_rotation_max_deg, 3 * kPairRotationTolDeg);
  EXPECT_LT(sol.loop_translation_max_mm, 3000 * kPairTranslationTolM);
  // Factory-stereo check against the true stereo extrinsic.
  const auto stereo = stereoConsistency(sol, 0, 1, scene.sensors[1].reference_T_sensor);
  ASSERT_TRUE(stereo.ok()) << stereo.error();
  EXPECT_LT(stereo->rotation_deg, kPairRotationTolDeg);
  EXPECT_LT(stereo->translation_mm, 1000 * kPairTranslationTolM);
  // 1 sigma exists for every non-reference sensor and is small against the tolerance.
  for (int s = 1; s < 4; ++s) {
    EXPECT_GT(sol.sensors[s].stddev.translation_m.maxCoeff(), 0.0);
    EXPECT_LT(sol.sensors[s].stddev.translation_m.maxCoeff(), kPairTranslationTolM);
  }
  EXPECT_TRUE(sol.rejected.empty());
  EXPECT_GT(sol.residuals.corner_terms, 0);
}

// A fifth sensor with 3x the noise (VLP-16-like) must not pull the four good ones out of
// tolerance: its sigmas are estimated from the pairwise residuals and it is down-weighted.
TEST(MsgGraph, NoisyFifthSensorDoesNotRuinTheOthers) {
  auto rig = sim::defaultRig();
  rig.push_back(sim::extraLidar16("vlp16_noisy", 3.0));
  const sim::RigScene scene = makeScene(rig, 2);
  const MsgSolution sol = solveMsgGraph(scene.problem, MsgGraphOptions());
  ASSERT_TRUE(sol.success) << sol.reason;
  expectPairsWithin(sol, scene, {0, 1, 2, 3}, kNoisyRotationTolDeg, kNoisyTranslationTolM);
  std::cout << "good pairs: max " << maxPairRotationDeg(sol, scene, {0, 1, 2, 3}) << " deg, "
            << 1000 * maxPairTranslationM(sol, scene, {0, 1, 2, 3}) << " mm; noisy sensor sigma "
            << sol.sensors[4].offset_sigma_m * 1000 << " mm vs "
            << sol.sensors[3].offset_sigma_m * 1000 << " mm\n";
  // The noisy sensor is found noisier than its good sibling.
  EXPECT_GT(sol.sensors[4].offset_sigma_m, sol.sensors[3].offset_sigma_m);
}

// The same with one of the rig's own LiDARs made 3x noisier.
TEST(MsgGraph, OneLidarThreeTimesNoisier) {
  auto rig = sim::defaultRig();
  rig[3].noise_scale = 3.0;
  const sim::RigScene scene = makeScene(rig, 3);
  const MsgSolution sol = solveMsgGraph(scene.problem, MsgGraphOptions());
  ASSERT_TRUE(sol.success) << sol.reason;
  expectPairsWithin(sol, scene, {0, 1, 2}, kNoisyRotationTolDeg, kNoisyTranslationTolM);
  // The noisy LiDAR's own pairs stay usable too (looser: 3x the noise).
  expectPairsWithin(sol, scene, {0, 1, 2, 3}, 3 * kNoisyRotationTolDeg, 3 * kNoisyTranslationTolM);
}

// Issue 13 item 4: each camera <- LiDAR pair of the graph fits the image edges about as well as a
// PBPC solve of that pair alone (MLRE within 1.3x), with a 3x-noise LiDAR in the graph, while
// the stereo pair stays within the issue-9 tolerance. PBPC minimises the line residuals of its
// pair alone, so its MLRE is the floor; the graph balances every sensor. Measured over 5 scenes
// (bench_msg_graph --only-pairs): ratio mean 1.06, max 1.18.
TEST(MsgGraph, CameraLidarPairsFitTheImageEdgesAsWellAsTheirPbpcSolve) {
  constexpr double kMaxMlreRatio = 1.3;
  auto rig = sim::defaultRig();
  rig.push_back(sim::extraLidar16("vlp16_noisy", 3.0));
  const sim::RigScene scene = makeScene(rig, 4);
  MsgGraphOptions options;
  options.compute_covariance = false;
  const MsgSolution sol = solveMsgGraph(scene.problem, options);
  ASSERT_TRUE(sol.success) << sol.reason;
  SolverOptions pbpc_options;
  pbpc_options.compute_covariance = false;
  for (int c = 0; c < 2; ++c)
    for (int l = 2; l < 5; ++l) {
      std::vector<View> views;
      for (const auto& pose : scene.problem.poses) {
        View v;
        v.id = pose.id;
        v.camera = pose.cameras.at(c);
        v.lidar = pose.lidars.at(l);
        views.push_back(v);
      }
      const CalibrationSolution pbpc = calibrate(views, Method::kPbpc, pbpc_options);
      ASSERT_TRUE(pbpc.success) << pbpc.reason;
      const auto graph_mlre = pairMlrePx(scene.problem, c, l, *sensorTSensor(sol, c, l));
      const auto pbpc_mlre = meanLineReprojectionErrorPx(views, pbpc.camera_T_lidar);
      ASSERT_TRUE(graph_mlre && pbpc_mlre);
      EXPECT_LT(*graph_mlre, kMaxMlreRatio * *pbpc_mlre)
          << scene.sensors[c].frame << " <- " << scene.sensors[l].frame << ": graph " << *graph_mlre
          << " px, PBPC " << *pbpc_mlre << " px";
    }
  const auto stereo = stereoConsistency(sol, 0, 1, scene.sensors[1].reference_T_sensor);
  ASSERT_TRUE(stereo.ok()) << stereo.error();
  EXPECT_LT(stereo->rotation_deg, kPairRotationTolDeg);
  EXPECT_LT(stereo->translation_mm, 1000 * kPairTranslationTolM);
}

// 100% convergence from the pairwise initialisation over independent rigs (fresh noise and
// board poses each time).
TEST(MsgGraph, ConvergesFromPairwiseInitialisationEveryTime) {
  constexpr int kScenes = 5;
  int ok = 0;
  for (int i = 0; i < kScenes; ++i) {
    const sim::RigScene scene = makeScene(sim::defaultRig(), 100 + i);
    const MsgSolution sol = solveMsgGraph(scene.problem, MsgGraphOptions());
    if (sol.success && maxPairRotationDeg(sol, scene, {0, 1, 2, 3}) < kPairRotationTolDeg &&
        maxPairTranslationM(sol, scene, {0, 1, 2, 3}) < kPairTranslationTolM)
      ++ok;
  }
  EXPECT_EQ(ok, kScenes);
}

// Random starts (sigma 90 deg per rotation axis, 50 cm per translation axis, applied to every
// non-reference sensor): >= 95% reach the pairwise-initialised solution.
TEST(MsgGraph, ConvergesFromRandomStarts) {
  const sim::RigScene scene = makeScene(sim::defaultRig(), 4);
  MsgGraphOptions options;
  options.compute_covariance = false;
  const MsgSolution reference = solveMsgGraph(scene.problem, options);
  ASSERT_TRUE(reference.success) << reference.reason;
  constexpr int kTrials = 40;
  // The same minimum: far below the accuracy targets.
  constexpr double kSameDeg = 0.01, kSameM = 0.001;
  std::mt19937 rng(7);
  int converged = 0;
  for (int trial = 0; trial < kTrials; ++trial) {
    std::vector<Eigen::Isometry3d> start;
    for (int s = 0; s < 4; ++s)
      start.push_back(
          s == 0 ? Eigen::Isometry3d::Identity()
                 : perturb(scene.sensors[s].reference_T_sensor, 90.0 * kRadPerDeg, 0.5, rng));
    const MsgSolution sol = solveMsgGraph(scene.problem, options, start);
    EXPECT_FALSE(sol.used_pairwise_init);
    bool same = sol.success;
    for (int s = 1; s < 4 && same; ++s)
      same = rotationErrorDeg(sol.sensors[s].reference_T_sensor,
                              reference.sensors[s].reference_T_sensor) < kSameDeg &&
             translationErrorM(sol.sensors[s].reference_T_sensor,
                               reference.sensors[s].reference_T_sensor) < kSameM;
    converged += same ? 1 : 0;
  }
  std::cout << "random starts converged: " << converged << " / " << kTrials << "\n";
  EXPECT_GE(converged, static_cast<int>(std::ceil(0.95 * kTrials)));
}

// Two groups of sensors that never saw the same board pose: refused with the unreachable ones.
TEST(MsgGraph, DisconnectedGraphIsRefusedWithReason) {
  sim::RigScene scene = makeScene(sim::defaultRig(), 5, 20);
  for (size_t p = 0; p < scene.problem.poses.size(); ++p) {
    auto& pose = scene.problem.poses[p];
    if (p % 2 == 0) {
      pose.lidars.clear();  // cameras only
    } else {
      pose.cameras.clear();  // LiDARs only
    }
  }
  const MsgSolution sol = solveMsgGraph(scene.problem, MsgGraphOptions());
  EXPECT_FALSE(sol.success);
  EXPECT_NE(sol.reason.find("disconnected"), std::string::npos) << sol.reason;
  EXPECT_NE(sol.reason.find("vlp32c"), std::string::npos) << sol.reason;
  EXPECT_NE(sol.reason.find("os1_64"), std::string::npos) << sol.reason;
}

TEST(MsgGraph, DegenerateInputGivesReasons) {
  sim::RigScene scene = makeScene(sim::defaultRig(), 6, 10);
  // No sensors / one sensor.
  MsgProblem empty;
  EXPECT_FALSE(solveMsgGraph(empty, MsgGraphOptions()).success);
  // Bad reference index.
  MsgProblem bad_ref = scene.problem;
  bad_ref.reference_sensor = 9;
  auto r = solveMsgGraph(bad_ref, MsgGraphOptions());
  EXPECT_FALSE(r.success);
  EXPECT_NE(r.reason.find("reference_sensor"), std::string::npos) << r.reason;
  // A LiDAR observation filed under a camera.
  MsgProblem wrong_kind = scene.problem;
  wrong_kind.poses[0].lidars[0] = wrong_kind.poses[0].lidars.begin()->second;
  r = solveMsgGraph(wrong_kind, MsgGraphOptions());
  EXPECT_FALSE(r.success);
  EXPECT_NE(r.reason.find("is a camera"), std::string::npos) << r.reason;
  // Every board pose with the same orientation: plane-to-plane cannot fix the poses.
  MsgProblem parallel = scene.problem;
  for (auto& pose : parallel.poses) {
    for (auto& [s, f] : pose.cameras)
      f.plane.normal = scene.problem.poses[0].cameras.at(s).plane.normal;
    for (auto& [s, f] : pose.lidars)
      f.plane.normal = scene.problem.poses[0].lidars.at(s).plane.normal;
  }
  MsgGraphOptions no_corners;
  no_corners.use_corner_terms = false;
  r = solveMsgGraph(parallel, no_corners);
  EXPECT_FALSE(r.success);
  EXPECT_NE(r.reason.find("parallel"), std::string::npos) << r.reason;
  // Non-finite planes are skipped with a note, not a crash.
  MsgProblem nan_plane = scene.problem;
  nan_plane.poses[1].lidars.begin()->second.plane.offset = std::nan("");
  r = solveMsgGraph(nan_plane, MsgGraphOptions());
  EXPECT_TRUE(r.success) << r.reason;
  EXPECT_FALSE(r.notes.empty());
  // A wrong-sized initial guess.
  r = solveMsgGraph(scene.problem, MsgGraphOptions(), std::vector<Eigen::Isometry3d>(2));
  EXPECT_FALSE(r.success);
  EXPECT_NE(r.reason.find("initial guess"), std::string::npos) << r.reason;
  // Invalid options.
  MsgGraphOptions bad;
  bad.min_shared_views = 1;
  r = solveMsgGraph(scene.problem, bad);
  EXPECT_FALSE(r.success);
  EXPECT_NE(r.reason.find("min_shared_views"), std::string::npos) << r.reason;
}

// Gross errors (a wrong LiDAR plane offset, a camera pose from a mis-detection) are rejected
// and the accuracy holds.
TEST(MsgGraph, OutlierObservationsAreRejected) {
  sim::RigScene scene = makeScene(sim::defaultRig(), 8);
  const std::vector<int> corrupted_lidar_poses = {3, 11, 25};
  for (int p : corrupted_lidar_poses) scene.problem.poses[p].lidars.at(2).plane.offset += 0.15;
  auto& cam = scene.problem.poses[17].cameras.at(1);
  cam.plane.normal =
      (Eigen::AngleAxisd(10 * kRadPerDeg, Eigen::Vector3d::UnitX()) * cam.plane.normal)
          .normalized();
  for (auto& c : cam.pattern) c.pixel += Eigen::Vector2d(25.0, -15.0);
  const MsgSolution sol = solveMsgGraph(scene.problem, MsgGraphOptions());
  ASSERT_TRUE(sol.success) << sol.reason;
  expectPairsWithin(sol, scene, {0, 1, 2, 3}, kPairRotationTolDeg, kPairTranslationTolM);
  auto rejected = [&](int pose, int sensor) {
    for (const auto& r : sol.rejected)
      if (r.pose_id == pose && r.sensor == sensor) return true;
    return false;
  };
  for (int p : corrupted_lidar_poses) EXPECT_TRUE(rejected(p, 2)) << "pose " << p;
  EXPECT_TRUE(rejected(17, 1));
  // Nothing else (a handful of false alarms would still be acceptable; none are expected).
  EXPECT_LE(sol.rejected.size(), corrupted_lidar_poses.size() + 2);
}

// PBPC line terms are on by default (measured better, docs/BENCHMARKS.md); the graph meets the
// targets without them too, and with them the LiDAR edges fit the image lines at least as well.
TEST(MsgGraph, LineTermsOptional) {
  const sim::RigScene scene = makeScene(sim::defaultRig(), 9);
  const MsgSolution with_lines = solveMsgGraph(scene.problem, MsgGraphOptions());
  ASSERT_TRUE(with_lines.success) << with_lines.reason;
  EXPECT_GT(with_lines.residuals.line_terms, 0);
  MsgGraphOptions no_lines;
  no_lines.use_line_terms = false;
  const MsgSolution without = solveMsgGraph(scene.problem, no_lines);
  ASSERT_TRUE(without.success) << without.reason;
  EXPECT_EQ(without.residuals.line_terms, 0);
  expectPairsWithin(with_lines, scene, {0, 1, 2, 3}, kPairRotationTolDeg, kPairTranslationTolM);
  expectPairsWithin(without, scene, {0, 1, 2, 3}, kPairRotationTolDeg, kPairTranslationTolM);
  for (int c = 0; c < 2; ++c)
    for (int l = 2; l < 4; ++l) {
      const auto m_with = pairMlrePx(scene.problem, c, l, *sensorTSensor(with_lines, c, l));
      const auto m_without = pairMlrePx(scene.problem, c, l, *sensorTSensor(without, c, l));
      ASSERT_TRUE(m_with && m_without);
      // The line terms minimise what MLRE measures; 0.05 px slack for the robust loss.
      EXPECT_LT(*m_with, *m_without + 0.05) << c << "<->" << l;
    }
}

// The fixed sensor is a choice of frame, not of answer: a LiDAR as the reference gives the same
// relative poses (to well below the accuracy targets).
TEST(MsgGraph, ReferenceSensorChoiceDoesNotChangeTheRelativePoses) {
  sim::RigScene scene = makeScene(sim::defaultRig(), 11, 25);
  const MsgSolution camera_ref = solveMsgGraph(scene.problem, MsgGraphOptions());
  scene.problem.reference_sensor = 3;
  const MsgSolution lidar_ref = solveMsgGraph(scene.problem, MsgGraphOptions());
  ASSERT_TRUE(camera_ref.success && lidar_ref.success) << camera_ref.reason << lidar_ref.reason;
  EXPECT_TRUE(lidar_ref.sensors[3].reference_T_sensor.isApprox(Eigen::Isometry3d::Identity()));
  for (int a = 0; a < 4; ++a)
    for (int b = a + 1; b < 4; ++b) {
      const Eigen::Isometry3d x = *sensorTSensor(camera_ref, a, b),
                              y = *sensorTSensor(lidar_ref, a, b);
      EXPECT_LT(rotationErrorDeg(x, y), 0.01);
      EXPECT_LT(translationErrorM(x, y), 0.001);
    }
  // The result file names the LiDAR as the reference frame.
  EXPECT_EQ(msgResultFile(scene.problem, lidar_ref).reference_frame, "os1_64");
}

TEST(MsgGraph, ResultFileListsEverySensorAndPair) {
  const sim::RigScene scene = makeScene(sim::defaultRig(), 10, 20);
  const MsgSolution sol = solveMsgGraph(scene.problem, MsgGraphOptions());
  ASSERT_TRUE(sol.success) << sol.reason;
  const ResultFile file = msgResultFile(scene.problem, sol);
  EXPECT_EQ(file.method, "msg");
  EXPECT_EQ(file.reference_frame, "camera_left");
  ASSERT_EQ(file.sensors.size(), 4u);
  ASSERT_EQ(file.pairs.size(), 4u);  // 2 cameras x 2 LiDARs
  // A pair with the reference camera reduces to the LiDAR's own pose covariance.
  for (const PairEstimate& pair : sol.pairs) {
    ASSERT_TRUE(pair.has_covariance);
    if (pair.camera == sol.reference_sensor) {
      EXPECT_TRUE(pair.covariance.isApprox(sol.sensors[pair.lidar].covariance, 1e-9));
    }
  }
  for (const auto& pair : file.pairs) {
    ASSERT_TRUE(pair.stddev.has_value());
    EXPECT_GT(pair.stddev->translation_m.minCoeff(), 0.0);
    ASSERT_TRUE(pair.mlre_px.has_value());
    // Synthetic lines carry 0.3 px noise and edge points sit up to one step inside the edge:
    // a few px at most (the paper's MSG figures were 2.6-11.8 px).
    EXPECT_LT(*pair.mlre_px, 5.0) << pair.camera_frame << "<->" << pair.lidar_frame;
  }
  const auto parsed = parseResult(resultToYaml(file));
  ASSERT_TRUE(parsed.ok()) << parsed.error();
  ASSERT_EQ(parsed->sensors.size(), 4u);
  ASSERT_EQ(parsed->pairs.size(), 4u);
  for (size_t i = 0; i < 4; ++i) {
    EXPECT_EQ(parsed->pairs[i].camera_frame, file.pairs[i].camera_frame);
    EXPECT_LT(rotationErrorDeg(parsed->pairs[i].camera_T_lidar, file.pairs[i].camera_T_lidar),
              1e-3);
    EXPECT_LT(translationErrorM(parsed->pairs[i].camera_T_lidar, file.pairs[i].camera_T_lidar),
              1e-5);
  }
}

}  // namespace
}  // namespace multi_sensor
}  // namespace board_calib
