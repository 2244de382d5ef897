// Ceres pieces shared by the solver and the MSG-graph translation units (private: includes
// Ceres, so it stays out of the public headers).
#pragma once

#include <board_calib/core/solvers.h>

#include <ceres/ceres.h>

namespace board_calib {
namespace solvers_detail {

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
/// msg::MsgGraphOptions) applied to a silent Ceres solve.
template <typename Options>
void applyStopCriteria(const Options& options, ceres::Solver::Options* so) {
  so->max_num_iterations = options.max_iterations;
  so->function_tolerance = options.function_tolerance;
  so->gradient_tolerance = options.gradient_tolerance;
  so->parameter_tolerance = options.parameter_tolerance;
  so->num_threads = options.num_threads;
  so->logging_type = ceres::SILENT;
}

}  // namespace solvers_detail
}  // namespace board_calib
