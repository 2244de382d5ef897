// Private helpers shared by the solver translation units (no Ceres here).
#pragma once

#include <board_calib/core/common/board_geometry.h>
#include <board_calib/core/solvers/solvers.h>

#include <string>
#include <vector>

namespace board_calib {
namespace solvers_detail {

/// Derivative of the robust loss at squared residual s (1 for no loss).
double robustWeight(RobustLoss loss, double scale, double squared_residual);

/// Eigen-analysis of a 6x6 covariance (rotation in rad taken at a 1 m lever arm).
Observability analyseObservability(const Matrix6d& covariance, bool ok, double max_weak_stddev,
                                   const std::string& frame_name);

/// Kabsch: R minimising sum w |a_i - R b_i|^2. Fails when the pairs do not fix a rotation.
Expected<Eigen::Matrix3d> alignVectors(const std::vector<Eigen::Vector3d>& a,
                                       const std::vector<Eigen::Vector3d>& b,
                                       const std::vector<double>& weights);

/// Angle (deg) whose sine is the k-th singular value (k = 1 or 2, 0-based, descending) of the
/// stacked unit normals divided by sqrt(count): 0 when all normals are parallel (k = 1) or
/// coplanar (k = 2).
double normalSpreadDeg(const std::vector<Eigen::Vector3d>& normals, int k);

/// calibrate() for Method::kMsgPair: camera plane (a) and LiDAR plane (b) per view, then
/// solvePlaneToPlane, with the same quality figures as the other methods (plane_to_plane.cpp).
CalibrationSolution calibrateMsgPair(const std::vector<View>& views, const SolverOptions& options,
                                     const std::optional<Eigen::Isometry3d>& initial_guess);

}  // namespace solvers_detail
}  // namespace board_calib
