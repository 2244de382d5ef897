// Benchmark of the LiDAR board detector on real recordings: median / p90 time per cloud,
// single-threaded, plus detection counts. Usage:
//   bench_lidar_detector [--data DIR] [--repeat N] [--no-sparse]
//   bench_lidar_detector --sim-table config/scenarios/plain_vlp16_outdoor_far.yaml   (rates by
//   distance)
// DIR defaults to ../shared/data, relative to the working directory (run it from the package
// root); it holds basler_os1_plain/, left_vlp32_checker/ and rs16_plain/.
#include <board_calib/bag_reader.h>
#include <board_calib/core/lidar_detection/lidar_board_detector.h>
#include <board_calib/core/sim/scenario.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <map>
#include <string>
#include <vector>

using namespace board_calib;

namespace {

struct Dataset {
  std::string folder, topic;
};

int run(const std::string& data, const Dataset& ds, int repeat,
        const LidarBoardDetectorOptions& options) {
  const std::string dir = data + "/" + ds.folder;
  auto target = loadTarget(dir + "/target.yaml");
  if (!target) {
    std::fprintf(stderr, "%s: %s\n", ds.folder.c_str(), target.error().c_str());
    return 1;
  }
  std::vector<LidarCloud> clouds;
  BagTopics topics;
  topics.cloud_topics = {ds.topic};
  BagCallbacks cb;
  cb.on_cloud = [&](const std::string&, const LidarCloud& c) { clouds.push_back(c); };
  const Status st = readBags({dir + "/session.bag"}, topics, cb);
  if (!st) {
    std::fprintf(stderr, "%s: %s\n", ds.folder.c_str(), st.reason.c_str());
    return 1;
  }
  if (clouds.empty()) {
    std::fprintf(stderr, "%s: no clouds on %s\n", ds.folder.c_str(), ds.topic.c_str());
    return 1;
  }
  for (const bool strip_ring : {false, true}) {
    std::vector<double> ms,
        cpu_ms;  // wall clock; CPU time of this thread (robust to a busy machine)
    int found = 0, four_edges = 0;
    size_t points = 0;
    for (LidarCloud c : clouds) {
      if (strip_ring) {
        c.has_ring = false;
        for (auto& p : c.points) p.ring = -1;
        c.width = static_cast<int>(c.points.size());
        c.height = 1;
      }
      points += c.points.size();
      for (int r = 0; r < repeat; ++r) {
        timespec c0, c1;
        const auto t0 = std::chrono::steady_clock::now();
        clock_gettime(CLOCK_THREAD_CPUTIME_ID, &c0);
        const LidarBoardDetection det = detectLidarBoard(c, *target, options);
        clock_gettime(CLOCK_THREAD_CPUTIME_ID, &c1);
        const auto t1 = std::chrono::steady_clock::now();
        ms.push_back(std::chrono::duration<double, std::milli>(t1 - t0).count());
        cpu_ms.push_back((c1.tv_sec - c0.tv_sec) * 1e3 + (c1.tv_nsec - c0.tv_nsec) * 1e-6);
        if (r == 0) {
          found += det.features.found;
          four_edges += det.features.found && det.features.allEdgesValid();
        }
      }
    }
    std::sort(ms.begin(), ms.end());
    std::sort(cpu_ms.begin(), cpu_ms.end());
    std::printf(
        "%-20s %-22s clouds %2zu  points/cloud %6zu  found %2d  four edges %2d  wall median %6.2f "
        "ms  "
        "p90 %6.2f ms  CPU median %6.2f ms  p90 %6.2f ms\n",
        ds.folder.c_str(), strip_ring ? "(unorganized, no ring)" : "(as recorded)", clouds.size(),
        points / clouds.size(), found, four_edges, ms[ms.size() / 2], ms[ms.size() * 9 / 10],
        cpu_ms[cpu_ms.size() / 2], cpu_ms[cpu_ms.size() * 9 / 10]);
  }
  return 0;
}

// Detection rate by distance, LiDAR and ring / no ring on the simulator's outdoor scene
// (config/scenarios/plain_vlp16_outdoor_far.yaml without its posters: the far, sparse case
// alone), board 2-14 m. A cloud counts when >= 3 scan lines carry >= 2 board returns.
int simTable(const std::string& scenario_path) {
  auto loaded = sim::loadScenario(scenario_path);
  if (!loaded) {
    std::fprintf(stderr, "%s\n", loaded.error().c_str());
    return 1;
  }
  const double bins[] = {2.0, 5.0, 9.0, 14.0};
  std::printf("%-8s %-22s %-10s %7s %7s %11s\n", "LiDAR", "cloud", "distance", "clouds", "board",
              "four edges");
  for (const char* preset : {"VLP-16", "VLP-32C", "OS1-64"}) {
    for (const bool ring : {true, false}) {
      sim::Scenario s = *loaded;
      s.scene.panels.clear();
      s.motion.poses = 36;
      s.motion.min_distance_m = bins[0];
      s.motion.max_distance_m = bins[3];
      s.motion.still_frames_per_hold = 1;
      s.motion.frames_per_move = 0;
      auto spec = sim::lidarPreset(preset);
      if (!spec) return 1;
      spec->organized = ring;
      spec->with_ring = ring;
      s.lidars[0].spec = *spec;
      auto timeline = sim::makeTimeline(s);
      auto generator = sim::FrameGenerator::create(s);
      if (!timeline || !generator) {
        std::fprintf(stderr, "%s: %s\n", preset,
                     timeline ? generator.error().c_str() : timeline.error().c_str());
        continue;
      }
      std::map<int, std::array<int, 3>> tally;  // bin -> clouds, board, four edges
      const Target& target = s.scene.target;
      for (size_t i = 0; i < timeline->frames.size(); ++i) {
        const auto& frame = timeline->frames[i];
        if (frame.is_camera) continue;
        std::vector<sim::ReturnOrigin> origins;
        const LidarCloud cloud = generator->cloud(frame, i, &origins);
        std::map<long, int> per_line;
        for (size_t k = 0; k < cloud.points.size(); ++k)
          if (origins[k] == sim::ReturnOrigin::kBoard) {
            const auto& p = cloud.points[k];
            ++per_line[std::lround(std::atan2(p.z, std::hypot(p.x, p.y)) * 180.0 / M_PI * 20)];
          }
        int lines = 0;
        for (const auto& kv : per_line) lines += kv.second >= 2;
        if (lines < 3) continue;
        const Eigen::Vector3d centre =
            sim::worldTLidar(s, 0).inverse() * frame.world_T_board * target.center();
        const double d = centre.norm();
        const int bin = d < bins[1] ? 0 : d < bins[2] ? 1 : 2;
        const auto det = detectLidarBoard(cloud, target);
        Eigen::Vector3d mean = Eigen::Vector3d::Zero();
        for (const auto& p : det.features.board_points) mean += p;
        mean /= std::max<size_t>(1, det.features.board_points.size());
        const bool at_board = det.features.found &&
                              (mean - centre).norm() < 0.5 * std::min(target.width, target.height);
        auto& t = tally[bin];
        ++t[0];
        t[1] += at_board;
        t[2] += at_board && det.features.allEdgesValid();
      }
      for (const auto& kv : tally) {
        char range[32];
        std::snprintf(range, sizeof(range), "%.0f-%.0f m", bins[kv.first], bins[kv.first + 1]);
        std::printf("%-8s %-22s %-10s %7d %7d %11d\n", preset,
                    ring ? "organized, ring" : "unorganized, no ring", range, kv.second[0],
                    kv.second[1], kv.second[2]);
      }
    }
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  std::string data = "../shared/data";  // from the package root
  int repeat = 5;
  LidarBoardDetectorOptions options;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--data" && i + 1 < argc) {
      data = argv[++i];
    } else if (a == "--sim-table" && i + 1 < argc) {
      return simTable(argv[++i]);
    } else if (a == "--no-sparse") {
      options.sparse_candidates = false;  // the voxel candidates only (before far-board support)
    } else if (a == "--repeat" && i + 1 < argc) {
      repeat = std::max(1, std::atoi(argv[++i]));
    } else {
      std::fprintf(stderr,
                   "usage: bench_lidar_detector [--data DIR] [--repeat N] [--no-sparse] | "
                   "--sim-table SCENARIO.yaml\n");
      return a == "--help" || a == "-h" ? 0 : 2;
    }
  }
  int rc = 0;
  rc |= run(data, {"basler_os1_plain", "/os1/points"}, repeat, options);
  rc |= run(data, {"left_vlp32_checker", "/lidar/points"}, repeat, options);
  rc |= run(data, {"rs16_plain", "/rslidar/points"}, repeat, options);
  return rc;
}
