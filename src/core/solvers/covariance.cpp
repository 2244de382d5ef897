// Cluster-robust covariance of a solved Ceres problem (see ceres_helpers.h).
#include "ceres_helpers.h"

#include <Eigen/Core>

#include <map>

namespace board_calib {
namespace solvers_detail {

namespace {
// Ceres' quaternion tangent d rotates by 2|d|: the rotation vector is 2 d.
constexpr double kRotationPerQuaternionTangent = 2.0;
}  // namespace

bool clusterRobustCovariance(ceres::Problem* problem, const std::vector<double*>& blocks,
                             const std::vector<std::pair<ceres::ResidualBlockId, int>>& clusters,
                             Matrix6d* covariance, std::vector<double>* nuisance_variances) {
  using RowMatrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
  std::map<const double*, int> offset_of;
  int dim = 0;
  for (double* b : blocks) {
    offset_of[b] = dim;
    dim += problem->ParameterBlockTangentSize(b);
  }
  if (dim < 6) return false;

  // Bread: (J^T J)^-1 over all the blocks, from Ceres.
  quietCeresLogging();
  ceres::Covariance::Options co;
  co.algorithm_type = ceres::DENSE_SVD;
  co.num_threads = 1;
  ceres::Covariance ceres_covariance(co);
  const std::vector<const double*> const_blocks(blocks.begin(), blocks.end());
  if (!ceres_covariance.Compute(const_blocks, problem)) return false;
  RowMatrix H_inv(dim, dim);
  if (!ceres_covariance.GetCovarianceMatrixInTangentSpace(const_blocks, H_inv.data())) return false;

  // Meat: the scores of each cluster from the residual blocks' Jacobians (tangent space).
  std::map<int, Eigen::VectorXd> scores;
  std::vector<double*> params;
  for (const auto& [id, cluster] : clusters) {
    params.clear();
    problem->GetParameterBlocksForResidualBlock(id, &params);
    const int m = problem->GetCostFunctionForResidualBlock(id)->num_residuals();
    Eigen::VectorXd r(m);
    std::vector<RowMatrix> jac(params.size());
    std::vector<double*> jac_ptr(params.size(), nullptr);
    for (size_t k = 0; k < params.size(); ++k) {
      if (!offset_of.count(params[k])) continue;
      jac[k].resize(m, problem->ParameterBlockTangentSize(params[k]));
      jac_ptr[k] = jac[k].data();
    }
    double cost = 0.0;
    if (!problem->EvaluateResidualBlock(id, true, &cost, r.data(), jac_ptr.data())) return false;
    auto it = scores.try_emplace(cluster, Eigen::VectorXd::Zero(dim)).first;
    for (size_t k = 0; k < params.size(); ++k)
      if (jac_ptr[k])
        it->second.segment(offset_of[params[k]], jac[k].cols()) += jac[k].transpose() * r;
  }
  const double count = static_cast<double>(scores.size());
  if (count <= dim) return false;
  Eigen::MatrixXd B = Eigen::MatrixXd::Zero(dim, dim);
  for (const auto& kv : scores) B.noalias() += kv.second * kv.second.transpose();
  B *= count / (count - dim);  // small-sample correction

  const Eigen::MatrixXd tangent = H_inv * B * H_inv;
  Eigen::Matrix<double, 6, 1> scale;
  scale << Eigen::Vector3d::Constant(kRotationPerQuaternionTangent), Eigen::Vector3d::Ones();
  *covariance = scale.asDiagonal() * tangent.topLeftCorner<6, 6>() * scale.asDiagonal();
  *covariance = 0.5 * (*covariance + covariance->transpose()).eval();
  if (nuisance_variances) {
    nuisance_variances->clear();
    for (int i = 6; i < dim; ++i) nuisance_variances->push_back(tangent(i, i));
  }
  return covariance->allFinite();
}

}  // namespace solvers_detail
}  // namespace board_calib
