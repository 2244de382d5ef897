// Benchmark of the MSG graph on simulated rigs at known ground truth: speed (4 sensors x 100
// views, single-threaded), accuracy of every pair, the effect of each ingredient (corner
// terms, PBPC line terms, noise estimation) with and without a 3x-noise fifth sensor, and
// convergence from random starts.
//   bench_msg_graph [--views N] [--scenes N] [--trials N] [--seed S] [--only-pairs]
//   bench_msg_graph --scenario RIG_SCENARIO.yaml [--scenes N] [--seed S]: the graph pairs against
//     PBPC on features the detectors find in simulated frames (one still frame per sensor and
//     hold), e.g. test/data/msg_rig_checker_scenario.yaml
#include <board_calib/core/image_detection/image_board_detector.h>
#include <board_calib/core/lidar_detection/lidar_board_detector.h>
#include <board_calib/core/msg_graph/msg_graph.h>
#include <board_calib/core/sim/scenario.h>
#include <board_calib/core/transform.h>
#include "support/synthetic_rig.h"

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <map>
#include <string>
#include <vector>

using namespace board_calib;
using namespace board_calib::multi_sensor;

namespace {

struct Args {
  int views = 100;
  int scenes = 10;
  int trials = 100;
  unsigned seed = 1;
  bool only_pairs = false;  ///< only the pairs-against-PBPC section
  std::string scenario;     ///< rig scenario: only the pairs against PBPC on detected features
};

bool parseArgs(int argc, char** argv, Args* args) {
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto next = [&](int* out) {
      if (i + 1 >= argc) return false;
      *out = std::atoi(argv[++i]);
      return true;
    };
    int v = 0;
    if (a == "--views" && next(&args->views)) continue;
    if (a == "--scenes" && next(&args->scenes)) continue;
    if (a == "--trials" && next(&args->trials)) continue;
    if (a == "--scenario" && i + 1 < argc) {
      args->scenario = argv[++i];
      continue;
    }
    if (a == "--only-pairs") {
      args->only_pairs = true;
      continue;
    }
    if (a == "--seed" && next(&v)) {
      args->seed = static_cast<unsigned>(v);
      continue;
    }
    std::fprintf(stderr,
                 "usage: bench_msg_graph [--views N] [--scenes N] [--trials N] [--seed S] "
                 "[--only-pairs] [--scenario FILE]\n");
    return false;
  }
  return args->views >= 3 && args->scenes >= 1 && args->trials >= 0;
}

// Worst pair error among `sensors` against the ground truth.
void worstPair(const MsgSolution& sol, const sim::RigScene& scene, int sensors, double* rot_deg,
               double* trans_mm) {
  *rot_deg = 0;
  *trans_mm = 0;
  for (int a = 0; a < sensors; ++a)
    for (int b = a + 1; b < sensors; ++b) {
      const Eigen::Isometry3d truth =
          scene.sensors[a].reference_T_sensor.inverse() * scene.sensors[b].reference_T_sensor;
      const Eigen::Isometry3d est = *sensorTSensor(sol, a, b);
      *rot_deg = std::max(*rot_deg, rotationErrorDeg(est, truth));
      *trans_mm = std::max(*trans_mm, 1000.0 * translationErrorM(est, truth));
    }
}

struct Variant {
  const char* name;
  MsgGraphOptions options;
};


// One board pose per hold of a simulated rig recording: each sensor's first still frame of the
// hold through the detectors (the image with 2 grey levels of noise).
Expected<MsgProblem> detectedProblem(sim::Scenario scenario) {
  for (auto& c : scenario.cameras) c.render.noise_sigma = 2.0;
  auto timeline = sim::makeTimeline(scenario);
  if (!timeline) return Expected<MsgProblem>::failure(timeline.error());
  auto generator = sim::FrameGenerator::create(scenario);
  if (!generator) return Expected<MsgProblem>::failure(generator.error());
  const Target& target = scenario.scene.target;
  std::vector<ImageBoardDetector> detectors;
  for (size_t c = 0; c < scenario.cameras.size(); ++c) {
    auto d = ImageBoardDetector::create(target, ImageBoardDetectorOptions{});
    if (!d) return Expected<MsgProblem>::failure(d.error());
    detectors.push_back(std::move(*d));
  }
  MsgProblem problem;
  const int cameras = static_cast<int>(scenario.cameras.size());
  for (const auto& c : scenario.cameras)
    problem.sensors.push_back({c.frame_id, SensorKind::kCamera});
  for (const auto& l : scenario.lidars) problem.sensors.push_back({l.frame_id, SensorKind::kLidar});
  std::map<int, BoardPoseObservation> poses;
  for (size_t i = 0; i < timeline->frames.size(); ++i) {
    const sim::Frame& f = timeline->frames[i];
    if (!f.still || f.pose < 0) continue;
    BoardPoseObservation& o = poses[f.pose];
    o.id = f.pose;
    if (f.is_camera && !o.cameras.count(f.sensor)) {
      CameraBoardFeatures feat =
          detectors[f.sensor]
              .detect(generator->image(f, i), generator->cameraModel(f.sensor))
              .features;
      if (feat.found) o.cameras[f.sensor] = feat;
    } else if (!f.is_camera && !o.lidars.count(cameras + f.sensor)) {
      LidarBoardFeatures feat = detectLidarBoard(generator->cloud(f, i), target).features;
      if (feat.found) o.lidars[cameras + f.sensor] = feat;
    }
  }
  for (auto& [id, o] : poses) problem.poses.push_back(std::move(o));
  return problem;
}

// The graph's camera <- LiDAR pairs against PBPC of each pair (real-LiDAR settings, as
// calibrate_bag solves a pair) on detected features of a simulated rig, over seeds.
int scenarioPairs(const Args& args) {
  auto base = sim::loadScenario(args.scenario);
  if (!base) {
    std::fprintf(stderr, "scenario: %s\n", base.error().c_str());
    return 1;
  }
  std::printf("%s: camera <- LiDAR pairs of the graph vs PBPC of the pair on detected features\n",
              args.scenario.c_str());
  std::printf("  %-6s %-26s %6s %9s %9s %7s %11s %11s %11s %11s %9s\n", "seed", "pair", "views",
              "graph px", "PBPC px", "ratio", "graph deg", "graph mm", "PBPC deg", "PBPC mm",
              "stereo mm");
  const int cameras = static_cast<int>(base->cameras.size());
  for (int k = 0; k < args.scenes; ++k) {
    sim::Scenario scenario = *base;
    scenario.seed = args.seed * 1000 + static_cast<unsigned>(k);
    auto problem = detectedProblem(scenario);
    if (!problem) {
      std::fprintf(stderr, "seed %u: %s\n", scenario.seed, problem.error().c_str());
      continue;
    }
    const MsgSolution sol = solveMsgGraph(*problem, MsgGraphOptions());
    if (!sol.success) {
      std::printf("  %-6u graph failed: %s\n", scenario.seed, sol.reason.c_str());
      continue;
    }
    auto cameraPose = [&](int s) {
      return s < cameras ? sim::worldTCamera(scenario, s) : sim::worldTLidar(scenario, s - cameras);
    };
    double stereo = 0.0;
    if (cameras >= 2) {
      const auto c = stereoConsistency(sol, 0, 1, cameraPose(0).inverse() * cameraPose(1));
      stereo = c ? c->translation_mm : 0.0;
    }
    for (int c = 0; c < cameras; ++c)
      for (int l = cameras; l < static_cast<int>(problem->sensors.size()); ++l) {
        const std::vector<View> views = pairViews(*problem, c, l);
        const CalibrationSolution pbpc = calibrate(views, Method::kPbpc, realLidarSolverOptions());
        const Eigen::Isometry3d graph = *sensorTSensor(sol, c, l);
        const Eigen::Isometry3d truth = cameraPose(c).inverse() * cameraPose(l);
        const auto mg = meanLineReprojectionErrorPx(views, graph);
        const auto mp = meanLineReprojectionErrorPx(views, pbpc.camera_T_lidar);
        if (!pbpc.success || !mg || !mp) {
          std::printf("  %-6u %-26s PBPC failed: %s\n", scenario.seed,
                      (problem->sensors[c].frame + " <- " + problem->sensors[l].frame).c_str(),
                      pbpc.reason.c_str());
          continue;
        }
        std::printf(
            "  %-6u %-26s %6zu %9.2f %9.2f %7.3f %11.3f %11.2f %11.3f %11.2f %9.2f\n",
            scenario.seed, (problem->sensors[c].frame + " <- " + problem->sensors[l].frame).c_str(),
            views.size(), *mg, *mp, *mg / *mp, rotationErrorDeg(graph, truth),
            1000.0 * translationErrorM(graph, truth), rotationErrorDeg(pbpc.camera_T_lidar, truth),
            1000.0 * translationErrorM(pbpc.camera_T_lidar, truth), stereo);
      }
  }
  return 0;
}

// Issue 13 item 4: each camera <- LiDAR pair of the graph against a PBPC solve of the same pair
// (MLRE ratio graph / PBPC, and both errors against the truth), over scenes, noise levels and
// with a 3x-noise LiDAR; plus the stereo consistency the graph must keep.
void pairsAgainstPbpc(const Args& args) {
  std::printf(
      "\ncamera <- LiDAR pairs of the graph vs a PBPC solve of the same pair (%d scenes each):\n",
      args.scenes);
  std::printf("  %-34s %9s %9s %9s %11s %11s %11s %11s %9s\n", "rig", "ratio avg", "ratio max",
              "MLRE px", "graph deg", "graph mm", "PBPC deg", "PBPC mm", "stereo mm");
  struct Case {
    const char* name;
    double noise;
    bool noisy_lidar;
  };
  for (const Case& k :
       {Case{"rig, nominal noise", 1.0, false}, Case{"rig, 2x noise on every sensor", 2.0, false},
        Case{"rig + VLP-16 with 3x noise", 1.0, true}}) {
    double ratio_sum = 0, ratio_max = 0, mlre_sum = 0, g_rot = 0, g_tr = 0, p_rot = 0, p_tr = 0,
           stereo = 0;
    int count = 0, solves = 0;
    for (int i = 0; i < args.scenes; ++i) {
      std::mt19937 rng(args.seed * 1000 + i);
      auto rig = sim::defaultRig();
      for (auto& s : rig) s.noise_scale = k.noise;
      if (k.noisy_lidar) rig.push_back(sim::extraLidar16("vlp16_noisy", 3.0));
      auto scene = sim::generateRigScene(rig, sim::RigSceneOptions(), rng);
      if (!scene) continue;
      MsgGraphOptions o;
      o.compute_covariance = false;
      const MsgSolution sol = solveMsgGraph(scene->problem, o);
      if (!sol.success) continue;
      ++solves;
      const Eigen::Isometry3d stereo_truth =
          scene->sensors[0].reference_T_sensor.inverse() * scene->sensors[1].reference_T_sensor;
      stereo = std::max(stereo, stereoConsistency(sol, 0, 1, stereo_truth)->translation_mm);
      SolverOptions so;
      so.compute_covariance = false;
      for (int c = 0; c < 2; ++c)
        for (int l = 2; l < static_cast<int>(rig.size()); ++l) {
          const std::vector<View> views = pairViews(scene->problem, c, l);
          const CalibrationSolution pbpc = calibrate(views, Method::kPbpc, so);
          const Eigen::Isometry3d graph = *sensorTSensor(sol, c, l);
          const auto mg = meanLineReprojectionErrorPx(views, graph);
          const auto mp = meanLineReprojectionErrorPx(views, pbpc.camera_T_lidar);
          if (!pbpc.success || !mg || !mp) continue;
          const Eigen::Isometry3d truth =
              scene->sensors[c].reference_T_sensor.inverse() * scene->sensors[l].reference_T_sensor;
          ratio_sum += *mg / *mp;
          ratio_max = std::max(ratio_max, *mg / *mp);
          mlre_sum += *mg;
          g_rot = std::max(g_rot, rotationErrorDeg(graph, truth));
          g_tr = std::max(g_tr, 1000.0 * translationErrorM(graph, truth));
          p_rot = std::max(p_rot, rotationErrorDeg(pbpc.camera_T_lidar, truth));
          p_tr = std::max(p_tr, 1000.0 * translationErrorM(pbpc.camera_T_lidar, truth));
          ++count;
        }
    }
    if (count == 0) {
      std::printf("  %-34s no usable pair (%d graph solves)\n", k.name, solves);
      continue;
    }
    std::printf("  %-34s %9.3f %9.3f %9.2f %11.3f %11.2f %11.3f %11.2f %9.2f\n", k.name,
                ratio_sum / count, ratio_max, mlre_sum / count, g_rot, g_tr, p_rot, p_tr, stereo);
  }
  std::printf(
      "  (deg / mm: worst pair against the truth; stereo: worst camera <-> camera translation "
      "error)\n");
}

// 1. Speed: 4 sensors x N views, single-threaded.
int speed(const Args& args) {
  {
    std::mt19937 rng(args.seed);
    sim::RigSceneOptions so;
    so.num_poses = args.views;
    auto scene = sim::generateRigScene(sim::defaultRig(), so, rng);
    if (!scene) {
      std::fprintf(stderr, "scene: %s\n", scene.error().c_str());
      return 1;
    }
    for (bool covariance : {false, true}) {
      MsgGraphOptions o;
      o.num_threads = 1;
      o.compute_covariance = covariance;
      std::vector<double> total, graph, cpu;
      MsgSolution sol;
      for (int r = 0; r < 5; ++r) {
        const std::clock_t c0 = std::clock();
        sol = solveMsgGraph(scene->problem, o);
        cpu.push_back(1000.0 * static_cast<double>(std::clock() - c0) / CLOCKS_PER_SEC);
        if (!sol.success) {
          std::fprintf(stderr, "solve: %s\n", sol.reason.c_str());
          return 1;
        }
        total.push_back(sol.solve_time_ms);
        graph.push_back(sol.graph_time_ms);
      }
      std::sort(total.begin(), total.end());
      std::sort(graph.begin(), graph.end());
      std::sort(cpu.begin(), cpu.end());
      double rot = 0, trans = 0;
      worstPair(sol, *scene, 4, &rot, &trans);
      std::printf(
          "speed: 4 sensors x %d views, 1 thread, covariance %s: whole call median %.0f ms wall, "
          "%.0f ms CPU (global solves %.0f ms wall), %d corner + %d plane + %d line terms, worst "
          "pair "
          "%.3f deg %.2f mm\n",
          args.views, covariance ? "on " : "off", total[2], cpu[2], graph[2],
          sol.residuals.corner_terms, sol.residuals.plane_terms, sol.residuals.line_terms, rot,
          trans);
    }
  }

  return 0;
}

// The graph options compared: the default and one ingredient off at a time.
std::vector<Variant> graphVariants() {
  std::vector<Variant> variants;
  variants.push_back({"default (planes + corners + PBPC lines)", MsgGraphOptions()});
  {
    MsgGraphOptions o;
    o.balance_plane_pairs = !o.balance_plane_pairs;
    variants.push_back(
        {o.balance_plane_pairs ? "with plane-pair balancing" : "without plane-pair balancing", o});
  }
  {
    MsgGraphOptions o;
    o.use_line_terms = false;
    variants.push_back({"without PBPC line terms", o});
  }
  {
    MsgGraphOptions o;
    o.use_corner_terms = false;
    variants.push_back({"without corner terms", o});
  }
  {
    MsgGraphOptions o;
    o.estimate_sensor_noise = false;
    variants.push_back({"without noise estimation", o});
  }
  {
    MsgGraphOptions o;
    o.use_line_terms = false;
    o.estimate_sensor_noise = false;
    o.loss = RobustLoss::kNone;
    o.outlier_rounds = 0;
    variants.push_back({"paper-like (no lines, noise est., loss, rejection)", o});
  }
  return variants;
}

// 2. Accuracy of each variant over several scenes (40 poses), clean rig and rig + noisy sensor.
int accuracyOfVariants(const Args& args) {
  std::vector<Variant> variants = graphVariants();
  for (bool noisy : {false, true}) {
    std::printf(
        "\naccuracy over %d scenes of 40 poses, %s (worst pair among the 4 rig sensors, vs "
        "truth):\n",
        args.scenes, noisy ? "rig + VLP-16 with 3x noise" : "rig (stereo + VLP-32C + OS1-64)");
    std::printf("  %-50s %10s %10s %10s %10s %8s %8s\n", "variant", "rot mean", "rot max",
                "trans mean", "trans max", "MLRE px", "ms");
    std::vector<sim::RigScene> scenes;
    for (int i = 0; i < args.scenes; ++i) {
      std::mt19937 rng(args.seed * 1000 + i);
      auto rig = sim::defaultRig();
      if (noisy) rig.push_back(sim::extraLidar16("vlp16_noisy", 3.0));
      auto scene = sim::generateRigScene(rig, sim::RigSceneOptions(), rng);
      if (!scene) {
        std::fprintf(stderr, "scene: %s\n", scene.error().c_str());
        return 1;
      }
      scenes.push_back(std::move(*scene));
    }
    for (auto& v : variants) {
      v.options.compute_covariance = false;
      double rot_sum = 0, rot_max = 0, tr_sum = 0, tr_max = 0, mlre_sum = 0, ms = 0;
      int failures = 0, mlre_count = 0;
      for (const auto& scene : scenes) {
        const MsgSolution sol = solveMsgGraph(scene.problem, v.options);
        if (!sol.success) {
          ++failures;
          continue;
        }
        double rot = 0, tr = 0;
        worstPair(sol, scene, 4, &rot, &tr);
        rot_sum += rot;
        tr_sum += tr;
        rot_max = std::max(rot_max, rot);
        tr_max = std::max(tr_max, tr);
        ms += sol.solve_time_ms;
        for (int c = 0; c < 2; ++c)
          for (int l = 2; l < 4; ++l) {
            const auto m = pairMlrePx(scene.problem, c, l, *sensorTSensor(sol, c, l));
            if (m) {
              mlre_sum += *m;
              ++mlre_count;
            }
          }
      }
      const int ok = args.scenes - failures;
      if (ok == 0) {
        std::printf("  %-50s all failed\n", v.name);
        continue;
      }
      std::printf("  %-50s %10.3f %10.3f %10.2f %10.2f %8.2f %8.0f%s\n", v.name, rot_sum / ok,
                  rot_max, tr_sum / ok, tr_max, mlre_count ? mlre_sum / mlre_count : 0.0, ms / ok,
                  failures ? (" (" + std::to_string(failures) + " failed)").c_str() : "");
    }
  }

  return 0;
}

// 3. Random starts (sigma 90 deg, 50 cm on every non-reference sensor).
void randomStarts(const Args& args) {
  if (args.trials > 0) {
    std::mt19937 rng(args.seed + 77);
    auto scene = sim::generateRigScene(sim::defaultRig(), sim::RigSceneOptions(), rng);
    MsgGraphOptions o;
    o.compute_covariance = false;
    const MsgSolution ref = solveMsgGraph(scene->problem, o);
    int converged = 0;
    double ms = 0;
    for (int t = 0; t < args.trials; ++t) {
      std::vector<Eigen::Isometry3d> start(4, Eigen::Isometry3d::Identity());
      for (int s = 1; s < 4; ++s)
        start[s] = perturb(scene->sensors[s].reference_T_sensor, 90.0 * kRadPerDeg, 0.5, rng);
      const MsgSolution sol = solveMsgGraph(scene->problem, o, start);
      ms += sol.solve_time_ms;
      bool same = sol.success;
      for (int s = 1; s < 4 && same; ++s)
        same = rotationErrorDeg(sol.sensors[s].reference_T_sensor,
                                ref.sensors[s].reference_T_sensor) < 0.01 &&
               translationErrorM(sol.sensors[s].reference_T_sensor,
                                 ref.sensors[s].reference_T_sensor) < 0.001;
      converged += same ? 1 : 0;
    }
    std::printf(
        "\nrandom starts (sigma 90 deg, 50 cm): %d / %d converged to the pairwise-initialised "
        "solution "
        "(%.0f ms mean)\n",
        converged, args.trials, ms / args.trials);
  }
}

}  // namespace

int main(int argc, char** argv) {
  Args args;
  if (!parseArgs(argc, argv, &args)) return 2;

  if (!args.scenario.empty()) return scenarioPairs(args);
  if (args.only_pairs) {
    pairsAgainstPbpc(args);
    return 0;
  }
  if (speed(args) != 0) return 1;
  pairsAgainstPbpc(args);
  if (accuracyOfVariants(args) != 0) return 1;
  randomStarts(args);
  return 0;
}
