// MSG graph on simulated rigs at known ground truth: a stereo pair, a VLP-32C-like and an
// OS1-64-like LiDAR, 40 board poses of a 1 m AprilTag grid (issue 9 targets).
#include <board_calib/core/msg_graph.h>
#include <board_calib/core/msg_synthetic.h>
#include <board_calib/core/transform.h>

#include <gtest/gtest.h>

#include <cmath>

namespace board_calib {
namespace msg {
namespace {

// Issue 9 targets: every pair within 0.2 deg and 1 cm; with a 3x-noise sensor in the graph the
// other pairs within 0.3 deg and 1.5 cm.
constexpr double kPairRotationTolDeg = 0.2;
constexpr double kPairTranslationTolM = 0.01;
constexpr double kNoisyRotationTolDeg = 0.3;
constexpr double kNoisyTranslationTolM = 0.015;

MsgSyntheticScene makeScene(const std::vector<SimSensor>& rig, unsigned seed, int poses = 40) {
  std::mt19937 rng(seed);
  MsgSyntheticOptions opt;
  opt.num_poses = poses;
  auto scene = generateMsgScene(rig, opt, rng);
  EXPECT_TRUE(scene.ok()) << scene.error();
  return *scene;
}

struct PairError {
  double rotation_deg = 0, translation_m = 0;
};

PairError pairError(const MsgSolution& sol, const MsgSyntheticScene& scene, int a, int b) {
  const Eigen::Isometry3d truth = scene.sensors[a].reference_T_sensor.inverse() * scene.sensors[b].reference_T_sensor;
  const Eigen::Isometry3d est = *sensorTSensor(sol, a, b);
  return {rotationErrorDeg(est, truth), translationErrorM(est, truth)};
}

// Every pair among `sensors` within the tolerances.
void expectPairsWithin(const MsgSolution& sol, const MsgSyntheticScene& scene, const std::vector<int>& sensors,
                       double rot_tol_deg, double trans_tol_m) {
  for (size_t i = 0; i < sensors.size(); ++i)
    for (size_t j = i + 1; j < sensors.size(); ++j) {
      const PairError e = pairError(sol, scene, sensors[i], sensors[j]);
      EXPECT_LT(e.rotation_deg, rot_tol_deg) << scene.sensors[sensors[i]].frame << "<->" << scene.sensors[sensors[j]].frame;
      EXPECT_LT(e.translation_m, trans_tol_m) << scene.sensors[sensors[i]].frame << "<->" << scene.sensors[sensors[j]].frame;
    }
}

double maxPairRotationDeg(const MsgSolution& sol, const MsgSyntheticScene& scene, const std::vector<int>& sensors) {
  double m = 0;
  for (size_t i = 0; i < sensors.size(); ++i)
    for (size_t j = i + 1; j < sensors.size(); ++j) m = std::max(m, pairError(sol, scene, sensors[i], sensors[j]).rotation_deg);
  return m;
}
double maxPairTranslationM(const MsgSolution& sol, const MsgSyntheticScene& scene, const std::vector<int>& sensors) {
  double m = 0;
  for (size_t i = 0; i < sensors.size(); ++i)
    for (size_t j = i + 1; j < sensors.size(); ++j)
      m = std::max(m, pairError(sol, scene, sensors[i], sensors[j]).translation_m);
  return m;
}

TEST(MsgGraph, FourSensorRigEveryPairWithinTolerance) {
  const MsgSyntheticScene scene = makeScene(defaultRig(), 1);
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

}  // namespace
}  // namespace msg
}  // namespace board_calib
