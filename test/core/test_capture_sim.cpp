// Capture on simulated recordings with the board moving between holds, frames emitted during
// the moves, camera rates from 1 to 30 Hz against a 10 Hz LiDAR, organized clouds with a ring
// field and unorganized ones without (issue 13): every hold captured once, never a moving board,
// and the run's verdict is honest about the result.
#include "support/env_seeds.h"
#include "support/sim_session.h"

#include <board_calib/core/pipeline/pair_calibration.h>
#include <board_calib/core/transform.h>

#include <gtest/gtest.h>

#include <cstdio>
#include <string>

namespace board_calib {
namespace {

struct Config {
  double camera_hz;
  bool organized;
  unsigned seed;
};

// The demo scenario scaled down for test time: 960x600 camera, 2x2 supersampling, 8 holds.
sim::Scenario scenarioFor(const Config& c) {
  auto s = sim::loadScenario(std::string(BOARD_CALIB_SOURCE_DIR) +
                             "/config/scenarios/plain_vlp32c_1920.yaml");
  EXPECT_TRUE(s.ok()) << s.error();
  sim::Scenario out = test_support::captureScenario(*s, 0.5, c.camera_hz, c.organized, 8, c.seed);
  out.cameras.front().render.supersampling = 2;
  return out;
}

}  // namespace

TEST(CaptureSim, EveryHoldOnceNeverAMovingBoard) {
  std::vector<Config> configs{{2.0, true, 3}, {2.0, false, 4}, {30.0, true, 5}, {1.0, false, 6}};
  // Development aid: BOARD_CALIB_CAPTURE_CONFIGS="7:1:11,15:0:12" (camera Hz : organized : seed)
  // runs other rates and worlds instead.
  const std::vector<std::string> other = test_support::envList("BOARD_CALIB_CAPTURE_CONFIGS");
  if (!other.empty()) configs.clear();
  for (const std::string& item : other) {
    Config c{};
    int organized = 0;
    if (std::sscanf(item.c_str(), "%lf:%d:%u", &c.camera_hz, &organized, &c.seed) != 3) continue;
    c.organized = organized != 0;
    configs.push_back(c);
  }
  for (const Config& c : configs) {
    const sim::Scenario scenario = scenarioFor(c);
    auto session = test_support::runSimulatedSession(scenario, PipelineOptions{});
    ASSERT_TRUE(session.ok()) << session.error();
    const auto& s = *session;
    const PairCalibration run = calibratePair(s.views, {Method::kPbpc}, scenario.scene.target,
                                              "camera", "lidar", PairCalibrationOptions{});
    const MethodRun* chosen = run.chosenRun();
    const double rot =
        chosen ? rotationErrorDeg(chosen->solution.camera_T_lidar, s.truth.camera_T_lidar) : -1;
    const double trans =
        chosen ? translationErrorM(chosen->solution.camera_T_lidar, s.truth.camera_T_lidar) : -1;
    std::printf(
        "[capture] camera %4.0f Hz %-11s seed %u: holds %d/%d, moving %d, views %zu, %s, %.3f deg "
        "%.1f mm, %.0f s\n"
        "          %s\n",
        c.camera_hz, c.organized ? "organized" : "unorganized", c.seed, s.holds_captured, s.holds,
        s.moving_captured, s.views.size(), verdictName(run.verdict), rot, trans * 1e3, s.seconds,
        s.capture_summary.c_str());
    EXPECT_EQ(s.moving_captured, 0) << c.camera_hz << " Hz";
    // A 1 Hz camera takes one or two images per 1.5 s hold; one may fall within 0.25 s of a move.
    EXPECT_GE(s.holds_captured, c.camera_hz >= 2.0 ? 8 : 7) << c.camera_hz << " Hz";
    ASSERT_NE(chosen, nullptr) << run.reason;
    EXPECT_NE(run.verdict, Verdict::kFailed) << run.reason;
    // Half-size camera, 8 views: looser than the benchmark's full-size figures, and within the
    // result's own 3 sigma.
    EXPECT_LT(rot, 0.3);
    EXPECT_LT(trans, 0.02);
    for (int i = 0; i < 3; ++i) {
      EXPECT_LT(std::abs((chosen->solution.camera_T_lidar.translation() -
                          s.truth.camera_T_lidar.translation())(i)),
                3 * chosen->verdict.stddev.translation_m(i));
    }
  }
}

}  // namespace board_calib
