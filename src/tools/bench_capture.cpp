// bench_capture: capture and accuracy over camera rates, cloud layouts and seeds on simulated
// recordings with moving frames (issue 13's table in docs/BENCHMARKS.md).
//   bench_capture [--scenario FILE] [--rates 1,2,5,10,30] [--seeds N] [--poses N] [--scale S]
//                 [--method pbpc|ppc|msg|all] [--layouts organized,unorganized]
#include "support/sim_session.h"

#include <board_calib/core/pipeline/pair_calibration.h>
#include <board_calib/core/transform.h>

#include <cstdio>
#include <iostream>
#include <sstream>

using namespace board_calib;

namespace {

std::vector<std::string> split(const std::string& s) {
  std::vector<std::string> out;
  std::stringstream in(s);
  for (std::string item; std::getline(in, item, ',');) out.push_back(item);
  return out;
}

// One table row: a simulated capture session at `rate` Hz, calibrated and scored against the
// simulator's truth.
void printRow(const sim::Scenario& base, const std::string& rate, const std::string& layout,
              int seed, int poses, double scale, const std::vector<Method>& methods) {
  const sim::Scenario s = test_support::captureScenario(
      base, scale, std::stod(rate), layout == "organized", poses, static_cast<unsigned>(seed));
  auto session = test_support::runSimulatedSession(s, PipelineOptions{});
  if (!session) {
    std::printf("| %s | %s | %d | simulation failed: %s |\n", rate.c_str(), layout.c_str(), seed,
                session.error().c_str());
    return;
  }
  // Why holds were missed, for the table's notes (stderr keeps stdout a table).
  std::fprintf(stderr, "%s Hz %s seed %d: %s\n", rate.c_str(), layout.c_str(), seed,
               session->capture_summary.c_str());
  const PairCalibration run =
      calibratePair(session->views, methods, s.scene.target, "camera", "lidar");
  const MethodRun* c = run.chosenRun();
  const auto& truth = session->truth.camera_T_lidar;
  std::printf("| %s | %s | %d | %d/%d | %d | %zu | %s | %.3f | %.1f | %.3f / %.1f | %.0f |\n",
              rate.c_str(), layout.c_str(), seed, session->holds_captured, session->holds,
              session->moving_captured, session->views.size(), verdictName(run.verdict),
              c ? rotationErrorDeg(c->solution.camera_T_lidar, truth) : -1.0,
              c ? translationErrorM(c->solution.camera_T_lidar, truth) * 1e3 : -1.0,
              c ? c->verdict.stddev.rotation_deg.maxCoeff() : -1.0,
              c ? c->verdict.stddev.translation_m.maxCoeff() * 1e3 : -1.0, session->seconds);
}

}  // namespace

int main(int argc, char** argv) {
  std::string scenario_path =
      std::string(BOARD_CALIB_SOURCE_DIR) + "/config/scenarios/plain_vlp32c_1920.yaml";
  std::string rates = "1,2,5,10,30", layouts = "organized,unorganized", method = "pbpc";
  int seeds = 2, poses = 20;
  double scale = 1.0;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto next = [&]() -> std::string {
      if (i + 1 >= argc) {
        std::cerr << "bench_capture: " << a << " needs a value\n";
        std::exit(2);
      }
      return argv[++i];
    };
    try {
      if (a == "--scenario")
        scenario_path = next();
      else if (a == "--rates")
        rates = next();
      else if (a == "--layouts")
        layouts = next();
      else if (a == "--method")
        method = next();
      else if (a == "--seeds")
        seeds = std::stoi(next());
      else if (a == "--poses")
        poses = std::stoi(next());
      else if (a == "--scale")
        scale = std::stod(next());
      else {
        std::cerr << "usage: bench_capture [--scenario FILE] [--rates 1,2,5] [--layouts "
                     "organized,unorganized] "
                     "[--seeds N] [--poses N] [--scale S] [--method pbpc|ppc|msg|all]\n";
        return a == "--help" ? 0 : 2;
      }
    } catch (const std::exception&) {
      std::cerr << "bench_capture: " << a << " needs a number\n";
      return 2;
    }
  }
  auto base = sim::loadScenario(scenario_path);
  if (!base) {
    std::cerr << "bench_capture: " << base.error() << "\n";
    return 1;
  }
  const auto methods = parseMethods(method);
  if (!methods) {
    std::cerr << "bench_capture: " << methods.error() << "\n";
    return 2;
  }
  std::printf(
      "| camera Hz | cloud | seed | holds captured | moving captured | views | verdict | rotation "
      "error (deg) | translation error (mm) | reported 1 sigma (deg / mm) | time (s) |\n");
  std::printf("|---|---|---|---|---|---|---|---|---|---|---|\n");
  for (const auto& rate : split(rates))
    for (const auto& layout : split(layouts))
      for (int seed = 1; seed <= seeds; ++seed) {
        printRow(*base, rate, layout, seed, poses, scale, *methods);
        std::fflush(stdout);
      }
  return 0;
}
