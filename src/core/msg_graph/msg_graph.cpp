// MSG-Cal multi-sensor graph: pairwise initialisation, spanning tree, global Ceres solve with
// outlier-observation rejection (see msg_graph.h for the formulation). The stages live in
// pairwise_links.cpp, graph_problem.cpp and graph_results.cpp.
#include "graph_internal.h"

#include <board_calib/core/common/statistics.h>

#include <cmath>

namespace board_calib {
namespace multi_sensor {

using namespace graph_detail;

namespace {

// Global solve: squared-loss plane stage, then every term with the robust loss, then
// reject-and-resolve rounds. False (and sol->reason) when a solve fails.
bool globalSolve(const MsgProblem& problem, const MsgGraphOptions& options, Graph* graph,
                 MsgSolution* sol) {
  const int n = static_cast<int>(problem.sensors.size());
  const int ref = problem.reference_sensor;
  const auto graph_start = Clock::now();
  auto stage = graph->solve(true, ref, false);
  sol->iterations += stage.iterations;
  if (!stage.usable) {
    sol->reason = "the plane stage of the graph solve failed: " + stage.message;
    return false;
  }
  std::vector<std::vector<std::vector<double>>> entries;
  for (int round = 0;; ++round) {
    stage = graph->solve(false, ref, true);
    sol->iterations += stage.iterations;
    if (!stage.usable) {
      sol->reason = "the graph solve failed: " + stage.message;
      return false;
    }
    graph->observationErrors(&entries, &sol->residuals);
    if (round >= options.outlier_rounds) break;
    int rejected = 0;
    auto& o = graph->observations();
    for (size_t p = 0; p < o.size(); ++p)
      for (int s = 0; s < n; ++s) {
        if (!o[p][s].active || entries[p][s].empty()) continue;
        const double m = medianOf(entries[p][s], EvenMedian::kMeanOfMiddle);
        if (m > options.outlier_gate_sigma) {
          o[p][s].active = false;
          sol->rejected.push_back({problem.poses[p].id, s, m});
          ++rejected;
        }
      }
    if (rejected == 0) break;
  }
  sol->graph_time_ms = msSince(graph_start);
  sol->final_cost = stage.cost;
  sol->termination = stage.termination;
  return true;
}

}  // namespace

const char* sensorKindName(SensorKind kind) {
  return kind == SensorKind::kCamera ? "camera" : "lidar";
}

std::string MsgGraphOptions::validate() const {
  for (double v : {camera_normal_sigma_deg, camera_offset_sigma_m, camera_pixel_sigma_px,
                   lidar_normal_sigma_deg, lidar_offset_sigma_m, lidar_edge_sigma_m})
    if (!(v > 0) || !std::isfinite(v)) return "every default sigma must be > 0";
  if (!(noise_estimate_max_ratio >= 1.0)) return "noise_estimate_max_ratio must be >= 1";
  if (min_shared_corners < 3) return "min_shared_corners must be >= 3";
  if (min_edge_points < 2) return "min_edge_points must be >= 2";
  if (!(loss_scale_sigma > 0)) return "loss_scale_sigma must be > 0";
  if (min_shared_views < 3)
    return "min_shared_views must be >= 3 (plane-to-plane needs three non-coplanar planes)";
  if (!(outlier_gate_sigma > 0)) return "outlier_gate_sigma must be > 0";
  if (outlier_rounds < 0) return "outlier_rounds must be >= 0";
  if (max_iterations < 1) return "max_iterations must be >= 1";
  if (!(function_tolerance >= 0) || !(gradient_tolerance >= 0) || !(parameter_tolerance >= 0))
    return "tolerances must be >= 0";
  if (num_threads < 1) return "num_threads must be >= 1";
  if (!(min_normal_spread_deg >= 0)) return "min_normal_spread_deg must be >= 0";
  return "";
}

MsgSolution solveMsgGraph(
    const MsgProblem& problem, const MsgGraphOptions& options,
    const std::optional<std::vector<Eigen::Isometry3d>>& initial_reference_T_sensor) {
  const auto start = Clock::now();
  MsgSolution sol;
  sol.reference_sensor = problem.reference_sensor;
  const std::string invalid = options.validate();
  if (!invalid.empty()) {
    sol.reason = "invalid MSG graph options: " + invalid;
    return sol;
  }
  const std::string bad = checkProblem(problem, initial_reference_T_sensor);
  if (!bad.empty()) {
    sol.reason = bad;
    return sol;
  }
  const int n = static_cast<int>(problem.sensors.size());
  const int ref = problem.reference_sensor;
  std::vector<Sigmas> sigmas;
  for (const auto& spec : problem.sensors) sigmas.push_back(resolveSigmas(spec, options));
  std::vector<std::vector<Obs>> obs = collectObservations(problem, &sol.notes);
  solveLinks(problem, options, obs, &sigmas, &sol);
  std::vector<Eigen::Isometry3d> init;
  if (!spanningTreeInit(problem, options, &sol, &init)) {
    sol.solve_time_ms = msSince(start);
    return sol;
  }
  if (initial_reference_T_sensor) {
    init = *initial_reference_T_sensor;
    sol.used_pairwise_init = false;
  }
  init[ref] = Eigen::Isometry3d::Identity();
  loopErrors(n, &sol);

  Graph graph(problem, options, sigmas, std::move(obs));
  for (int s = 0; s < n; ++s) graph.poses()[s].set(init[s]);
  if (!globalSolve(problem, options, &graph, &sol) ||
      !fillSensors(problem, options, graph, sigmas, init, &sol)) {
    sol.solve_time_ms = msSince(start);
    return sol;
  }
  if (options.compute_covariance) poseCovariance(options, graph, &sol);
  pairEstimates(&sol);
  finalNotes(problem, options, sigmas, &sol);
  sol.success = true;
  sol.solve_time_ms = msSince(start);
  return sol;
}

}  // namespace multi_sensor
}  // namespace board_calib
