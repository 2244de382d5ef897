// Stillness of far boards cut by few scan lines (issue 14 items 2-3 under issue 13's trust
// rule): the street scenario's board held 5-14 m from a VLP-16 without ring (3-8 scan lines on
// it), the camera at 2 Hz, every cloud through the LiDAR detector with its session memory. The
// camera samples are the true board poses (the LiDAR is what judges at 2 Hz: within +-0.25 s of
// an image there is no other image), so these tests measure the LiDAR noise model.
//  - FarHeldBoardsAreStill: images whose whole still window lies inside a hold are judged still.
//  - SlowFarMotionIsMoving: a board moving slowly (0.25-0.4 m/s) or turning at 8-12 m is never
//    judged still.
//  - FarSlideInPlaneIsMoving: a board sliding in its own plane at 0.2-0.4 m/s at 10-12 m is
//    judged moving by the drift fit over the window, where pairs of frames alone do not see it.
#include <board_calib/core/capture/stillness.h>
#include <board_calib/core/lidar_detection/lidar_board_detector.h>
#include <board_calib/core/pipeline/pipeline.h>
#include <board_calib/core/sim/scenario.h>
#include <board_calib/core/sim/simulator.h>
#include <board_calib/core/transform.h>

#include "support/env_seeds.h"
#include "support/sim_session.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <deque>
#include <map>

namespace board_calib {
namespace {

constexpr double kCameraHz = 2.0;

sim::Scenario streetScenario(unsigned seed) {
  auto loaded = sim::loadScenario(std::string(BOARD_CALIB_SOURCE_DIR) +
                                  "/config/scenarios/plain_vlp16_outdoor_far.yaml");
  EXPECT_TRUE(loaded.ok()) << loaded.error();
  return test_support::captureScenario(*loaded, 1.0, kCameraHz, false, 8, seed);
}

// The streams a PairSession judges, filled from simulated frames.
struct Streams {
  std::deque<BoardSample> lidar, camera;
  StreamClock lidar_clock, camera_clock;
  std::vector<StillnessStream> judged() const {
    return {{&lidar, &lidar_clock, "LiDAR"}, {&camera, &camera_clock, "camera"}};
  }
  void addCamera(const sim::Scenario& s, const sim::Frame& f) {
    CameraBoardFeatures c;
    c.found = true;
    c.stamp = f.stamp;
    const CameraIntrinsics& in = s.cameras.front().intrinsics;
    c.K << in.fx, 0, in.cx, 0, in.fy, in.cy, 0, 0, 1;
    c.image_width = in.width;
    c.image_height = in.height;
    c.camera_T_board = sim::worldTCamera(s, 0).inverse() * f.world_T_board;
    c.plane.normal = c.camera_T_board.linear().col(2);
    camera.push_back(boardSampleOf(c, &s.scene.target));
    camera_clock.add(f.stamp);
  }
  // Returns whether the board was found.
  bool addCloud(LidarBoardTracker* tracker, sim::FrameGenerator* gen, const sim::Frame& f,
                size_t index) {
    LidarCloud cloud = gen->cloud(f, index);
    cloud.stamp = f.stamp;
    LidarBoardFeatures l = tracker->detect(cloud).features;
    l.stamp = f.stamp;
    lidar.push_back(boardSampleOf(l));
    lidar_clock.add(f.stamp);
    return lidar.back().found;
  }
};

TEST(StillnessFar, FarHeldBoardsAreStill) {
  const StillnessOptions o = SessionOptions{}.stillness();
  int held = 0, still = 0, holds = 0, holds_still = 0;
  for (const unsigned seed :
       test_support::seedsFromEnv("BOARD_CALIB_STILL_SEEDS", {21u, 22u, 23u, 24u})) {
    const sim::Scenario s = streetScenario(seed);
    auto timeline = sim::makeTimeline(s);
    ASSERT_TRUE(timeline.ok()) << timeline.error();
    auto gen = sim::FrameGenerator::create(s);
    ASSERT_TRUE(gen.ok()) << gen.error();
    const PipelineOptions p;
    LidarBoardTracker tracker(s.scene.target, p.lidar, p.lidar_memory);
    Streams st;
    std::map<double, int> lidar_pose;  // stamp -> hold (-1 moving)
    std::vector<std::pair<double, int>> images;
    for (size_t i = 0; i < timeline->frames.size(); ++i) {
      const sim::Frame& f = timeline->frames[i];
      if (f.sensor != 0) continue;
      if (f.is_camera) {
        st.addCamera(s, f);
        images.emplace_back(f.stamp, f.still ? f.pose : -1);
      } else {
        st.addCloud(&tracker, &*gen, f, i);
        lidar_pose[f.stamp] = f.still ? f.pose : -1;
      }
    }
    std::map<int, int> still_per_hold;
    for (const auto& [stamp, pose] : images) {
      if (pose < 0) continue;
      // Held: every cloud of the still window is a still frame of the same hold.
      bool inside = true;
      for (auto it = lidar_pose.lower_bound(stamp - o.window_s);
           it != lidar_pose.end() && it->first <= stamp + o.window_s; ++it)
        inside = inside && it->second == pose;
      if (!inside) continue;
      const StillnessJudgement j = judgeStillness(st.judged(), stamp, o, true);
      ++held;
      still_per_hold[pose] += 0;  // the hold counts even without a still image
      if (j.state == StillState::kStill) {
        ++still;
        ++still_per_hold[pose];
      } else {
        std::printf("[still far] seed %u %.2f s hold %d: %s: %s\n", seed, stamp, pose,
                    stillStateName(j.state), j.why.c_str());
      }
    }
    for (const auto& [pose, n] : still_per_hold) {
      ++holds;
      holds_still += n > 0;
    }
  }
  std::printf("[still far] held images judged still %d/%d; holds with a still image %d/%d\n", still,
              held, holds_still, holds);
  ASSERT_GE(held, 40);  // 4 seeds x 8 holds x 2 images whose window is inside the hold
  // Measured: 66/68 held images still (the other 2: no LiDAR board in their window) and 31/32
  // holds; with the previous model (centroids, 1 sigma rms / sqrt(n)) 34 of 96 images of holds.
  // A held image may meet a detector's bad frame: 90 % of the images and of the holds asked.
  EXPECT_GE(still, 0.9 * held);
  EXPECT_GE(holds_still, 0.9 * holds);
}

// A board moving at constant speed from a held pose of the street scenario, the LiDAR at its
// 10 Hz and the camera at 2 Hz for 2 s; images at 0.5, 1.0 and 1.5 s judged.
struct SlowMotion {
  const char* name;
  double towards_mps;   ///< m/s along the board normal (towards the sensors when > 0)
  double sideways_mps;  ///< m/s along the board's plane, horizontal
  double turn_dps;      ///< deg/s about the board's vertical in-plane axis
  double up_mps = 0.0;  ///< m/s along the board's plane, its in-plane axis nearest vertical
};

struct MotionCounts {
  int judged = 0, moving = 0, still = 0;
};

// Every held pose of seed 21 whose range from the LiDAR is in [near_m, far_m], each motion,
// judged as a PairSession does; `pairs_only`: also by the judge without the drift fit.
MotionCounts judgeMotions(const std::vector<SlowMotion>& motions, double near_m, double far_m,
                          MotionCounts* pairs_only = nullptr) {
  const StillnessOptions o = SessionOptions{}.stillness();
  StillnessOptions pairs = o;
  pairs.fit_drift = false;
  MotionCounts n;
  // Development aid: BOARD_CALIB_SCENARIO_SEED holds the board in another street.
  const sim::Scenario s =
      streetScenario(test_support::seedsFromEnv("BOARD_CALIB_SCENARIO_SEED", {21u}).front());
  auto timeline = sim::makeTimeline(s);
  EXPECT_TRUE(timeline.ok()) << timeline.error();
  if (!timeline) return n;
  const Eigen::Isometry3d world_T_lidar = sim::worldTLidar(s, 0);
  for (const Eigen::Isometry3d& start : timeline->world_T_board_poses) {
    const double range = (world_T_lidar.inverse() * start.translation()).norm();
    if (range < near_m || range > far_m) continue;
    for (const SlowMotion& m : motions) {
      auto gen = sim::FrameGenerator::create(s);
      EXPECT_TRUE(gen.ok()) << gen.error();
      if (!gen) return n;
      const PipelineOptions p;
      LidarBoardTracker tracker(s.scene.target, p.lidar, p.lidar_memory);
      Streams st;
      // Board axes in the world: x, y in its plane, z its normal (facing the sensors).
      const Eigen::Vector3d normal = start.linear().col(2);
      Eigen::Vector3d sideways = normal.cross(Eigen::Vector3d::UnitZ());
      sideways.normalize();
      const Eigen::Vector3d up = normal.cross(sideways).normalized();
      const Eigen::Vector3d to_sensor =
          (world_T_lidar.translation() - start.translation()).dot(normal) > 0 ? normal : -normal;
      int found = 0;
      for (int k = 0; k <= 20; ++k) {
        sim::Frame f;
        f.stamp = 0.1 * k;
        f.sensor = 0;
        f.world_T_board = start;
        f.world_T_board.translation() +=
            f.stamp * (m.towards_mps * to_sensor + m.sideways_mps * sideways + m.up_mps * up);
        f.world_T_board.linear() =
            Eigen::AngleAxisd(m.turn_dps * kRadPerDeg * f.stamp, up).toRotationMatrix() *
            start.linear();
        found += st.addCloud(&tracker, &*gen, f, static_cast<size_t>(k));
        if (k % 5 == 0) {
          f.is_camera = true;
          st.addCamera(s, f);
        }
      }
      EXPECT_GE(found, 15) << m.name;  // the board is seen, so the test can fail
      for (const double t : {0.5, 1.0, 1.5}) {
        const StillnessJudgement j = judgeStillness(st.judged(), t, o, true);
        ++n.judged;
        n.moving += j.state == StillState::kMoving;
        n.still += j.state == StillState::kStill;
        std::printf("[still far] %.1f m %s at %.1f s: %s: %s\n", range, m.name, t,
                    stillStateName(j.state), j.why.c_str());
        if (!pairs_only) continue;
        const StillnessJudgement jp = judgeStillness(st.judged(), t, pairs, true);
        ++pairs_only->judged;
        pairs_only->moving += jp.state == StillState::kMoving;
        pairs_only->still += jp.state == StillState::kStill;
      }
    }
  }
  return n;
}

TEST(StillnessFar, SlowFarMotionIsMoving) {
  // Slow for a hand-held board: 0.25-0.4 m/s moves it 5-8 cm between the image's cloud and the
  // outer clouds of the +-0.25 s window (0.2 s at 10 Hz), beyond the judge's allowance along the
  // normal (max_translation_m 3 cm + 3 sigma of two plane offsets, ~0.4 cm here): below ~0.18 m/s
  // a board is "still" by that option's own definition, so 0.25 m/s keeps a margin. The turn
  // (30 deg/s: 6 deg in 0.2 s) against max_rotation_deg 1.5 + 3 sigma of two normals (~2.5 deg
  // with 3-5 scan lines). The diagonal move has a component along the normal, as a hand-held
  // board's has; a slide exactly in the board plane: FarSlideInPlaneIsMoving.
  const std::vector<SlowMotion> motions = {{"towards 0.25 m/s", 0.25, 0.0, 0.0},
                                           {"away 0.4 m/s", -0.4, 0.0, 0.0},
                                           {"diagonal 0.4 m/s", 0.28, 0.28, 0.0},
                                           {"turning 30 deg/s", 0.0, 0.0, 30.0}};
  const MotionCounts n = judgeMotions(motions, 8.0, 12.0);
  std::printf("[still far] slow motion at 8-12 m: %d images, moving %d, still %d\n", n.judged,
              n.moving, n.still);
  ASSERT_GE(n.judged, 12);  // at least one held pose at 8-12 m, four motions, three images
  EXPECT_EQ(n.still, 0);    // issue 13: a moving board is never captured
}

TEST(StillnessFar, FarSlideInPlaneIsMoving) {
  // A slide exactly in the board plane at 10-12 m: no pair of frames resolves it below
  // ~0.45 m/s (the edge centres' column sampling allows 7-10 cm between two frames), the fit
  // over the window's 5 clouds does (docs/BENCHMARKS.md "Session 6", drift over the window).
  // Its allowance over the 0.4 s between the outer clouds is max_translation_m 3 cm + 3 x the
  // fit's 1 sigma, measured 1.2-1.4 cm with every edge, 2.2-2.9 cm when some cloud lacks an
  // edge: 7-12 cm. 0.3-0.4 m/s (12-16 cm) is beyond it, so every such image must be moving;
  // 0.2 m/s (8 cm) is inside it when edges are missing, so only counted.
  MotionCounts fast_pairs, slow_pairs;
  const MotionCounts fast = judgeMotions({{"sideways 0.3 m/s", 0.0, -0.3, 0.0},
                                          {"sideways 0.4 m/s", 0.0, 0.4, 0.0},
                                          {"up 0.3 m/s", 0.0, 0.0, 0.0, 0.3}},
                                         10.0, 12.0, &fast_pairs);
  const MotionCounts slow =
      judgeMotions({{"sideways 0.2 m/s", 0.0, 0.2, 0.0}}, 10.0, 12.0, &slow_pairs);
  std::printf(
      "[still far] in-plane slide at 10-12 m, 0.3-0.4 m/s: %d images, moving %d (pairs only "
      "%d); 0.2 m/s: %d images, moving %d (pairs only %d)\n",
      fast.judged, fast.moving, fast_pairs.moving, slow.judged, slow.moving, slow_pairs.moving);
  ASSERT_GE(fast.judged, 9);  // at least one held pose at 10-12 m, three motions, three images
  ASSERT_GE(slow.judged, 3);
  EXPECT_EQ(fast.moving, fast.judged);
  // Measured 33 of 36 with 0.2 m/s (pairs only: 12): 80 % asked, as the 0.2 m/s images at the
  // edge of the allowance may go either way with another sampling.
  EXPECT_GE(fast.moving + slow.moving, 0.8 * (fast.judged + slow.judged));
}

}  // namespace
}  // namespace board_calib
