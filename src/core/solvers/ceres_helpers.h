// Ceres pieces shared by the solver and the MSG-graph translation units (private: includes
// Ceres, so it stays out of the public headers).
#pragma once

#include <board_calib/core/solvers.h>

#include <ceres/ceres.h>

#include <mutex>
#include <utility>
#include <vector>

namespace board_calib {
namespace solvers_detail {

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
/// msg::MsgGraphOptions) applied to a silent Ceres solve.
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

/// Covariance of a solved problem, computed with Ceres and robust to errors shared within a
/// cluster of residuals (one camera plane, one image line, one MSG plane pair):
///   C = H^-1 B H^-1,  H^-1 = (J^T J)^-1 from ceres::Covariance (tangent space),
///   B = C/(C - dim) sum_c g_c g_c^T,  g_c = J_c^T r_c from each residual block's Ceres Jacobian.
/// When the residuals are independent with a common variance, B estimates sigma^2 H and C is
/// the usual sigma^2 (J^T J)^-1; when a view's points share its camera-plane error, the plain
/// scaled (J^T J)^-1 is too small by up to sqrt(points per view) and B accounts for it.
/// `blocks`: the rotation (EigenQuaternionManifold), the translation, then nuisance blocks
/// (marginalised). `clusters`: residual block -> cluster id. Output 6x6 in the solvers.h
/// convention (rotation vector of a left perturbation in rad: twice Ceres' quaternion tangent,
/// whose Plus is [cos|d|, sin|d| d/|d|] * q; translation in m). False when H is singular.
bool clusterRobustCovariance(ceres::Problem* problem, const std::vector<double*>& blocks,
                             const std::vector<std::pair<ceres::ResidualBlockId, int>>& clusters,
                             Matrix6d* covariance);

}  // namespace solvers_detail
}  // namespace board_calib
