// Ceres settings shared by the solver and the MSG-graph modules. Internal to the core: it
// includes Ceres, so no public header includes it.
#pragma once

#include <ceres/ceres.h>

#include <board_calib/core/solvers/solvers.h>

#include <mutex>
#include <string>

namespace board_calib {
namespace ceres_common {

/// Ceres logs through glog to stderr (e.g. "Covariance matrix is near rank deficient" in a
/// solve that then succeeds). The core never logs: every failure already comes back as a
/// reason, so Ceres' log lines below FATAL are switched off once for the process.
inline void quietCeresLogging() {
  static std::once_flag once;
  std::call_once(once, [] { FLAGS_minloglevel = google::GLOG_FATAL; });
}

/// The Ceres loss for a robust-loss kind at `scale`; nullptr (squared loss) for kNone.
inline ceres::LossFunction* makeLoss(RobustLoss loss, double scale) {
  switch (loss) {
    case RobustLoss::kNone: return nullptr;
    case RobustLoss::kHuber: return new ceres::HuberLoss(scale);
    case RobustLoss::kCauchy: return new ceres::CauchyLoss(scale);
    case RobustLoss::kTukey: return new ceres::TukeyLoss(scale);
  }
  return nullptr;
}

/// Iteration, tolerance and thread settings of an options struct (SolverOptions,
/// multi_sensor::MsgGraphOptions) applied to a silent Ceres solve.
template <typename Options>
void applyStopCriteria(const Options& options, ceres::Solver::Options* so) {
  so->max_num_iterations = options.max_iterations;
  so->function_tolerance = options.function_tolerance;
  so->gradient_tolerance = options.gradient_tolerance;
  so->parameter_tolerance = options.parameter_tolerance;
  so->num_threads = options.num_threads;
  so->logging_type = ceres::SILENT;
  quietCeresLogging();
}

/// What every solve reports of a Ceres run.
struct SolveOutcome {
  bool usable = false;
  double cost = 0.0;
  int iterations = 0;
  std::string termination;
  std::string message;
};

/// Runs Ceres on `problem` and keeps what the solvers report of it.
inline SolveOutcome solveAndSummarize(const ceres::Solver::Options& options,
                                      ceres::Problem* problem) {
  ceres::Solver::Summary summary;
  ceres::Solve(options, problem, &summary);
  SolveOutcome out;
  out.usable = summary.IsSolutionUsable();
  out.cost = summary.final_cost;
  out.iterations = static_cast<int>(summary.iterations.size());
  out.termination = ceres::TerminationTypeToString(summary.termination_type);
  out.message = summary.message;
  return out;
}

}  // namespace ceres_common
}  // namespace board_calib
