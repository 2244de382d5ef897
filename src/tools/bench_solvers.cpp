// Benchmark of the solvers on synthetic features (ROS-free core only): solve time, accuracy
// against ground truth, robustness to random starts, and the measured choices of defaults
// (PBPC schedule, edge outward shift, plane offset factor).
//
//   bench_solvers [--seeds N] [--trials N]
#include <board_calib/core/solvers/solvers.h>
#include <board_calib/core/transform.h>
#include "support/synthetic_views.h"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <string>
#include <vector>

using namespace board_calib;

namespace {

struct Scenario {
  sim::SyntheticScene scene;
  double board_points = 0, edge_points = 0;  // per view
};

Scenario makeScenario(unsigned seed, const sim::SyntheticFeatureOptions& o) {
  std::mt19937 rng(seed);
  const Eigen::Isometry3d truth = sim::randomCameraTLidar(rng);
  auto scene = sim::generateSyntheticViews(o, truth, rng);
  if (!scene) {
    std::fprintf(stderr, "scene generation failed: %s\n", scene.error().c_str());
    std::exit(1);
  }
  Scenario s{*scene};
  for (const View& v : s.scene.views) {
    s.board_points += v.lidar.board_points.size();
    for (const auto& e : v.lidar.edge_points) s.edge_points += e.size();
  }
  s.board_points /= s.scene.views.size();
  s.edge_points /= s.scene.views.size();
  return s;
}

sim::SyntheticFeatureOptions thirtyViewsOf84Rings() {
  sim::SyntheticFeatureOptions o;
  o.num_views = 30;
  o.lidar_range_noise_m = 0.02;
  o.lidar_horizontal_resolution_deg = 0.2;
  o.line_noise_px = 0.3;
  o.max_board_points = 500;
  o.lidar_rings = 84;  // ~80 edge points per view at 2-5 m
  return o;
}

struct Accuracy {
  double rot_mean = 0, rot_max = 0, trans_mean = 0, trans_max = 0, mlre = 0, time_ms = 0;
  int failures = 0;
};

Accuracy accuracy(Method method, const SolverOptions& options, int seeds,
                  const sim::SyntheticFeatureOptions& o) {
  Accuracy a;
  std::vector<double> times;
  for (int seed = 1; seed <= seeds; ++seed) {
    const Scenario s = makeScenario(seed, o);
    const CalibrationSolution sol = calibrate(s.scene.views, method, options);
    if (!sol.success) {
      ++a.failures;
      continue;
    }
    const double r = rotationErrorDeg(sol.camera_T_lidar, s.scene.camera_T_lidar);
    const double t = translationErrorM(sol.camera_T_lidar, s.scene.camera_T_lidar);
    a.rot_mean += r / seeds;
    a.trans_mean += t / seeds;
    a.rot_max = std::max(a.rot_max, r);
    a.trans_max = std::max(a.trans_max, t);
    a.mlre += sol.mlre_px.value_or(0.0) / seeds;
    times.push_back(sol.solve_time_ms);
  }
  std::sort(times.begin(), times.end());
  if (!times.empty()) a.time_ms = times[times.size() / 2];
  return a;
}

void printAccuracy(const char* label, const Accuracy& a) {
  std::printf(
      "  %-44s rot mean %.3f max %.3f deg | trans mean %5.1f max %5.1f mm | MLRE %.2f px | %6.1f "
      "ms%s\n",
      label, a.rot_mean, a.rot_max, a.trans_mean * 1000, a.trans_max * 1000, a.mlre, a.time_ms,
      a.failures ? " | FAILURES" : "");
}

// Median wall time and median CPU time (the process's, so other load on the machine does not
// count) of `runs` solves, ms.
std::pair<double, double> medianSolveMs(const std::vector<View>& views, Method method,
                                        const SolverOptions& options, int runs) {
  std::vector<double> wall, cpu;
  for (int i = 0; i < runs; ++i) {
    const auto start = std::chrono::steady_clock::now();
    const std::clock_t cpu_start = std::clock();
    const CalibrationSolution sol = calibrate(views, method, options);
    cpu.push_back(1000.0 * (std::clock() - cpu_start) / CLOCKS_PER_SEC);
    wall.push_back(
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start)
            .count());
    if (!sol.success) std::printf("  solve failed: %s\n", sol.reason.c_str());
  }
  std::sort(wall.begin(), wall.end());
  std::sort(cpu.begin(), cpu.end());
  return {wall[wall.size() / 2], cpu[cpu.size() / 2]};
}

// The pair solvers' options compared in this benchmark.
struct Variants {
  SolverOptions defaults, joint, sequential;
  Variants() {
    joint.pbpc_schedule = PbpcSchedule::kJoint;
    sequential.pbpc_schedule = PbpcSchedule::kSequential;
  }
};

void printTiming(const Scenario& s, const Variants& v) {
  const SolverOptions &defaults = v.defaults, &joint = v.joint, &sequential = v.sequential;
  std::printf(
      "\nSolve time from the closed-form start (median of 20, one thread, including "
      "covariance):\n");
  const std::vector<std::pair<const char*, std::pair<Method, SolverOptions>>> timed = {
      {"ppc", {Method::kPpc, defaults}},
      {"pbpc joint", {Method::kPbpc, joint}},
      {"pbpc sequential (default)", {Method::kPbpc, sequential}},
      {"msg pairwise", {Method::kMsgPair, defaults}}};
  for (const auto& [label, what] : timed) {
    const auto [wall, cpu] = medianSolveMs(s.scene.views, what.first, what.second, 20);
    std::printf("  %-26s wall %6.1f ms, cpu %6.1f ms\n", label, wall, cpu);
  }
}

void printAccuracies(const sim::SyntheticFeatureOptions& o, int seeds, const Variants& v) {
  const SolverOptions &defaults = v.defaults, &joint = v.joint, &sequential = v.sequential;
  std::printf(
      "\nAccuracy against ground truth over %d seeds (closed-form initialisation, default "
      "options):\n",
      seeds);
  printAccuracy("ppc", accuracy(Method::kPpc, defaults, seeds, o));
  printAccuracy("pbpc joint", accuracy(Method::kPbpc, joint, seeds, o));
  printAccuracy("pbpc sequential (default)", accuracy(Method::kPbpc, sequential, seeds, o));
  printAccuracy("msg pairwise", accuracy(Method::kMsgPair, defaults, seeds, o));
}

// PPC weighting, the edge shift and a mis-declared board size, against ground truth.
void printModelChoices(const sim::SyntheticFeatureOptions& o, int seeds, const Variants& v) {
  const SolverOptions& defaults = v.defaults;
  std::printf(
      "\nPPC view weighting, camera planes from PnP (default) and with the earlier distance-free "
      "noise "
      "(0.2 deg, 3 mm):\n");
  SolverOptions paper_ppc = defaults;
  paper_ppc.ppc_plane_error_model = false;
  sim::SyntheticFeatureOptions flat = o;
  flat.camera_plane_from_pnp = false;
  printAccuracy("ppc error model (default), pnp planes",
                accuracy(Method::kPpc, defaults, seeds, o));
  printAccuracy("ppc 1/p_i (paper), pnp planes", accuracy(Method::kPpc, paper_ppc, seeds, o));
  printAccuracy("ppc error model, distance-free noise",
                accuracy(Method::kPpc, defaults, seeds, flat));
  printAccuracy("ppc 1/p_i (paper), distance-free noise",
                accuracy(Method::kPpc, paper_ppc, seeds, flat));
  printAccuracy("pbpc, distance-free noise", accuracy(Method::kPbpc, defaults, seeds, flat));
  printAccuracy("msg pairwise, distance-free noise",
                accuracy(Method::kMsgPair, defaults, seeds, flat));

  std::printf("\nEdge outward shift (per-scan-line extremes lie inside the edge):\n");
  for (double shift : {0.0, 0.5, 1.0}) {
    SolverOptions opt = defaults;
    opt.edge_outward_shift_steps = shift;
    char label[64];
    std::snprintf(label, sizeof(label), "pbpc shift %.1f steps", shift);
    printAccuracy(label, accuracy(Method::kPbpc, opt, seeds, o));
  }

  std::printf("\nBoard declared 3 %% too small (camera plane offsets / 1.03):\n");
  sim::SyntheticFeatureOptions small = o;
  small.declared_size_factor = 1.0 / 1.03;
  SolverOptions no_scale = defaults;
  no_scale.estimate_plane_scale = false;
  printAccuracy("ppc", accuracy(Method::kPpc, defaults, seeds, small));
  printAccuracy("pbpc with plane offset factor", accuracy(Method::kPbpc, defaults, seeds, small));
  printAccuracy("pbpc without plane offset factor",
                accuracy(Method::kPbpc, no_scale, seeds, small));
  printAccuracy("msg pairwise", accuracy(Method::kMsgPair, defaults, seeds, small));
}

void printRobustness(const Scenario& s, int trials, const Variants& v) {
  const SolverOptions &defaults = v.defaults, &joint = v.joint, &sequential = v.sequential;
  std::printf(
      "\nRobustness: %d random starts, rotation N(0, 90 deg), translation N(0, 50 cm) about "
      "identity; "
      "converged = within 0.5 deg / 2 cm of the method's solve from the closed-form start:\n",
      trials);
  RobustnessOptions robustness;
  robustness.trials = trials;
  struct Case {
    const char* label;
    Method method;
    SolverOptions options;
  };
  SolverOptions cauchy = defaults;
  cauchy.loss = RobustLoss::kCauchy;
  const std::vector<Case> cases = {{"ppc", Method::kPpc, defaults},
                                   {"pbpc joint", Method::kPbpc, joint},
                                   {"pbpc sequential", Method::kPbpc, sequential},
                                   {"msg pairwise", Method::kMsgPair, defaults},
                                   {"msg pairwise (cauchy)", Method::kMsgPair, cauchy}};
  for (const Case& c : cases) {
    const RobustnessReport r =
        evaluateRandomInitialisation(s.scene.views, c.method, c.options, robustness);
    if (!r.success) {
      std::printf("  %-24s failed: %s\n", c.label, r.reason.c_str());
      continue;
    }
    std::printf(
        "  %-24s converged %3d/%d (%.0f %%), spread rot %.4f deg trans %.2f mm (max), %.1f ms per "
        "solve\n",
        c.label, r.converged, r.trials, 100 * r.convergence_rate, r.rotation_spread_max_deg,
        r.translation_spread_max_m * 1000, r.mean_solve_time_ms);
  }
}

void printDefaultSolves(const Scenario& s, const Variants& v) {
  const SolverOptions& defaults = v.defaults;
  const CalibrationSolution ppc = calibrate(s.scene.views, Method::kPpc, defaults);
  for (const auto& n : ppc.notes) std::printf("\nPPC default on seed 1, note: %s\n", n.c_str());
  const CalibrationSolution sol = calibrate(s.scene.views, Method::kPbpc, defaults);
  std::printf(
      "\nPBPC default on seed 1: MLRE %.2f px, plane RMS %.1f mm, line RMS %.1f mm, 1 sigma rot "
      "(%.3f %.3f %.3f) "
      "deg trans (%.1f %.1f %.1f) mm, weakest: %s\n",
      sol.mlre_px.value_or(-1), sol.plane_rms_mm, sol.line_rms_mm, sol.stddev.rotation_deg.x(),
      sol.stddev.rotation_deg.y(), sol.stddev.rotation_deg.z(), sol.stddev.translation_m.x() * 1000,
      sol.stddev.translation_m.y() * 1000, sol.stddev.translation_m.z() * 1000,
      sol.observability.weakest_description.c_str());
  for (const auto& n : sol.notes) std::printf("  note: %s\n", n.c_str());
}

}  // namespace

int main(int argc, char** argv) {
  int seeds = 10, trials = 100;
  for (int i = 1; i + 1 < argc; i += 2) {
    if (!std::strcmp(argv[i], "--seeds"))
      seeds = std::atoi(argv[i + 1]);
    else if (!std::strcmp(argv[i], "--trials"))
      trials = std::atoi(argv[i + 1]);
  }
  const sim::SyntheticFeatureOptions o = thirtyViewsOf84Rings();
  const Scenario s = makeScenario(1, o);
  std::printf(
      "Scenario: %zu views, %.0f board points and %.0f edge points per view, range noise %.0f mm, "
      "horizontal step %.2f deg, line noise %.1f px\n",
      s.scene.views.size(), s.board_points, s.edge_points, o.lidar_range_noise_m * 1000,
      o.lidar_horizontal_resolution_deg, o.line_noise_px);

  const Variants variants;
  printTiming(s, variants);
  printAccuracies(o, seeds, variants);
  printModelChoices(o, seeds, variants);
  printRobustness(s, trials, variants);
  printDefaultSolves(s, variants);
  return 0;
}
