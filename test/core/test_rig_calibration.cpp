// The rig run (core/pipeline/rig_calibration.h): a clean synthetic rig is judged good with
// every pair at the truth, and a fault sweep (too few poses, coplanar poses, a LiDAR that sees
// another object in 30 % of the poses, swapped cameras, a sensor whose stamps pair it with the
// wrong poses, a tag_size declared slightly off) never gives a silent success: each case is failed
// or doubtful with a reason, or every pair lies within 3 sigma of its own reported uncertainty.
#include <board_calib/core/pipeline/rig_calibration.h>
#include <board_calib/core/transform.h>
#include "support/env_seeds.h"
#include "support/synthetic_rig.h"
#include "support/synthetic_views.h"

#include <gtest/gtest.h>

#include <iostream>
#include <map>
#include <random>

namespace board_calib {
namespace {

using multi_sensor::MsgProblem;

struct Scene {
  sim::RigScene scene;
  RigConfig rig;
  Target target;
};

Scene makeScene(unsigned seed, int poses) {
  auto s = sim::defaultRigScene(poses, seed);
  EXPECT_TRUE(s.ok()) << s.error();
  Scene out;
  out.scene = *s;
  out.target = sim::RigSceneOptions().target;
  // The rig file's view of the sensors, with the factory stereo calibration as known extrinsic.
  out.rig = sim::rigConfigOf(out.scene);
  KnownExtrinsic stereo;
  stereo.a = out.scene.sensors[0].frame;
  stereo.b = out.scene.sensors[1].frame;
  stereo.a_T_b =
      out.scene.sensors[0].reference_T_sensor.inverse() * out.scene.sensors[1].reference_T_sensor;
  out.rig.known_extrinsics.push_back(stereo);
  return out;
}

Eigen::Isometry3d truthPair(const Scene& s, int camera, int lidar) {
  return s.scene.sensors[static_cast<size_t>(camera)].reference_T_sensor.inverse() *
         s.scene.sensors[static_cast<size_t>(lidar)].reference_T_sensor;
}

// Every pair within 3 sigma of its reported uncertainty (the norm of the per-axis sigmas).
bool withinReportedSigma(const RigCalibration& run, const Scene& s, std::string* worst) {
  bool ok = true;
  for (const auto& p : run.pairs) {
    const Eigen::Isometry3d truth = truthPair(s, p.camera, p.lidar);
    const double rot = rotationErrorDeg(p.solution.camera_T_lidar, truth);
    const double trans = translationErrorM(p.solution.camera_T_lidar, truth);
    const double rot_sigma = p.verdict.stddev.rotation_deg.norm(),
                 trans_sigma = p.verdict.stddev.translation_m.norm();
    if (rot > 3.0 * rot_sigma || trans > 3.0 * trans_sigma) {
      ok = false;
      *worst += p.camera_frame + " <- " + p.lidar_frame + ": " + std::to_string(rot) + " deg / " +
                std::to_string(trans * 1e3) + " mm against 1 sigma " + std::to_string(rot_sigma) +
                " deg / " + std::to_string(trans_sigma * 1e3) + " mm; ";
    }
  }
  return ok;
}

RigCalibrationOptions fastOptions() {
  RigCalibrationOptions o;
  o.verdict.max_leave_one_out_views = 8;  // 8 folds keep the sweep within the test budget
  o.pbpc_solver = SolverOptions{};        // the synthetic features' settings (edge shift on)
  return o;
}

TEST(RigCalibration, CleanRigIsGoodWithEveryPairAtTheTruth) {
  const Scene s = makeScene(7, 20);
  const RigCalibration run = calibrateRig(s.scene.problem, s.rig, s.target, fastOptions());
  ASSERT_TRUE(run.solution.success) << run.reason;
  EXPECT_EQ(run.verdict, Verdict::kGood) << rigVerdictSummary(run);
  ASSERT_EQ(run.pairs.size(), 4u);
  for (const auto& p : run.pairs) {
    const Eigen::Isometry3d truth = truthPair(s, p.camera, p.lidar);
    // The graph's target on this rig (test_msg_graph): 0.2 deg / 1 cm per pair.
    EXPECT_LT(rotationErrorDeg(p.solution.camera_T_lidar, truth), 0.2)
        << p.camera_frame << " <- " << p.lidar_frame;
    EXPECT_LT(translationErrorM(p.solution.camera_T_lidar, truth), 0.01)
        << p.camera_frame << " <- " << p.lidar_frame;
    EXPECT_TRUE(p.verdict.cross_validation.ran);
  }
  // The result file carries the verdict overall and per pair, and round-trips.
  const auto parsed = parseResult(resultToYaml(run.result));
  ASSERT_TRUE(parsed.ok()) << parsed.error();
  EXPECT_EQ(parsed->verdict, "good");
  ASSERT_EQ(parsed->pairs.size(), 4u);
  for (const auto& p : parsed->pairs) {
    EXPECT_EQ(p.verdict, "good") << p.verdict_reason;
    EXPECT_FALSE(p.verdict_reason.empty());
    ASSERT_TRUE(p.stddev.has_value());
  }
}

// ---- the fault sweep ----

MsgProblem firstPoses(MsgProblem p, size_t n) {
  p.poses.resize(std::min(n, p.poses.size()));
  return p;
}

// A LiDAR that sees another object: in every `every`-th pose its board is another pose's board.
MsgProblem lidarSeesAnotherObject(MsgProblem p, int lidar, int every) {
  const MsgProblem original = p;
  for (size_t i = 0; i < p.poses.size(); i += static_cast<size_t>(every)) {
    const auto& other = original.poses[(i + p.poses.size() / 2) % p.poses.size()];
    if (p.poses[i].lidars.count(lidar) && other.lidars.count(lidar))
      p.poses[i].lidars[lidar] = other.lidars.at(lidar);
  }
  return p;
}

MsgProblem swappedCameras(MsgProblem p) {
  for (auto& pose : p.poses)
    if (pose.cameras.count(0) && pose.cameras.count(1)) std::swap(pose.cameras[0], pose.cameras[1]);
  return p;
}

// Stamps offset by one hold: the sensor's features join the next pose.
MsgProblem stampsOffset(MsgProblem p, int lidar) {
  const MsgProblem original = p;
  for (size_t i = 0; i < p.poses.size(); ++i) {
    const auto& next = original.poses[(i + 1) % p.poses.size()];
    if (next.lidars.count(lidar)) p.poses[i].lidars[lidar] = next.lidars.at(lidar);
  }
  return p;
}

// Every return of the LiDAR `delta` metres long (a range offset): the planes move along their
// views and the graph follows with residuals as the noise predicts; only the edges tell.
MsgProblem rangeOffset(MsgProblem p, int lidar, double delta) {
  for (auto& pose : p.poses)
    if (pose.lidars.count(lidar)) sim::lengthenRanges(&pose.lidars.at(lidar), delta);
  return p;
}

// A tag_size declared off: every camera sees each board at `k` of its distance (its PnP scales
// the pose's depth, its plane's offset with it). The graph takes tag_size as exact.
MsgProblem cameraDepthsScaled(MsgProblem p, double k) {
  for (auto& pose : p.poses)
    for (auto& [id, c] : pose.cameras) {
      c.camera_T_board.translation() *= k;
      c.plane.offset *= k;
    }
  return p;
}

// Coplanar: every pose's board turned back to the first pose's orientation is not possible on
// features; the same board pose repeated (moved along its own plane is invisible to planes).
MsgProblem coplanar(MsgProblem p) {
  for (size_t i = 1; i < p.poses.size(); ++i) {
    const int id = p.poses[i].id;
    p.poses[i] = p.poses[0];
    p.poses[i].id = id;
  }
  return p;
}

TEST(RigCalibration, FaultSweepNeverGivesASilentSuccess) {
  std::map<std::string, std::map<std::string, int>> counts;  // case -> verdict -> count
  std::map<std::string, std::string> reasons;                // case -> the last reason given
  // Development aid: BOARD_CALIB_FAULT_SEEDS="1,2,3" sweeps other worlds.
  for (const unsigned seed : test_support::seedsFromEnv("BOARD_CALIB_FAULT_SEEDS", {3u, 11u})) {
    const Scene s = makeScene(seed, 20);
    const std::vector<std::pair<std::string, MsgProblem>> cases = {
        {"1 pose", firstPoses(s.scene.problem, 1)},
        {"2 poses", firstPoses(s.scene.problem, 2)},
        {"3 poses", firstPoses(s.scene.problem, 3)},
        {"coplanar poses", coplanar(s.scene.problem)},
        {"LiDAR sees another object in 30 % of poses",
         lidarSeesAnotherObject(s.scene.problem, 3, 3)},
        {"swapped cameras", swappedCameras(s.scene.problem)},
        {"LiDAR stamps offset by one hold", stampsOffset(s.scene.problem, 2)},
        {"LiDAR ranges 3 cm long", rangeOffset(s.scene.problem, 2, 0.03)},
        // Off by less than the pairs' scale check names (it names 0.5 %, doubtful, here).
        {"tag_size declared 0.1 % off", cameraDepthsScaled(s.scene.problem, 1.001)},
        {"tag_size declared 0.15 % off", cameraDepthsScaled(s.scene.problem, 0.9985)},
    };
    for (const auto& [name, problem] : cases) {
      const RigCalibration run = calibrateRig(problem, s.rig, s.target, fastOptions());
      ++counts[name][verdictName(run.verdict)];
      reasons[name] =
          run.reason + " [" + std::to_string(run.left_out.size()) + " observations left out]";
      EXPECT_FALSE(run.reason.empty()) << name;
      // A tag_size slightly off is no fault of the data: whatever the verdict, the 1 sigma must
      // hold what it moves (the graph alone takes the size as exact).
      if (name.rfind("tag_size", 0) == 0) {
        std::string worst;
        EXPECT_TRUE(withinReportedSigma(run, s, &worst))
            << name << " (seed " << seed << "): the 1 sigma misses the scale: " << worst;
      }
      if (run.verdict != Verdict::kGood) continue;
      std::string worst;
      EXPECT_TRUE(withinReportedSigma(run, s, &worst))
          << name << " (seed " << seed << "): a good verdict off the truth: " << worst << "\n"
          << rigVerdictSummary(run);
    }
  }
  // The counts for docs/BENCHMARKS.md.
  for (const auto& [name, by_verdict] : counts) {
    std::cout << "| " << name << " |";
    for (const char* v : {"good", "doubtful", "failed"})
      std::cout << " " << (by_verdict.count(v) ? by_verdict.at(v) : 0) << " |";
    std::cout << " " << reasons[name] << " |\n";
  }
  // Too few poses to judge are never good.
  for (const char* few : {"1 pose", "2 poses", "3 poses"}) EXPECT_EQ(counts[few]["good"], 0) << few;
  EXPECT_EQ(counts["coplanar poses"]["good"], 0);
  EXPECT_EQ(counts["swapped cameras"]["good"], 0) << "the known stereo extrinsic must catch it";
}

TEST(RigCalibration, ASensorInFewPosesDoesNotFailTheOtherPairsChecks) {
  // The OS1 took part in 4 of 20 poses only (it stopped publishing). Leaving one of them out
  // cut it off the graph, so that solve failed for every pair and the pairs that never involve
  // the OS1 were called "the result hangs on single views".
  Scene s = makeScene(7, 20);
  const int os1 = 3;
  for (size_t i = 4; i < s.scene.problem.poses.size(); ++i)
    s.scene.problem.poses[i].lidars.erase(os1);
  const RigCalibration run = calibrateRig(s.scene.problem, s.rig, s.target, fastOptions());
  ASSERT_TRUE(run.solution.success) << run.reason;
  for (const auto& p : run.pairs) {
    const std::string name = p.camera_frame + " <- " + p.lidar_frame;
    if (p.lidar == os1) {
      EXPECT_NE(p.verdict.verdict, Verdict::kFailed) << name << ": " << p.verdict.reason;
      continue;
    }
    EXPECT_EQ(p.verdict.cross_validation.failed_solves, 0) << name;
    EXPECT_EQ(p.verdict.verdict, Verdict::kGood) << name << ": " << p.verdict.reason;
    EXPECT_LT(translationErrorM(p.solution.camera_T_lidar, truthPair(s, p.camera, p.lidar)), 0.01)
        << name;
  }
}

TEST(RigCalibration, ASensorTheGraphCannotPlaceIsNamedAndTheOthersAreSolved) {
  // A sensor that saw the board in 0 or 2 poses (rolled, or aimed away) cannot be placed. The
  // whole graph used to fail, so the pairs of the sensors that saw every pose got no result.
  // When that sensor is the reference, the others are the ones linked and it is left out.
  for (const int cut : {0, 1, 2, 3})  // 0: the reference
    for (const size_t kept : {size_t{0}, size_t{2}}) {
      Scene s = makeScene(11, 16);
      const std::string frame = s.scene.sensors[static_cast<size_t>(cut)].frame;
      for (size_t i = kept; i < s.scene.problem.poses.size(); ++i) {
        s.scene.problem.poses[i].cameras.erase(cut);
        s.scene.problem.poses[i].lidars.erase(cut);
      }
      const std::string name = frame + " in " + std::to_string(kept) + " poses";
      const RigCalibration run = calibrateRig(s.scene.problem, s.rig, s.target, fastOptions());
      // Failed: the rig as configured is not calibrated, and the reason says which sensor.
      EXPECT_TRUE(run.failed()) << name;
      EXPECT_NE(run.reason.find("not every sensor could be calibrated: " + frame),
                std::string::npos)
          << name << ": " << run.reason;
      ASSERT_EQ(run.not_calibrated.size(), 1u) << name;
      ASSERT_TRUE(run.solution.success) << name << ": " << run.solution.reason;
      // The others are solved as without that sensor: 2 pairs of the 3 sensors left.
      ASSERT_EQ(run.pairs.size(), 2u) << name;
      for (const auto& p : run.pairs) {
        EXPECT_NE(p.lidar_frame, frame) << name;
        EXPECT_NE(p.camera_frame, frame) << name;
        int camera = -1, lidar = -1;
        for (size_t k = 0; k < s.scene.sensors.size(); ++k) {
          if (s.scene.sensors[k].frame == p.camera_frame) camera = static_cast<int>(k);
          if (s.scene.sensors[k].frame == p.lidar_frame) lidar = static_cast<int>(k);
        }
        EXPECT_EQ(p.verdict.verdict, Verdict::kGood) << name << ": " << p.verdict.reason;
        EXPECT_LT(translationErrorM(p.solution.camera_T_lidar, truthPair(s, camera, lidar)), 0.01)
            << name << ", " << p.camera_frame << " <- " << p.lidar_frame;
      }
      // The stereo check still finds its cameras by name in the smaller graph.
      bool stereo_checked = false;
      for (const auto& f : run.rig_findings)
        stereo_checked |= f.find("against the known extrinsic") != std::string::npos;
      EXPECT_EQ(stereo_checked, cut >= 2) << name;
      EXPECT_EQ(run.reason.find("relative to") != std::string::npos, cut == 0) << run.reason;
      bool noted = false;
      for (const auto& n : run.result.notes) noted |= n.find("not calibrated: " + frame) == 0;
      EXPECT_TRUE(noted) << name;
    }
}

TEST(RigCalibration, EmptyProblemAndBadOptionsFailWithAReason) {
  const Scene s = makeScene(5, 6);
  MsgProblem empty = s.scene.problem;
  empty.poses.clear();
  const RigCalibration none = calibrateRig(empty, s.rig, s.target);
  EXPECT_TRUE(none.failed());
  EXPECT_NE(none.reason.find("no board poses"), std::string::npos) << none.reason;
  RigCalibrationOptions bad;
  bad.loop_sigmas = -1;
  const RigCalibration refused = calibrateRig(s.scene.problem, s.rig, s.target, bad);
  EXPECT_TRUE(refused.failed());
  EXPECT_NE(refused.reason.find("invalid options"), std::string::npos) << refused.reason;
}

}  // namespace
}  // namespace board_calib
