// LiDAR board detector over simulated scenario sessions: far sparse boards outdoors (VLP-16
// without ring) and board-sized clutter indoors, scored against the simulator's ground truth.
#include <board_calib/core/lidar_detection/lidar_board_detector.h>
#include <board_calib/core/sim/scenario.h>
#include <board_calib/core/sim/simulator.h>
#include <board_calib/core/transform.h>

#include <gtest/gtest.h>

#include "lidar_truth.h"
#include "sim_test_helpers.h"
#include "support/env_seeds.h"

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <string>

namespace board_calib {
namespace {

using namespace lidar_truth;

// ------------------------------------------------------------------------------------------
// Scenario sessions: far sparse boards outdoors, board-sized clutter indoors.
// ------------------------------------------------------------------------------------------
struct SessionTally {
  int clouds = 0;      // clouds with >= 3 scan lines on the board (ground truth)
  int found = 0;       // the board found there (plane and centre at the truth)
  int four_edges = 0;  // ... with four valid edges
  int wrong = 0;       // anything else accepted as the board
  int edges_within = 0, edges_measured = 0;
  double sum_edge_ratio = 0.0;
};

// Scan lines with at least two returns entirely on the board (ground truth from the simulator).
int boardScanLines(const LidarCloud& cloud, const std::vector<sim::ReturnOrigin>& origins) {
  std::map<long, int> per_line;
  for (size_t i = 0; i < cloud.points.size(); ++i) {
    if (origins[i] != sim::ReturnOrigin::kBoard) continue;
    const auto& p = cloud.points[i];
    const double el = std::atan2(p.z, std::hypot(p.x, p.y)) / kRadPerDeg;
    ++per_line[std::lround(el * 20)];  // beams are >= 0.33 deg apart, elevation exact to 1e-5 deg
  }
  int lines = 0;
  for (const auto& kv : per_line) lines += kv.second >= 2;
  return lines;
}

SessionTally runSession(const sim::Scenario& scenario, bool stateful, const char* label,
                        double warmup_s = 0.0, const StaticMemoryOptions& memory = {}) {
  auto timeline = sim::makeTimeline(scenario);
  EXPECT_TRUE(timeline.ok()) << timeline.error();
  auto generator = sim::FrameGenerator::create(scenario);
  EXPECT_TRUE(generator.ok());
  SessionTally t;
  if (!timeline.ok() || !generator.ok()) return t;
  const Target& target = scenario.scene.target;
  const Eigen::Isometry3d lidar_T_world = sim::worldTLidar(scenario, 0).inverse();
  LidarBoardTracker tracker(target, {}, memory);
  for (size_t i = 0; i < timeline->frames.size(); ++i) {
    const sim::Frame& frame = timeline->frames[i];
    if (frame.is_camera || frame.sensor != 0) continue;
    std::vector<sim::ReturnOrigin> origins;
    const LidarCloud cloud = generator->cloud(frame, i, &origins);
    const LidarBoardDetection det =
        stateful ? tracker.detect(cloud) : detectLidarBoard(cloud, target);
    const Eigen::Isometry3d lidar_T_board = lidar_T_world * frame.world_T_board;
    const Truth truth = truthOf(target, lidar_T_board);
    const Eigen::Vector3d centre = lidar_T_board * target.center();
    const int lines = boardScanLines(cloud, origins);
    const auto& f = det.features;
    // The board: plane normal within 5 deg and the board points' centroid within half the
    // board's smaller side of its centre (sparse rows sample it unevenly); else a wrong board.
    bool at_board = false;
    if (f.found) {
      Eigen::Vector3d mean = Eigen::Vector3d::Zero();
      for (const auto& p : f.board_points) mean += p;
      mean /= std::max<size_t>(1, f.board_points.size());
      at_board = std::abs(f.plane.normal.dot(truth.plane.normal)) > std::cos(5 * kRadPerDeg) &&
                 (mean - centre).norm() < 0.5 * std::min(target.width, target.height);
      if (!at_board) {
        ++t.wrong;
        std::printf("[%s] cloud %zu: WRONG board at (%.2f %.2f %.2f), truth (%.2f %.2f %.2f)\n",
                    label, i, mean.x(), mean.y(), mean.z(), centre.x(), centre.y(), centre.z());
      }
    }
    if (lines < 3 || frame.stamp < warmup_s) continue;  // wrong boards count from the start
    ++t.clouds;
    if (!at_board) {
      std::printf("[%s] cloud %zu at %.1f m, %d lines: missed: %s\n", label, i, centre.norm(),
                  lines, f.reason.c_str());
      if (std::getenv("LIDAR_TEST_VERBOSE"))
        for (const auto& c : det.candidates) printCandidate(c);
      continue;
    }
    ++t.found;
    if (!f.allEdgesValid()) {
      std::printf("[%s] cloud %zu at %.1f m, %d lines: edges: %s\n", label, i, centre.norm(), lines,
                  f.reason.c_str());
      continue;
    }
    ++t.four_edges;
    // Edge lines: within half the ring spacing at that range (the true edge lies anywhere
    // between a line's extreme and the next, unseen sample; 2 deg x 14 m = 0.49 m for a VLP-16)
    // and at least the 1.5 cm near-range target.
    const double ring_gap = centre.norm() * sampleRingSpacingRad(scenario.lidars[0].spec, centre);
    for (int j = 0; j < kNumEdges; ++j) {
      const double e = edgeLineError(f, j, truth);
      const double tol = std::max(kMaxEdgeLineM, 0.5 * ring_gap);
      ++t.edges_measured;
      t.edges_within += e < tol;
      t.sum_edge_ratio += e / tol;
    }
  }
  std::printf(
      "[%s] clouds with >= 3 lines %d: board found %d, four edges %d, wrong boards %d, edges "
      "within "
      "tolerance %d/%d (mean error / tolerance %.2f)\n",
      label, t.clouds, t.found, t.four_edges, t.wrong, t.edges_within, t.edges_measured,
      t.edges_measured ? t.sum_edge_ratio / t.edges_measured : 0.0);
  return t;
}

sim::Scenario loadShippedScenario(const std::string& name) {
  auto s = sim::loadScenario(std::string(BOARD_CALIB_SOURCE_DIR) + "/config/scenarios/" + name);
  EXPECT_TRUE(s.ok()) << s.error();
  // Development aid: BOARD_CALIB_SCENARIO_SEED draws other worlds (the suite runs the seeds
  // below).
  s->seed = test_support::seedsFromEnv("BOARD_CALIB_SCENARIO_SEED", {s->seed}).front();
  return *s;
}

// Issue 14 targets: VLP-16 without ring, 5-14 m: board in >= 90 % of the clouds with >= 3
// scan lines on it, four edges in >= 80 %, no wrong board.
void expectFarSparseTargets(sim::Scenario s, const std::string& world) {
  s.motion.poses = 30;
  s.motion.frames_per_move = 0;  // still frames: the held board
  s.motion.still_frames_per_hold = 2;
  for (const bool organized : {false, true}) {
    s.lidars[0].spec.organized = organized;
    const std::string label = world + (organized ? " far-organized" : " far-flat");
    const SessionTally t = runSession(s, false, label.c_str());
    ASSERT_GT(t.clouds, 40);
    EXPECT_GE(t.found, (t.clouds * 90 + 99) / 100) << label;
    EXPECT_GE(t.four_edges, (t.clouds * 80 + 99) / 100) << label;
    EXPECT_EQ(t.wrong, 0) << label;
    EXPECT_GE(t.edges_within, (t.edges_measured * 90) / 100) << label;
    if (organized) continue;
    // The session memory is on by default (pipeline, cloud detector nodelet): outdoors, with
    // parked cars and posters in view and a board moving between holds, it must keep every
    // board the single cloud found and accept nothing else.
    const std::string tracked = world + " far-flat-tracker";
    const SessionTally memory = runSession(s, true, tracked.c_str());
    EXPECT_EQ(memory.wrong, 0) << tracked;
    EXPECT_GE(memory.found, t.found) << tracked;
    EXPECT_GE(memory.four_edges, t.four_edges) << tracked;
  }
}

TEST(LidarDetectorScenario, FarSparseBoardOutdoorsWithoutRing) {
  const sim::Scenario s = loadShippedScenario("plain_vlp16_outdoor_far.yaml");
  expectFarSparseTargets(s, "seed " + std::to_string(s.seed));
}

// The same street drawn again (board poses, holder, clutter and noise from another seed). Seed
// 23 holds the board at 5.3 m where its lower half, seen by more lines, grew a voxel region of
// its own (rejected: not rectangular): the scan-line candidate's plane refit then left those
// voxels out as "another plane" and settled on the 30 returns of its top, 0.5 m off the board,
// which was reported found.
TEST(LidarDetectorScenario, FarSparseBoardInAnotherStreet) {
  sim::Scenario s = loadShippedScenario("plain_vlp16_outdoor_far.yaml");
  s.seed = 23;
  expectFarSparseTargets(s, "seed 23");
}

// Board-sized posters, screens, doors and free-standing panels (some rolled like a held board)
// around a VLP-32C. One cloud alone cannot tell them from the board; the stateful detector
// learns over the session that they stay put. Target: no wrong board, and the board found in
// >= 90 % of the clouds once the memory has seen the clutter stay put longer than the longest
// hold (the first static_after_s of the session may be ambiguous, never wrong).
TEST(LidarDetectorScenario, ClutterIsNeverTakenForTheBoard) {
  sim::Scenario s = loadShippedScenario("plain_vlp32c_clutter.yaml");
  s.motion.poses = 16;
  s.motion.still_frames_per_hold = 3;
  s.motion.frames_per_move = 2;
  // The memory calls a place static after static_after_s (6 s) of a 40 s session; until then
  // two board-like places are ambiguous. Rates count from then on; wrong boards from the start.
  const double warmup_s = StaticMemoryOptions().static_after_s;
  const SessionTally single = runSession(s, false, "clutter-single-frame", warmup_s);
  StaticMemoryOptions strict;
  strict.strict_ambiguity = true;
  const SessionTally t = runSession(s, true, "clutter-tracker", warmup_s, strict);
  // The default memory (no strict ambiguity): the single cloud's rules plus the static places.
  const SessionTally lenient = runSession(s, true, "clutter-tracker-default", warmup_s);
  EXPECT_GE(lenient.found, single.found - single.wrong);
  EXPECT_LE(lenient.wrong, single.wrong);
  EXPECT_EQ(t.wrong, 0);
  ASSERT_GT(t.clouds, 55);
  EXPECT_GE(t.found, (t.clouds * 90) / 100);
  EXPECT_GE(t.four_edges, (t.clouds * 85) / 100);
  EXPECT_GE(t.found, single.found - single.wrong)
      << "the memory must not lose boards the single frame found";
}

}  // namespace
}  // namespace board_calib
