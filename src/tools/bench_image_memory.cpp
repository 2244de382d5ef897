// Benchmark of the image session memory live (ImageBoardTracker): the simulated street
// (plain_vlp16_outdoor_far, 1440x1080) at a camera rate for about a minute, every frame through
// the tracker in time order. Prints per 10 s of session: places and lines remembered, static
// lines, the memory's own time per frame (ImageBoardTracker::memoryMs) and the whole detect().
// Usage (from the package root): bench_image_memory [--hz 10] [--seconds 60] [--seed 21]
#include <board_calib/core/image_detection/image_board_tracker.h>
#include <board_calib/core/sim/scenario.h>
#include <board_calib/core/sim/simulator.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

namespace {

double percentile(std::vector<double> v, double q) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v[static_cast<size_t>(std::lround(q * static_cast<double>(v.size() - 1)))];
}

}  // namespace

int main(int argc, char** argv) {
  using namespace board_calib;
  double hz = 10.0, seconds = 60.0;
  unsigned seed = 21;
  for (int i = 1; i + 1 < argc; ++i) {
    if (std::strcmp(argv[i], "--hz") == 0) hz = std::max(0.1, std::atof(argv[i + 1]));
    if (std::strcmp(argv[i], "--seconds") == 0) seconds = std::max(1.0, std::atof(argv[i + 1]));
    if (std::strcmp(argv[i], "--seed") == 0) seed = static_cast<unsigned>(std::atoi(argv[i + 1]));
  }
  auto loaded = sim::loadScenario("config/scenarios/plain_vlp16_outdoor_far.yaml");
  if (!loaded) {
    std::fprintf(stderr, "bench_image_memory: %s (run from the package root)\n",
                 loaded.error().c_str());
    return 1;
  }
  sim::Scenario s = *loaded;
  s.seed = seed;
  s.cameras.front().rate_hz = hz;
  s.motion.still_frames_per_hold = 0;  // every frame of the holds and the moves
  s.motion.frames_per_move = -1;
  // Enough poses for `seconds` (a hold and a move each).
  const double per_pose_s = s.motion.hold_s + 1.0;
  s.motion.poses = std::max(1, static_cast<int>(std::ceil(seconds / per_pose_s)));
  auto timeline = sim::makeTimeline(s);
  auto gen = sim::FrameGenerator::create(s);
  auto tracker = ImageBoardTracker::create(s.scene.target, {});
  if (!timeline || !gen || !tracker) {
    std::fprintf(stderr, "bench_image_memory: cannot set up the street\n");
    return 1;
  }
  const CameraModel& camera = gen->cameraModel(0);
  std::vector<double> memory_ms, detect_ms;
  double next_report = 10.0, t0 = -1.0;
  std::printf("street seed %u, %.0f Hz, %dx%d\n", seed, hz, camera.width(), camera.height());
  for (size_t i = 0; i < timeline->frames.size(); ++i) {
    const sim::Frame& f = timeline->frames[i];
    if (!f.is_camera || f.sensor != 0) continue;
    if (t0 < 0) t0 = f.stamp;
    if (f.stamp - t0 > seconds) break;
    const cv::Mat image = gen->image(f, i);
    const auto start = std::chrono::steady_clock::now();
    tracker->detect(image, camera, f.stamp);
    detect_ms.push_back(
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start)
            .count());
    memory_ms.push_back(tracker->memoryMs());
    if (f.stamp - t0 >= next_report) {
      std::printf(
          "t %5.1f s, %4zu frames: places %d, lines %d (static %d); memory %.2f ms median %.2f "
          "ms p95, detect %.0f ms median\n",
          f.stamp - t0, detect_ms.size(), tracker->numPlaces(), tracker->numRememberedLines(),
          tracker->numStaticLines(), percentile(memory_ms, 0.5), percentile(memory_ms, 0.95),
          percentile(detect_ms, 0.5));
      std::fflush(stdout);  // progress of a long run
      next_report += 10.0;
    }
  }
  std::printf(
      "all %zu frames: memory %.2f ms median, %.2f ms p95, %.2f ms max; detect %.0f ms "
      "median, %.0f ms p95\n",
      detect_ms.size(), percentile(memory_ms, 0.5), percentile(memory_ms, 0.95),
      percentile(memory_ms, 1.0), percentile(detect_ms, 0.5), percentile(detect_ms, 0.95));
  return 0;
}
