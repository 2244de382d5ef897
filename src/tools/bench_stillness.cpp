// bench_stillness: the stillness judge on simulated recordings, against the simulator's truth
// (issue 14 item 3, docs/BENCHMARKS.md "Session 6: stillness of far sparse boards").
//   bench_stillness [--scenario FILE] [--seeds 21,22] [--poses N] [--hz RATE] [--images]
//                   [--pairs-only] [--session]
// --pairs-only: the judge without the drift fit over the window (the session 6 judge).
// --session: each seed's recording through the whole pair pipeline (as calibrate_bag: image
// memory and its pre-pass, stillness, consistency, PBPC, verdict), one table row per seed.
// Every cloud goes through the LiDAR detector with session memory (as the pipeline); with
// --images every image through the image detector with its memory and pre-pass, otherwise the
// camera sample of each held image is the true board pose (the LiDAR side alone). Printed:
//  - per hold, the LiDAR board's measured scatter over the hold's still frames (centre and normal)
//    against the 1 sigma the samples claim: the noise model's test;
//  - per image of a hold, the judge's state and why (which stream, the change, what was allowed);
//  - per image of a move, whether the judge saw the motion.
#include <board_calib/core/capture/stillness.h>
#include <board_calib/core/common/format.h>
#include <board_calib/core/common/statistics.h>
#include <board_calib/core/image_detection/image_board_tracker.h>
#include <board_calib/core/lidar_detection/lidar_board_detector.h>
#include <board_calib/core/pipeline/pair_calibration.h>
#include <board_calib/core/pipeline/pipeline.h>
#include <board_calib/core/pipeline/scene_prepass.h>
#include <board_calib/core/sim/scenario.h>
#include <board_calib/core/sim/simulator.h>
#include <board_calib/core/transform.h>

#include "support/sim_session.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <deque>
#include <iostream>
#include <map>
#include <sstream>

using namespace board_calib;

namespace {

std::vector<std::string> split(const std::string& s) {
  std::vector<std::string> out;
  std::stringstream in(s);
  for (std::string item; std::getline(in, item, ',');) out.push_back(item);
  return out;
}

struct Counts {
  int held = 0, still = 0, moving = 0, other = 0;  // images of holds with a board in both
  int moves = 0, moves_caught = 0;                 // images of moves with a board in both
};

// Scatter (rms, worst) of points about their mean, in the plane of `normal`.
std::pair<double, double> scatter(const std::vector<Eigen::Vector3d>& v,
                                  const Eigen::Vector3d& normal) {
  if (v.empty()) return {0.0, 0.0};
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const auto& p : v) mean += p;
  mean /= static_cast<double>(v.size());
  double s2 = 0.0, worst = 0.0;
  for (const auto& p : v) {
    Eigen::Vector3d d = p - mean;
    d -= d.dot(normal) * normal;
    s2 += d.squaredNorm();
    worst = std::max(worst, d.norm());
  }
  return {std::sqrt(s2 / static_cast<double>(v.size())), worst};
}

// Per hold: the LiDAR samples' scatter about their mean (in the board plane) against the 1 sigma
// they claim: centres from the edges, centroids, normals.
void printHoldNoise(const std::map<int, std::vector<BoardSample>>& holds) {
  for (const auto& [pose, samples] : holds) {
    if (samples.size() < 3) continue;
    Eigen::Vector3d n_mean = Eigen::Vector3d::Zero();
    std::vector<Eigen::Vector3d> edge_c, centroids;
    std::vector<double> es, cs, ns, lines;
    for (const auto& s : samples) {
      n_mean += s.normal;
      centroids.push_back(s.centroid);
      cs.push_back(s.centroid_sigma_m);
      lines.push_back(s.scan_lines);
      if (s.centre_from_edges) {
        edge_c.push_back(s.centre);
        es.push_back(s.centre_sigma_m);
      }
    }
    n_mean.normalize();
    double a2 = 0.0, worst_a = 0.0;
    for (const auto& s : samples) {
      const double a = std::acos(std::clamp(s.normal.dot(n_mean), -1.0, 1.0));
      a2 += a * a;
      worst_a = std::max(worst_a, a);
      ns.push_back(s.normal_sigma_rad);
    }
    const auto e = scatter(edge_c, n_mean), c = scatter(centroids, n_mean);
    std::printf(
        "[hold %2d] %.1f m, %zu clouds, %.0f lines: edge centre (%zu) scatter %.1f cm (worst %.1f) "
        "claimed %.1f; centroid scatter %.1f cm (worst %.1f) claimed %.1f; normal scatter %.2f "
        "deg (worst %.2f) claimed %.2f\n",
        pose, samples.front().centroid.norm(), samples.size(), medianOf(lines), edge_c.size(),
        100 * e.first, 100 * e.second, 100 * medianOf(es), 100 * c.first, 100 * c.second,
        100 * medianOf(cs), kDegPerRad * std::sqrt(a2 / static_cast<double>(samples.size())),
        kDegPerRad * worst_a, kDegPerRad * medianOf(ns));
  }
}

// BENCH_STILL_VERBOSE: one held cloud's board: points, centre, edges, points per scan line.
void printCloud(const sim::Frame& f, const LidarBoardFeatures& l, const BoardSample& sample) {
  std::string lines;
  for (const auto& line : sample.lines)
    lines +=
        " " + std::to_string(line.points) + "@" + formatFixed(kDegPerRad * line.elevation_rad, 2);
  const Eigen::Vector3d& c = sample.centre;
  std::printf("    cloud %.2f hold %d: %zu pts, c %.3f %.3f %.3f, edges %d%d%d%d, lines%s\n",
              f.stamp, f.pose, l.board_points.size(), c.x(), c.y(), c.z(), l.edge_valid[0],
              l.edge_valid[1], l.edge_valid[2], l.edge_valid[3], lines.c_str());
}

// Judges every image with a board, as a PairSession does, and counts against the truth.
Counts judgeImages(const std::deque<BoardSample>& lidar_samples, const StreamClock& lidar_clock,
                   const std::deque<BoardSample>& camera_samples, const StreamClock& camera_clock,
                   const std::vector<std::pair<double, int>>& image_frames, unsigned seed,
                   const StillnessOptions& o) {
  const std::vector<StillnessStream> streams{{&lidar_samples, &lidar_clock, "LiDAR"},
                                             {&camera_samples, &camera_clock, "camera"}};
  Counts n;
  for (const auto& [stamp, pose] : image_frames) {
    const StillnessJudgement j = judgeStillness(streams, stamp, o, true);
    if (pose >= 0) {
      ++n.held;
      if (j.state == StillState::kStill)
        ++n.still;
      else if (j.state == StillState::kMoving)
        ++n.moving;
      else
        ++n.other;
    } else {
      // Only moves the judge could see: a LiDAR board in the window.
      if (j.state == StillState::kNoBoard || j.state == StillState::kTooFewFrames) continue;
      ++n.moves;
      if (j.state != StillState::kStill) ++n.moves_caught;
    }
    std::printf("  %6.2f s %s: %s: %s\n", stamp,
                pose >= 0 ? ("hold " + std::to_string(pose)).c_str() : "move",
                stillStateName(j.state), j.why.c_str());
  }
  std::printf(
      "seed %u: held images %d: still %d, moving %d, other %d; moving images %d, judged moving "
      "%d\n",
      seed, n.held, n.still, n.moving, n.other, n.moves, n.moves_caught);
  return n;
}

Counts runSeed(const sim::Scenario& base, unsigned seed, int poses, double hz, bool images,
               const StillnessOptions& o) {
  const sim::Scenario s = test_support::captureScenario(base, 1.0, hz, false, poses, seed);
  auto timeline = sim::makeTimeline(s);
  auto gen = sim::FrameGenerator::create(s);
  if (!timeline || !gen) {
    std::fprintf(stderr, "seed %u: %s\n", seed,
                 (!timeline ? timeline.error() : gen.error()).c_str());
    return {};
  }
  const PipelineOptions p;
  LidarBoardTracker lidar(s.scene.target, p.lidar, p.lidar_memory);
  auto image = ImageBoardTracker::create(s.scene.target, p.image, p.image_memory);
  const Eigen::Isometry3d camera_T_world = sim::worldTCamera(s, 0).inverse();
  if (images) {
    auto prepass = ScenePrepass::create(s.scene.target, p.image, p.image_memory, p.image_prepass);
    auto survey = sim::FrameGenerator::create(s);
    for (size_t i = 0; prepass && survey && i < timeline->frames.size(); ++i) {
      const sim::Frame& f = timeline->frames[i];
      if (f.sensor == 0 && f.is_camera && prepass->wants(f.stamp))
        prepass->add(survey->image(f, i), s.cameras.front().intrinsics, f.stamp);
    }
    if (prepass) image->setKnownScene(prepass->scene());
  }
  std::deque<BoardSample> lidar_samples, camera_samples;
  StreamClock lidar_clock, camera_clock;
  std::vector<std::pair<double, int>> image_frames;  // stamp, pose (-1: moving)
  std::map<int, std::vector<BoardSample>> holds;
  for (size_t i = 0; i < timeline->frames.size(); ++i) {
    const sim::Frame& f = timeline->frames[i];
    if (f.sensor != 0) continue;
    if (f.is_camera) {
      CameraBoardFeatures c;
      if (images) {
        c = image->detect(gen->image(f, i), gen->cameraModel(0), f.stamp).features;
      } else {
        c.found = true;
        c.K << s.cameras.front().intrinsics.fx, 0, 0, 0, s.cameras.front().intrinsics.fy, 0, 0, 0,
            1;
        c.camera_T_board = camera_T_world * f.world_T_board;
        c.plane.normal = c.camera_T_board.linear().col(2);
      }
      c.stamp = f.stamp;
      camera_samples.push_back(boardSampleOf(c, &s.scene.target));
      camera_clock.add(f.stamp);
      if (c.found) image_frames.emplace_back(f.stamp, f.still ? f.pose : -1);
    } else {
      LidarCloud cloud = gen->cloud(f, i);
      cloud.stamp = f.stamp;
      LidarBoardFeatures l = lidar.detect(cloud).features;
      l.stamp = f.stamp;
      lidar_samples.push_back(boardSampleOf(l));
      lidar_clock.add(f.stamp);
      if (f.still && f.pose >= 0 && lidar_samples.back().found) {
        holds[f.pose].push_back(lidar_samples.back());
        if (std::getenv("BENCH_STILL_VERBOSE")) printCloud(f, l, lidar_samples.back());
      }
    }
  }
  std::printf("seed %u, camera %.0f Hz:\n", seed, hz);
  printHoldNoise(holds);
  return judgeImages(lidar_samples, lidar_clock, camera_samples, camera_clock, image_frames, seed,
                     o);
}

// One table row: the recording through the pipeline, calibrated, scored against the truth.
void printSession(const sim::Scenario& base, unsigned seed, int poses, double hz) {
  const sim::Scenario s = test_support::captureScenario(base, 1.0, hz, false, poses, seed);
  auto session = test_support::runSimulatedSession(s, PipelineOptions{});
  if (!session) {
    std::printf("| %u | simulation failed: %s |\n", seed, session.error().c_str());
    return;
  }
  std::fprintf(stderr, "seed %u: %s\n", seed, session->capture_summary.c_str());
  const PairCalibration run =
      calibratePair(session->views, {Method::kPbpc}, s.scene.target, "camera", "lidar");
  const MethodRun* c = run.chosenRun();
  const auto& truth = session->truth.camera_T_lidar;
  std::printf("| %u | %d | %d/%d/%d | %d | %d | %zu | %s: %s | ", seed, session->holds,
              session->images_true, session->images_wrong,
              session->images - session->images_true - session->images_wrong,
              session->holds_captured, session->moving_captured, session->views.size(),
              verdictName(run.verdict), run.reason.c_str());
  if (c && !run.failed())
    std::printf("%.3f deg / %.1f mm (1 sigma %.3f deg / %.1f mm) | %.0f |\n",
                rotationErrorDeg(c->solution.camera_T_lidar, truth),
                translationErrorM(c->solution.camera_T_lidar, truth) * 1e3,
                c->verdict.stddev.rotation_deg.norm(), c->verdict.stddev.translation_m.norm() * 1e3,
                session->seconds);
  else
    std::printf("- | %.0f |\n", session->seconds);
}

}  // namespace

int main(int argc, char** argv) {
  std::string scenario_path =
      std::string(BOARD_CALIB_SOURCE_DIR) + "/config/scenarios/plain_vlp16_outdoor_far.yaml";
  std::string seeds = "21,22,23,24";
  int poses = 8;
  double hz = 2.0;
  bool images = false, session = false;
  StillnessOptions still = SessionOptions{}.stillness();
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--images" || a == "--session") {
      (a == "--images" ? images : session) = true;
      continue;
    }
    if (a == "--pairs-only") {  // the judge without the drift fit, for comparison
      still.fit_drift = false;
      continue;
    }
    if (i + 1 >= argc) {
      std::cerr << "usage: bench_stillness [--scenario FILE] [--seeds 21,22] [--poses N] "
                   "[--hz RATE] [--images] [--pairs-only] [--session]\n";
      return a == "--help" ? 0 : 2;
    }
    const std::string v = argv[++i];
    try {
      if (a == "--scenario")
        scenario_path = v;
      else if (a == "--seeds")
        seeds = v;
      else if (a == "--poses")
        poses = std::stoi(v);
      else if (a == "--hz")
        hz = std::stod(v);
      else {
        std::cerr << "bench_stillness: unknown option " << a << "\n";
        return 2;
      }
    } catch (const std::exception&) {
      std::cerr << "bench_stillness: " << a << " needs a number\n";
      return 2;
    }
  }
  auto base = sim::loadScenario(scenario_path);
  if (!base) {
    std::cerr << "bench_stillness: " << base.error() << "\n";
    return 1;
  }
  if (session) {
    std::printf(
        "| seed | holds | images true/wrong/none | holds captured | moving captured | views "
        "| verdict | error (1 sigma) | time (s) |\n|---|---|---|---|---|---|---|---|---|\n");
    for (const auto& seed : split(seeds)) {
      printSession(*base, static_cast<unsigned>(std::stoul(seed)), poses, hz);
      std::fflush(stdout);
    }
    return 0;
  }
  Counts all;
  for (const auto& seed : split(seeds)) {
    const Counts n =
        runSeed(*base, static_cast<unsigned>(std::stoul(seed)), poses, hz, images, still);
    all.held += n.held;
    all.still += n.still;
    all.moving += n.moving;
    all.other += n.other;
    all.moves += n.moves;
    all.moves_caught += n.moves_caught;
    std::fflush(stdout);
  }
  std::printf(
      "all: held images %d: still %d, moving %d, other %d; moving images %d, judged "
      "moving %d\n",
      all.held, all.still, all.moving, all.other, all.moves, all.moves_caught);
  return 0;
}
