// SPDX-License-Identifier: BSD-3-Clause
// Test support: a simulated recording run through the offline pipeline frame by frame, with
// the capture scored against the simulator's ground truth (which frames were still, which
// pose each belongs to).
#pragma once

#include <board_calib/core/pipeline/pipeline.h>
#include <board_calib/core/sim/scenario.h>

#include <string>
#include <vector>

namespace board_calib {
namespace test_support {

struct SimulatedSession {
  int holds = 0;           ///< held poses in the recording
  int prepass_frames = 0;  ///< offline pre-pass of the static scene: images, what is static
  int prepass_static_rectangles = 0, prepass_static_lines = 0;
  int holds_captured =
      0;  ///< holds that gave a view whose image and cloud are still frames of that hold
  int moving_captured =
      0;                 ///< views with a frame taken while the board moved (or from another hold)
  int images = 0;        ///< camera frames fed
  int images_true = 0;   ///< ... whose board (alone or by the second chance) is the true board
  int images_wrong = 0;  ///< ... whose board is another object (centre off by > a quarter of the
                         ///< true board's size in the image)
  std::vector<View> views;
  std::string capture_summary;
  ResultFile truth;
  double seconds = 0.0;  ///< simulation and pipeline, wall
};

/// `base` with its first camera scaled by `image_scale` (size and focal length) at `camera_hz`,
/// 2 grey levels of image noise, the first LiDAR organized with a ring field or not, `poses`
/// holds, and every frame emitted (holds and moves): a capture test's recording.
sim::Scenario captureScenario(const sim::Scenario& base, double image_scale, double camera_hz,
                              bool organized, int poses, unsigned seed);

/// Simulates `scenario` (first camera, first LiDAR) and feeds every frame in stamp order.
Expected<SimulatedSession> runSimulatedSession(const sim::Scenario& scenario,
                                               const PipelineOptions& options);

}  // namespace test_support
}  // namespace board_calib
