// bench_sim: generation time of the simulator per frame and per scenario (no bag writing, so
// the figures are the simulator's own cost).
//   rosrun board_calib bench_sim [--poses N] SCENARIO.yaml...
// Default scenarios: config/scenarios/*.yaml relative to the working directory.
#include <board_calib/core/sim/scenario.h>

#include <dirent.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <ctime>
#include <iostream>
#include <string>
#include <vector>

namespace {

using Clock = std::chrono::steady_clock;

double secondsSince(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

double cpuSeconds() { return static_cast<double>(std::clock()) / CLOCKS_PER_SEC; }

std::vector<std::string> defaultScenarios() {
  std::vector<std::string> out;
  const std::string dir = "config/scenarios";
  if (DIR* d = opendir(dir.c_str())) {
    while (dirent* e = readdir(d)) {
      const std::string name = e->d_name;
      if (name.size() > 5 && name.substr(name.size() - 5) == ".yaml")
        out.push_back(dir + "/" + name);
    }
    closedir(d);
  }
  std::sort(out.begin(), out.end());
  return out;
}

}  // namespace

int main(int argc, char** argv) {
  int poses_override = 0;
  std::vector<std::string> files;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    if (arg == "--poses" && i + 1 < argc) {
      poses_override = std::atoi(argv[++i]);
    } else if (arg == "-h" || arg == "--help") {
      std::cout << "usage: bench_sim [--poses N] [SCENARIO.yaml...]  (default: "
                   "config/scenarios/*.yaml)\n";
      return 0;
    } else {
      files.push_back(arg);
    }
  }
  if (files.empty()) files = defaultScenarios();
  if (files.empty()) {
    std::cerr << "bench_sim: no scenarios given and none found in ./config/scenarios" << std::endl;
    return 1;
  }
  std::printf("%-22s %5s %6s %6s %9s %10s %10s %10s %9s %9s\n", "scenario", "poses", "images",
              "clouds", "timeline", "ray map", "img ms", "cloud ms", "total s", "cpu s");
  for (const auto& file : files) {
    auto scenario = board_calib::sim::loadScenario(file);
    if (!scenario) {
      std::cerr << "bench_sim: " << scenario.error() << std::endl;
      return 1;
    }
    if (poses_override > 0) scenario->motion.poses = poses_override;
    const auto t_start = Clock::now();
    const double cpu_start = cpuSeconds();
    auto timeline = board_calib::sim::makeTimeline(*scenario);
    if (!timeline) {
      std::cerr << "bench_sim: " << file << ": " << timeline.error() << std::endl;
      return 1;
    }
    const double timeline_s = secondsSince(t_start);
    auto generator = board_calib::sim::FrameGenerator::create(*scenario);
    if (!generator) {
      std::cerr << "bench_sim: " << generator.error() << std::endl;
      return 1;
    }
    // The first image of each camera builds its ray map (once per intrinsics); time it apart.
    double ray_map_s = 0, image_s = 0, cloud_s = 0;
    size_t images = 0, clouds = 0;
    std::vector<bool> first(scenario->cameras.size(), true);
    for (size_t i = 0; i < timeline->frames.size(); ++i) {
      const auto& f = timeline->frames[i];
      const auto t0 = Clock::now();
      if (f.is_camera) {
        const cv::Mat image = generator->image(f, i);
        if (image.empty()) {
          std::cerr << "bench_sim: rendering failed" << std::endl;
          return 1;
        }
        if (first[static_cast<size_t>(f.sensor)]) {
          ray_map_s += secondsSince(t0);
          first[static_cast<size_t>(f.sensor)] = false;
        } else {
          image_s += secondsSince(t0);
          ++images;
        }
      } else {
        const auto cloud = generator->cloud(f, i);
        cloud_s += secondsSince(t0);
        ++clouds;
      }
    }
    std::string name = scenario->name.empty() ? file : scenario->name;
    std::printf("%-22s %5d %6zu %6zu %7.0fms %8.0fms %10.1f %10.1f %9.1f %9.1f\n", name.c_str(),
                scenario->motion.poses, images + scenario->cameras.size(), clouds,
                1000 * timeline_s, 1000 * ray_map_s, images ? 1000 * image_s / images : 0.0,
                clouds ? 1000 * cloud_s / clouds : 0.0, secondsSince(t_start),
                cpuSeconds() - cpu_start);
  }
  std::printf(
      "img ms: mean per image after the first of each camera (still frames reuse the noise-free\n"
      "render and only add noise); ray map: the first image of each camera incl. its ray map.\n");
  return 0;
}
