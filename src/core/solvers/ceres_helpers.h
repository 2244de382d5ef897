// Ceres pieces private to the solver translation units (the settings shared with the MSG graph
// are in core/common/ceres_helpers.h).
#pragma once

#include <board_calib/core/common/ceres_helpers.h>
#include <board_calib/core/solvers/solvers.h>

#include <ceres/ceres.h>

#include <utility>
#include <vector>

namespace board_calib {
namespace solvers_detail {

using ceres_common::applyStopCriteria;
using ceres_common::makeLoss;
using ceres_common::quietCeresLogging;

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
/// `nuisance_variances` (optional) receives the variances of the tangent entries past the pose.
bool clusterRobustCovariance(ceres::Problem* problem, const std::vector<double*>& blocks,
                             const std::vector<std::pair<ceres::ResidualBlockId, int>>& clusters,
                             Matrix6d* covariance,
                             std::vector<double>* nuisance_variances = nullptr);

}  // namespace solvers_detail
}  // namespace board_calib
