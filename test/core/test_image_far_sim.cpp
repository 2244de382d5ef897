// Issue 14: far plain boards (plain_vlp16_outdoor_far: a cardboard-coloured 0.89 x 1.20 m board
// with printed marks and grain, the holder's legs under it, 5-14 m from a 1440x1080 camera, i.e.
// about 120-350 px across). Rendered per still pose of several seeds; each found board's lines are
// compared with the simulator's truth.
//  - FarBoardsOnPlainBackground: the scenario's board, legs and camera without the street: the
//    boards are found with sub-pixel lines (what works).
//  - the street frames, alone and with the session's memory (StreetFramesAddNoWrongBoard; the
//    history per session in docs/BENCHMARKS.md, from "Session 4: far boards in the simulated
//    street"); the street session must end "failed" or right
//    (StreetSessionNeverReportsAWrongCalibration).
#include <board_calib/core/image_detection/image_board_detector.h>
#include <board_calib/core/image_detection/image_board_tracker.h>
#include <board_calib/core/pipeline/pair_calibration.h>
#include <board_calib/core/pipeline/scene_prepass.h>
#include <board_calib/core/sim/scenario.h>
#include <board_calib/core/sim/simulator.h>
#include <board_calib/core/transform.h>

#include "support/env_seeds.h"
#include "support/sim_session.h"

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

namespace board_calib {
namespace {

struct FarResult {
  int poses = 0, found = 0, wrong = 0;
  double worst_line_px = 0.0;  ///< largest distance of a true side's end from its detected line
  std::vector<double> ms;      ///< wall time per frame (detection, and the memory when tracked)
  PlainStageTimes stages;      ///< the detector's time per stage, summed over the frames
};

double percentileMs(std::vector<double> v, double q) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v[static_cast<size_t>(std::lround(q * static_cast<double>(v.size() - 1)))];
}

// Distance of the true side ends from the detected lines (undistorted px), max over the lines.
// A plain board has no marked corner: which side is named UL is the detector's convention, so
// each detected line is matched to the true side it lies on. `sides`, when given, receives per
// detected line the signed offsets of its true side's two ends (a shifted line shows two alike,
// a tilted one two of opposite sign).
double lineErrorPx(const CameraBoardFeatures& f, const std::array<Eigen::Vector2d, 4>& truth,
                   std::string* sides = nullptr) {
  double worst = 0.0;
  for (int j = 0; j < kNumEdges; ++j) {
    const Eigen::Vector3d& l = f.edge_lines[j];
    double best = 1e18, ends[2] = {0, 0};
    for (int k = 0; k < kNumEdges; ++k) {
      double side = 0.0, at[2];
      for (int e = 0; e < 2; ++e) {
        const Eigen::Vector2d& p = truth[e ? k : (k + 3) % 4];
        at[e] = (l.head<2>().dot(p) + l.z()) / l.head<2>().norm();
        side = std::max(side, std::abs(at[e]));
      }
      if (side < best) {
        best = side;
        ends[0] = at[0];
        ends[1] = at[1];
      }
    }
    worst = std::max(worst, best);
    if (sides)
      *sides +=
          cv::format("%s%s %+.1f/%+.1f", sides->empty() ? "" : ", ", edgeName(j), ends[0], ends[1]);
  }
  return worst;
}

// Beyond this a found board is another object: a true board's line is off by at most its bow
// (~3 px for a held board, the edge inlier band); other rectangles were 100-700 px off.
constexpr double kWrongBoardPx = 3.0;

// One still frame per held pose of the scenario with `seed`; prints per frame the board's true
// size in px, the outcome and the reason (the diagnosis table).
// With `tracked`, the frames go through an ImageBoardTracker in time order (session memory of
// static rectangles); with `prepass` too, the tracker knows the static scene learnt first over
// the same frames (ScenePrepass, as calibrate_bag); with `mono`, through the simulator's mono
// camera (BOARD_CALIB_FAR_MONO set: every run's, a development aid). `options` are the
// detector's.
FarResult runScenario(unsigned seed, int poses, bool street,
                      const ImageBoardDetectorOptions& options, bool tracked, bool prepass,
                      bool mono, double noise_sigma) {
  auto loaded = sim::loadScenario(std::string(BOARD_CALIB_SOURCE_DIR) +
                                  "/config/scenarios/plain_vlp16_outdoor_far.yaml");
  EXPECT_TRUE(loaded.ok()) << loaded.error();
  sim::Scenario s = *loaded;
  s.seed = seed;
  s.motion.poses = poses;
  s.cameras.front().render.supersampling = 2;  // test time; edges still anti-aliased
  s.cameras.front().render.mono = mono || std::getenv("BOARD_CALIB_FAR_MONO");
  // Development aid: BOARD_CALIB_FAR_NOISE sets the camera's pixel noise (grey levels; real
  // cameras after compression measure 0.3-0.8, where the faint-line search runs).
  if (noise_sigma >= 0) s.cameras.front().render.noise_sigma = noise_sigma;
  if (const char* noise = std::getenv("BOARD_CALIB_FAR_NOISE"))
    s.cameras.front().render.noise_sigma = std::atof(noise);
  if (!street) {
    s.scene.outdoor = false;
    s.scene.room = false;
  }
  auto timeline = sim::makeTimeline(s);
  EXPECT_TRUE(timeline.ok()) << timeline.error();
  auto gen = sim::FrameGenerator::create(s);
  EXPECT_TRUE(gen.ok()) << gen.error();
  const CameraModel& camera = gen->cameraModel(0);
  auto det = ImageBoardDetector::create(s.scene.target, options);
  EXPECT_TRUE(det.ok()) << det.error();
  auto tracker = ImageBoardTracker::create(s.scene.target, options);
  EXPECT_TRUE(tracker.ok()) << tracker.error();
  const char* debug_dir = std::getenv("BOARD_CALIB_DEBUG_DIR");
  const auto isPoseFrame = [&](const sim::Frame& f, int* last) {
    if (!f.is_camera || !f.still || f.pose < 0 || f.pose == *last) return false;
    *last = f.pose;
    return true;
  };
  FarResult out;
  int last_pose = -1;
  if (prepass && timeline.ok()) {
    auto survey = ScenePrepass::create(s.scene.target, options, {});
    EXPECT_TRUE(survey.ok()) << survey.error();
    for (size_t i = 0; i < timeline->frames.size(); ++i)
      if (isPoseFrame(timeline->frames[i], &last_pose))
        survey->add(gen->image(timeline->frames[i], i), s.cameras.front().intrinsics,
                    timeline->frames[i].stamp);
    tracker->setKnownScene(survey->scene());
    last_pose = -1;
  }
  for (size_t i = 0; timeline.ok() && i < timeline->frames.size(); ++i) {
    const sim::Frame& f = timeline->frames[i];
    if (!isPoseFrame(f, &last_pose)) continue;
    const Eigen::Isometry3d camera_T_board = sim::worldTCamera(s, 0).inverse() * f.world_T_board;
    std::array<Eigen::Vector2d, 4> truth;
    const auto outer = s.scene.target.outerCorners();
    Eigen::Vector2d lo(1e9, 1e9), hi(-1e9, -1e9);
    for (int j = 0; j < kNumEdges; ++j) {
      EXPECT_TRUE(camera.projectUndistorted(camera_T_board * outer[j], &truth[j]));
      lo = lo.cwiseMin(truth[j]);
      hi = hi.cwiseMax(truth[j]);
    }
    const cv::Mat image = gen->image(f, i);
    const auto start = std::chrono::steady_clock::now();
    const ImageDetection d =
        tracked ? tracker->detect(image, camera, f.stamp) : det->detect(image, camera);
    out.ms.push_back(
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start)
            .count());
    ++out.poses;
    out.stages += d.details.stage_times;
    double err = -1.0;
    std::string sides;
    if (d.features.found) {
      err = lineErrorPx(d.features, truth, &sides);
      ++out.found;
      if (err > kWrongBoardPx)
        ++out.wrong;
      else
        out.worst_line_px = std::max(out.worst_line_px, err);
    }
    std::printf("[far] %s seed %u pose %2d %5.1f m %3.0fx%3.0f px: %s", street ? "street" : "plain",
                seed, f.pose, camera_T_board.translation().norm(), hi.x() - lo.x(), hi.y() - lo.y(),
                d.features.found ? "found" : "miss");
    if (d.features.found)
      std::printf(", lines within %.2f px (%s)%s\n", err, d.details.board_source.c_str(),
                  err > kWrongBoardPx
                      ? (" (WRONG board; true side ends from each line, px: " + sides + ")").c_str()
                      : "");
    else
      std::printf(" (%s)\n", d.features.reason.c_str());
    if (debug_dir)
      cv::imwrite(std::string(debug_dir) + "/far_" + (street ? "street_" : "plain_") +
                      (prepass   ? "prepass_"
                       : tracked ? "tracked_"
                                 : "") +
                      std::to_string(seed) + "_" + std::to_string(f.pose) + ".png",
                  drawImageDetection(image, camera, d));
  }
  return out;
}

// The seeds the found/wrong counts are asserted for; BOARD_CALIB_FAR_SEEDS="40,41" runs others by
// hand (a development aid: the assertions then do not apply).
std::vector<unsigned> defaultSeeds() {
  return test_support::seedsFromEnv("BOARD_CALIB_FAR_SEEDS", {14u, 15u, 16u});
}

// `noise_sigma`: the camera's pixel noise, grey levels (negative: the scenario's, 1.5).
FarResult runSeeds(bool street, const ImageBoardDetectorOptions& options = {}, bool tracked = false,
                   bool prepass = false, const std::vector<unsigned>& seeds = defaultSeeds(),
                   bool mono = false, double noise_sigma = -1.0) {
  FarResult all;
  for (unsigned seed : seeds) {
    const FarResult r = runScenario(seed, 8, street, options, tracked, prepass, mono, noise_sigma);
    all.poses += r.poses;
    all.found += r.found;
    all.wrong += r.wrong;
    all.worst_line_px = std::max(all.worst_line_px, r.worst_line_px);
    all.ms.insert(all.ms.end(), r.ms.begin(), r.ms.end());
    all.stages += r.stages;
  }
  std::printf(
      "[far] %s%s%s: found %d/%d, wrong %d, lines within %.2f px of the truth; %.0f ms median, "
      "%.0f ms p95 per frame\n",
      street ? "street" : "plain", mono ? " mono" : "",
      prepass   ? " (pre-pass + tracker)"
      : tracked ? " (tracker)"
                : "",
      all.found, all.poses, all.wrong, all.worst_line_px, percentileMs(all.ms, 0.5),
      percentileMs(all.ms, 0.95));
  std::printf("[far] stages, mean ms per frame: %s\n",
              all.stages.scaled(1.0 / std::max(1, all.poses)).text().c_str());
  return all;
}

}  // namespace

TEST(ImageDetectorFarSim, FarBoardsOnPlainBackground) {
  const FarResult r = runSeeds(false);
  ASSERT_EQ(r.poses, 24);
  // Measured 23/24 true boards (the 24th: the legs' rectangle under the board wins on edge
  // support, docs/BENCHMARKS.md); one more miss allowed for a pose whose lower tip
  // the legs cover.
  EXPECT_GE(r.found - r.wrong, 22);
  // Four sub-pixel lines: measured <= 0.24 px at 120-350 px with 2 grey levels of noise; the
  // issue asks sub-pixel.
  EXPECT_LT(r.worst_line_px, 0.5);
}

// The street frames, one still frame per pose (docs/BENCHMARKS.md, "Session 4: far boards in the
// simulated street" and "Session 5: image session memory"). A frame alone: measured 17 of 24,
// none wrong, since session 14's colour parts (the cardboard departs from the street's median
// colour; 0 of 24 before; 2, both facade rectangles, before session 7's segment detector). Through
// an ImageBoardTracker in time order (the camera frames 2.5 s apart): the first frames are as
// alone; once the static scene is known (6 s), its quadrilaterals are skipped and the line search
// widens; once the frames span 6 s, the session's background is known too, and a board is what
// departs from it, searched in its own colour contrast (the cardboard is the facade's grey):
// measured 9 true boards, 1 wrong (4 and 1 before the background; 16 and 2 with the colour
// parts); with the offline pre-pass over the same frames (scene and background known from the
// first): 17 true, 2 wrong (6 and 2 before; 18 and 2 with the colour parts). What is asserted is
// that the memory adds no wrong board (the hard rule) and keeps what it gains (one true board less
// allowed for the noise of another machine's LSD run; the background's gain is asserted at three
// quarters of what was measured).
TEST(ImageDetectorFarSim, StreetFramesAddNoWrongBoard) {
  const FarResult alone = runSeeds(true);
  const FarResult tracked = runSeeds(true, ImageBoardDetectorOptions{}, true);
  const FarResult prepass = runSeeds(true, ImageBoardDetectorOptions{}, true, true);
  ASSERT_EQ(alone.poses, 24);
  ASSERT_EQ(tracked.poses, 24);
  ASSERT_EQ(prepass.poses, 24);
  EXPECT_LE(prepass.wrong, 1);
  EXPECT_LT(prepass.worst_line_px, 1.5);
  EXPECT_EQ(alone.wrong, 0);
  // Measured 24 of 24 alone and tracked (0 wrong), since the colour parts are opened at a
  // holder's width: the board's part no longer holds the person under it (17, 16 before). With the
  // pre-pass 23 true, 1 wrong (a side 6 px off), since a board of lines alone is challenged in
  // colour (22 and 2 before: the holder's torso). One frame of slack each.
  EXPECT_GE(alone.found, 23);
  EXPECT_LE(tracked.wrong, 2);
  EXPECT_GE(tracked.found - tracked.wrong, 23);
  EXPECT_GE(prepass.found - prepass.wrong, 22);
  // The true boards' lines: sub-pixel to ~1 px at 120-350 px in the street (measured 1.08 px;
  // the kWrongBoardPx bound separates them from other objects).
  EXPECT_LT(tracked.worst_line_px, 1.5);
  // Single frames: within 1 px (issue 14; measured 0.34 px). A board the weak lines found in grey
  // is refitted in its colour contrast when that fits the declared board better: seed 15's board
  // had a side 1.07 px off, its grey edge pulled by the facade behind it.
  EXPECT_LT(alone.worst_line_px, 1.0);
}

// Seeds the other tests never used (docs/BENCHMARKS.md, "Session 21"). Single frames of seeds
// 40-42: in 4 of 24 the back facade's outline (building corners, roof line, ground line) fitted
// the declared board at ~2.4 m and, with more edge support than the board in front of it, was
// taken for it; seeds 46 and 50: the holder's dark torso, a uniform region, fitted a board
// turned ~65 deg (1 frame each); with the pre-pass, seeds 40 and 44: the torso as straight lines
// (1 each). Now a board of lines alone, or a region turned past 45 deg, is challenged in colour:
// 0 wrong everywhere; 38 of 40 and 16 of 16 true boards measured (one of slack each).
TEST(ImageDetectorFarSim, TheFacadeOrTorsoIsNotTakenForTheBoardInFrontOfIt) {
  const FarResult alone = runSeeds(true, {}, false, false, {40u, 41u, 42u, 46u, 50u});
  ASSERT_EQ(alone.poses, 40);
  EXPECT_EQ(alone.wrong, 0);
  EXPECT_GE(alone.found, 37);
  const FarResult prepass = runSeeds(true, {}, true, true, {40u, 44u});
  ASSERT_EQ(prepass.poses, 16);
  EXPECT_EQ(prepass.wrong, 0);
  EXPECT_GE(prepass.found, 15);
  EXPECT_LT(alone.worst_line_px, 1.5);
}

// The street at the noise real cameras measure (0.5 grey levels, not the simulator's 1.5): seed
// 45's pose 4 has the cardboard's lower right side against the facade of its grey. With session
// memory and with the pre-pass, the grey search outlined it by lines alone, that side 7.9 px off
// at its end while the corners fit the declared board to 0.03 px, and kept it: the foreground
// places' colour search found no board, and the place that was the grey board itself was not
// challenged unless weak lines had outlined it. Now a board of lines alone is challenged at its
// own place, and the frame's colour parts follow the foreground places (docs/BENCHMARKS.md,
// "Session 26"). Measured with seeds 14 and 45: 16 of 16 found in each run, none wrong.
TEST(ImageDetectorFarSim, AtARealCamerasNoiseNoSideFollowsTheFacade) {
  constexpr double kRealNoise = 0.5;
  const std::vector<unsigned> seeds = {14u, 45u};
  for (const bool tracked : {false, true})
    for (const bool prepass : {false, true}) {
      if (prepass && !tracked) continue;
      const FarResult r = runSeeds(true, {}, tracked, prepass, seeds, false, kRealNoise);
      ASSERT_EQ(r.poses, 16);
      EXPECT_EQ(r.wrong, 0) << "tracked " << tracked << ", pre-pass " << prepass;
      EXPECT_GE(r.found, 15) << "tracked " << tracked << ", pre-pass " << prepass;
      EXPECT_LT(r.worst_line_px, 1.0);
    }
}

// The same street through the simulator's mono camera (docs/BENCHMARKS.md, "Session 22"): the
// cardboard is the facade's grey, so its sides against the facade vanish and hardly a true board
// is found; what is asserted is how rarely another object passes for it. With a corner fit of 3 %
// of the side, facade outlines, a door and the holder's torso passed; at 1 % (true boards fit to
// <= 0.54 % here, <= 0.73 % on the augmented real frames) fewer do (figures for seeds 40-63 in
// docs/BENCHMARKS.md). On the seeds below, single frames 4 wrong at 3 %, 0 at 1 %; with the
// pre-pass 1 and 0. A weak lines' quadrilateral with an open corner (both its lines stop short of
// it) took a dark window for the board here (seed 40 pose 3) while its sides could run on past
// their other corners.
TEST(ImageDetectorFarSim, AMonoCameraRarelyTakesAnotherObjectForTheBoard) {
  const FarResult alone = runSeeds(true, {}, false, false, {40u, 41u, 42u, 46u, 50u}, true);
  ASSERT_EQ(alone.poses, 40);
  EXPECT_EQ(alone.wrong, 0);
  const FarResult prepass = runSeeds(true, {}, true, true, {40u, 44u}, true);
  ASSERT_EQ(prepass.poses, 16);
  EXPECT_EQ(prepass.wrong, 0);
}

// The street sessions both session tests run; BOARD_CALIB_STREET_SEEDS="30,31" runs others by
// hand.
std::vector<unsigned> streetSessionSeeds() {
  return test_support::seedsFromEnv("BOARD_CALIB_STREET_SEEDS", {21u, 22u, 24u});
}

// One street session of `seed` (through a mono camera with `mono`): printed, and when not failed
// its result checked against the truth within 3 sigma (the issue-10 promise). Returns whether it
// failed.
bool streetSessionFailedOrTrue(unsigned seed, bool mono) {
  auto loaded = sim::loadScenario(std::string(BOARD_CALIB_SOURCE_DIR) +
                                  "/config/scenarios/plain_vlp16_outdoor_far.yaml");
  EXPECT_TRUE(loaded.ok()) << loaded.error();
  if (!loaded.ok()) return false;
  // Full-size camera (the board is 120-350 px only at 1440x1080), 2 Hz, the VLP-16 without ring
  // and unorganized, 8 holds, every frame of holds and moves; the defaults: image memory and its
  // offline pre-pass, as calibrate_bag (each run is ~8-15 s).
  sim::Scenario s = test_support::captureScenario(*loaded, 1.0, 2.0, false, 8, seed);
  s.cameras.front().render.mono = mono;
  auto session = test_support::runSimulatedSession(s, PipelineOptions{});
  EXPECT_TRUE(session.ok()) << session.error();
  if (!session.ok()) return false;
  const char* camera = mono ? "mono" : "colour";
  std::printf(
      "[far street] %s seed %u: pre-pass %d frames, static %d rectangles, %d lines; %.1f s\n",
      camera, seed, session->prepass_frames, session->prepass_static_rectangles,
      session->prepass_static_lines, session->seconds);
  std::printf("[far street] %s seed %u: images %d: true board %d, wrong %d, none %d\n", camera,
              seed, session->images, session->images_true, session->images_wrong,
              session->images - session->images_true - session->images_wrong);
  std::printf("[far street] %zu views; capture: %s\n", session->views.size(),
              session->capture_summary.c_str());
  const PairCalibration run =
      calibratePair(session->views, {Method::kPbpc}, s.scene.target, "camera", "lidar");
  std::printf("[far street] verdict %s: %s\n", verdictName(run.verdict), run.reason.c_str());
  if (run.failed()) {
    EXPECT_FALSE(run.reason.empty());  // a failure says why
    return true;
  }
  const Eigen::Isometry3d& T = run.chosenRun()->solution.camera_T_lidar;
  const ResultFile& truth = session->truth;
  const PoseStddev& sd = run.chosenRun()->verdict.stddev;
  const double rot = rotationErrorDeg(T, truth.camera_T_lidar);
  const double trans = translationErrorM(T, truth.camera_T_lidar);
  std::printf("[far street] error %.3f deg %.1f mm, 1 sigma %.3f deg %.1f mm\n", rot, trans * 1e3,
              sd.rotation_deg.norm(), sd.translation_m.norm() * 1e3);
  // Not failed: the truth within 3 sigma of the reported result (plus 0.05 deg / 5 mm for the
  // simulator's own rendering and scan bias).
  EXPECT_LE(rot, 3.0 * sd.rotation_deg.norm() + 0.05) << camera << " seed " << seed;
  EXPECT_LE(trans, 3.0 * sd.translation_m.norm() + 0.005) << camera << " seed " << seed;
  return false;
}

// The street session (docs/BENCHMARKS.md, "Session 5: image session memory"): what must hold is
// the issue-10 promise: a session of such frames, through the whole pair pipeline (image session
// memory, stillness, consistency, PBPC, verdict), either says "failed" or gives an extrinsic that
// agrees with the truth within its own uncertainty, never a wrong one as a success. Printed per
// run: images whose board is the true one, another object, or none; with the image memory and
// its offline pre-pass (the defaults of calibrate_bag). Seed 21 calibrates (measured: doubtful,
// 3 views, 0.145 deg / 12.1 mm, within 3 sigma, since session 6's stillness model): asserted.
// Seed 24 (5 views since session 6) once came out doubtful, 138 mm off with a 1 sigma of 0 (no
// covariance, too few views to cross-validate), then failed with its reason; since session 7's
// segment detector (one wrong image board fewer, 4 views) it is doubtful, 0.79 deg / 80 mm off
// with a 1 sigma of 0.26 deg / 38 mm: within the bound below, near it in rotation.
TEST(ImageDetectorFarSim, StreetSessionNeverReportsAWrongCalibration) {
  for (const unsigned seed : streetSessionSeeds()) {
    const bool failed = streetSessionFailedOrTrue(seed, false);
    if (seed == 21) {
      EXPECT_FALSE(failed);
    }
  }
}

// The same sessions through a mono camera (docs/BENCHMARKS.md, "Session 22"): the board's sides
// against the facade of its grey vanish, so few images hold it (measured 7, 4 and 8 of 38, with
// 1, 1 and 0 other objects taken); every session must fail with its reason or agree with the
// truth. Measured: all three fail ("2 usable views", "only 1 usable view", "no three views
// agree on one rigid motion").
TEST(ImageDetectorFarSim, MonoStreetSessionNeverReportsAWrongCalibration) {
  for (const unsigned seed : streetSessionSeeds()) streetSessionFailedOrTrue(seed, true);
}

}  // namespace board_calib
