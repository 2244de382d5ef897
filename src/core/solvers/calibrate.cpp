// PPC-Cal and PBPC-Cal: the solve schedule of each method and the solution with its quality
// figures (views and clusters: prepared_views.cpp; solves: cluster_solve.cpp).
#include "calibrate_internal.h"
#include "internal.h"

#include <chrono>
#include <limits>
#include <sstream>

namespace board_calib {

using namespace calibrate_detail;

Expected<Eigen::Isometry3d> closedFormInitialGuess(const std::vector<View>& views, Method method,
                                                   const SolverOptions& options) {
  const std::string invalid = options.validate();
  if (!invalid.empty())
    return Expected<Eigen::Isometry3d>::failure("invalid solver options: " + invalid);
  if (method == Method::kMsgPair)
    return closedFormPlaneToPlane(planeCorrespondences(views), options);
  const auto prepared = prepareAll(views, method, options);
  int used = 0;
  const std::string why = checkGeometry(prepared, method, options, &used);
  if (!why.empty()) return Expected<Eigen::Isometry3d>::failure(why);
  return closedForm(prepared, method, options);
}

namespace {

// The pose being solved, the clusters of its last solve and that solve's outcome.
struct Run {
  Pose pose;
  std::vector<Cluster> final_terms;
  PlaneErrorModel plane_model;
  SolveOutcome outcome;
  bool use_scale = false;
};

// One solve of `terms` from run->pose; false when Ceres gives no usable solution.
bool solveTerms(const std::vector<Cluster>& terms, bool scale, bool warm,
                const SolverOptions& options, Run* run, CalibrationSolution* sol,
                const PlaneErrorModel& model = PlaneErrorModel()) {
  run->outcome = solveStage(terms, scale, options, warm, &run->pose, model);
  sol->iterations += run->outcome.iterations;
  return run->outcome.usable;
}

// PPC: the paper's solve, then each view's offset and tilts weighted by the camera plane error
// estimated from the residuals (a few rounds: the estimate and the pose settle together).
bool runPpc(const std::vector<PreparedView>& prepared, const SolverOptions& options, Run* run,
            CalibrationSolution* sol) {
  run->final_terms = buildClusters(prepared, true, false, false, options.pbpc_line_weight);
  bool ok = solveTerms(run->final_terms, false, true, options, run, sol);
  for (int round = 0; ok && options.ppc_plane_error_model && round < kPlaneErrorRounds; ++round) {
    run->plane_model = choosePlaneErrorModel(run->final_terms, run->pose, options);
    if (!run->plane_model.enabled) break;
    ok = solveTerms(run->final_terms, false, false, options, run, sol, run->plane_model);
  }
  const PlaneErrorModel& m = run->plane_model;
  if (m.enabled) {
    std::ostringstream note;
    note.precision(3);
    note << "PPC views weighted by the camera plane error estimated from the residuals: offset "
         << 1000.0 * std::sqrt(m.offset_var) << " mm, tilt " << std::sqrt(m.tilt_var) * kDegPerRad
         << " deg per axis (1 sigma"
         << (m.distance_power > 0.0
                 ? ", at " + std::to_string(m.reference_distance_m).substr(0, 4) +
                       " m, growing with distance^2)"
                 : ", the same for every view)");
    sol->notes.push_back(note.str());
  }
  return ok;
}

// PBPC: as the paper (PPC first, then the line terms alone, then both) or one joint solve; then
// the edges re-associated by projection and solved again if any changed.
bool runPbpc(const std::vector<View>& views, std::vector<PreparedView>* prepared,
             const SolverOptions& options, Run* run, CalibrationSolution* sol) {
  const bool planes = options.pbpc_use_plane_terms;
  const double lw = options.pbpc_line_weight;
  bool ok = true;
  if (options.pbpc_schedule == PbpcSchedule::kSequential) {
    // With the final solve's free plane scale already here: a declared size 2 % off otherwise
    // puts this start several cm off, enough to pair edges wrongly in some view subsets.
    const auto plane_terms = buildClusters(*prepared, true, false, run->use_scale, lw);
    ok = plane_terms.empty() || solveTerms(plane_terms, run->use_scale, true, options, run, sol);
    // The plane-only pose already tells which LiDAR edge lies on which image line: pair them
    // before the line terms pull the pose towards wrongly named edges.
    if (ok && !plane_terms.empty() && options.edge_reassociation)
      reassociateEdges(views, prepared, run->pose.isometry(), &sol->notes);
    ok = ok && solveTerms(buildClusters(*prepared, false, true, false, lw), false,
                          plane_terms.empty(), options, run, sol);
  }
  run->final_terms = buildClusters(*prepared, planes, true, run->use_scale, lw);
  ok = ok && solveTerms(run->final_terms, run->use_scale,
                        options.pbpc_schedule == PbpcSchedule::kJoint, options, run, sol);
  // Re-pair and re-solve until the pairs are those of the final pose (the MLRE figures and the
  // overlay pair edges at that pose).
  for (int round = 0; ok && options.edge_reassociation && round < kMaxReassociationRounds &&
                      reassociateEdges(views, prepared, run->pose.isometry(), &sol->notes);
       ++round) {
    run->final_terms = buildClusters(*prepared, planes, true, run->use_scale, lw);
    ok = solveTerms(run->final_terms, run->use_scale, false, options, run, sol);
  }
  return ok;
}

// Covariance, observability and the plane-scale note of a solved run.
void finishSolution(const Run& run, const SolverOptions& options, CalibrationSolution* sol) {
  // PBPC solves the camera planes' depth scale itself (its edges fix the scale-free pose): the
  // declared size's check is that scale, and correcting the size does not move the result.
  if (run.use_scale && std::isfinite(run.pose.s)) {
    sol->declared_scale.estimated = true;
    sol->declared_scale.scale = run.pose.s;
  }
  if (options.compute_covariance) {
    double scale_variance = 0.0;
    const bool cov_ok =
        finalCovariance(run.final_terms, run.use_scale, run.plane_model, options, run.pose,
                        &sol->covariance, run.use_scale ? &scale_variance : nullptr);
    if (!cov_ok) sol->covariance.setConstant(std::numeric_limits<double>::infinity());
    if (cov_ok && run.use_scale && scale_variance > 0.0 && std::isfinite(run.pose.s)) {
      sol->declared_scale.checked = true;
      sol->declared_scale.stddev = std::sqrt(scale_variance);
    }
    sol->stddev = stddevFromCovariance(sol->covariance);
    sol->observability = solvers_detail::analyseObservability(
        sol->covariance, cov_ok, options.observability_max_stddev, "camera");
    if (!sol->observability.well_conditioned)
      sol->notes.push_back("weakly observable: " + sol->observability.weakest_description);
  }
  if (run.use_scale && std::abs(sol->plane_scale - 1.0) > options.plane_scale_note_threshold) {
    std::ostringstream note;
    note.precision(3);
    note << "camera board planes fit best scaled by " << sol->plane_scale
         << (sol->plane_scale > 1.0
                 ? ": the board is larger than declared or LiDAR edges bloom"
                 : ": the board is smaller than declared or LiDAR edges are eroded");
    sol->notes.push_back(note.str());
  }
}

// Prepares the views, checks them and finds the start; false (and sol->reason) when they
// cannot be solved.
bool prepareStart(const std::vector<View>& views, Method method, const SolverOptions& options,
                  const std::optional<Eigen::Isometry3d>& initial_guess,
                  std::vector<PreparedView>* prepared, CalibrationSolution* sol) {
  double step_rad = 0.0;
  *prepared = prepareAll(views, method, options, &step_rad);
  if (method == Method::kPbpc && options.edge_outward_shift_steps != 0.0) {
    std::ostringstream note;
    note.precision(3);
    if (step_rad > 0.0)
      note << "LiDAR edge points shifted outward by " << options.edge_outward_shift_steps << " x "
           << step_rad * kDegPerRad << " deg horizontal step"
           << (options.lidar_horizontal_resolution_deg > 0.0
                   ? ""
                   : " (step estimated from the board points)");
    else
      note << "LiDAR horizontal step could not be estimated: edge points not shifted";
    sol->notes.push_back(note.str());
  }
  int used = 0;
  const std::string why = checkGeometry(*prepared, method, options, &used);
  for (const auto& v : *prepared)
    if (!v.used) sol->notes.push_back("view " + std::to_string(v.id) + " skipped: " + v.reason);
  if (!why.empty()) {
    sol->reason = why;
    fillResidualFigures(views, *prepared, method, sol);
    return false;
  }
  sol->views_used = used;

  if (initial_guess) {
    sol->initial_guess = *initial_guess;
  } else {
    auto guess = closedForm(*prepared, method, options);
    if (!guess) {
      sol->reason = guess.error();
      return false;
    }
    sol->initial_guess = *guess;
    sol->used_closed_form_init = true;
  }
  return true;
}

// PPC puts each camera plane at the distance the declared board size gives: a size 1 % off
// moves every plane 1 % of its distance, and the result's translation with it, while the
// residuals barely show it (all planes move alike). The same clusters solved with one scale on
// the camera plane offsets measure the size the LiDAR sees.
void checkDeclaredScale(const std::vector<PreparedView>& prepared, const SolverOptions& options,
                        const Run& ppc, CalibrationSolution* sol) {
  Run scaled;
  scaled.pose = ppc.pose;
  scaled.pose.s = 1.0;
  scaled.use_scale = true;
  scaled.plane_model = ppc.plane_model;
  scaled.final_terms = buildClusters(prepared, true, false, true, options.pbpc_line_weight);
  CalibrationSolution scratch;
  if (!solveTerms(scaled.final_terms, true, false, options, &scaled, &scratch, ppc.plane_model) ||
      !std::isfinite(scaled.pose.s))
    return;
  if (!options.compute_covariance) {  // a fold: the scale alone
    sol->declared_scale.estimated = true;
    sol->declared_scale.scale = scaled.pose.s;
    return;
  }
  Matrix6d covariance;
  double scale_variance = 0.0;
  if (!finalCovariance(scaled.final_terms, true, ppc.plane_model, options, scaled.pose, &covariance,
                       &scale_variance) ||
      !(scale_variance > 0.0) || !std::isfinite(scaled.pose.s))
    return;
  DeclaredScaleCheck& check = sol->declared_scale;
  check.checked = true;
  check.estimated = true;
  check.scale = scaled.pose.s;
  check.stddev = std::sqrt(scale_variance);
  check.shift = poseDelta(scaled.pose.isometry(), sol->camera_T_lidar);
  // The solve took the declared size as exact; its 1 sigma gets the scale's.
  if (sol->covariance.allFinite()) {
    sol->covariance += declaredScaleUncertainty(check);
    sol->stddev = stddevFromCovariance(sol->covariance);
  }
}

// Defined after calibrate, which it calls.
void addEdgeBiasUncertainty(const std::vector<View>& views, const SolverOptions& options,
                            CalibrationSolution* sol);

}  // namespace

CalibrationSolution calibrate(const std::vector<View>& views, Method method,
                              const SolverOptions& options,
                              const std::optional<Eigen::Isometry3d>& initial_guess) {
  const auto start = std::chrono::steady_clock::now();
  auto elapsed_ms = [&] {
    return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start)
        .count();
  };
  CalibrationSolution sol;
  sol.method = method;
  const std::string invalid = options.validate();
  if (!invalid.empty()) {
    sol.reason = "invalid solver options: " + invalid;
    return sol;
  }
  if (views.empty()) {
    sol.reason = "no views";
    return sol;
  }
  if (initial_guess && (!initial_guess->matrix().allFinite())) {
    sol.reason = "the initial guess is not finite";
    return sol;
  }
  if (method == Method::kMsgPair) {
    sol = solvers_detail::calibrateMsgPair(views, options, initial_guess);
    sol.solve_time_ms = elapsed_ms();
    return sol;
  }

  std::vector<PreparedView> prepared;
  if (!prepareStart(views, method, options, initial_guess, &prepared, &sol)) return sol;
  Run run;
  run.pose = Pose::from(sol.initial_guess);
  run.use_scale =
      method == Method::kPbpc && options.estimate_plane_scale && options.pbpc_use_plane_terms;
  const bool ok = method == Method::kPpc ? runPpc(prepared, options, &run, &sol)
                                         : runPbpc(views, &prepared, options, &run, &sol);
  sol.camera_T_lidar = run.pose.isometry();
  sol.final_cost = run.outcome.cost;
  sol.termination = run.outcome.termination;
  sol.plane_scale = run.use_scale ? run.pose.s : 1.0;
  if (!ok || !sol.camera_T_lidar.matrix().allFinite()) {
    sol.reason = "Ceres solution not usable: " + run.outcome.message;
    return sol;
  }
  fillResidualFigures(views, prepared, method, &sol);
  finishSolution(run, options, &sol);
  if (method == Method::kPpc && options.check_declared_scale &&
      (options.compute_covariance || options.declared_scale_without_covariance))
    checkDeclaredScale(prepared, options, run, &sol);
  if (method == Method::kPbpc && options.compute_covariance && options.edge_bias_range_steps > 0.0)
    addEdgeBiasUncertainty(views, options, &sol);
  sol.success = true;
  sol.solve_time_ms = elapsed_ms();
  return sol;
}

namespace {

// The edge points' net sampling bias lies somewhere over edge_bias_range_steps: the result
// solved with the shift at the range's other end says how far it can move, and half that change
// becomes a 1 sigma along it.
void addEdgeBiasUncertainty(const std::vector<View>& views, const SolverOptions& options,
                            CalibrationSolution* sol) {
  constexpr double kMaxShiftSteps = 2.0;  // SolverOptions::validate's bound
  SolverOptions other = options;
  other.edge_bias_range_steps = 0.0;
  other.compute_covariance = false;
  other.edge_outward_shift_steps += options.edge_bias_range_steps;
  if (other.edge_outward_shift_steps > kMaxShiftSteps)
    other.edge_outward_shift_steps -= 2.0 * options.edge_bias_range_steps;
  const CalibrationSolution alt = calibrate(views, Method::kPbpc, other, sol->camera_T_lidar);
  if (!alt.success) {
    sol->notes.push_back("the LiDAR edge sampling bias could not be assessed (" + alt.reason +
                         "): the 1 sigma leaves it out");
    return;
  }
  const Vector6d half = 0.5 * poseDelta(alt.camera_T_lidar, sol->camera_T_lidar);
  sol->edge_bias_covariance = half * half.transpose();
  std::ostringstream note;
  note.precision(2);
  note << std::fixed << "1 sigma includes the LiDAR edge sampling bias: moving the edge points "
       << options.edge_bias_range_steps << " horizontal step moves the result by "
       << 2.0 * half.tail<3>().norm() * 1e3 << " mm / " << 2.0 * half.head<3>().norm() * kDegPerRad
       << " deg";
  sol->notes.push_back(note.str());
}

}  // namespace
}  // namespace board_calib
