// PPC-Cal and PBPC-Cal cluster solves: each cluster of points on one plane in closed form
// (its moments), robust losses by iteratively reweighted least squares, the camera plane
// error model of PPC and the cluster-robust covariance.
#include "calibrate_internal.h"
#include "ceres_helpers.h"
#include "cost_functions.h"
#include "internal.h"

#include <board_calib/core/common/statistics.h>

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <array>

namespace board_calib {
namespace calibrate_detail {

namespace {

constexpr double kPlaneScaleMin = 0.5;  // bounds of the offset factor: a plausible board
constexpr double kPlaneScaleMax = 2.0;
constexpr int kMaxIrlsRounds = 10;       // reweighting rounds of a robust solve
constexpr double kIrlsTolerance = 1e-9;  // rad / m / scale change that ends the rounds

// Weighted moments of one cluster's points: W = sum w, mean, scatter eigen-decomposition
// (eigenvalues ascending; the first is the noise thickness across the plane).
struct Moments {
  double W = 0.0;
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  Eigen::Vector3d lambda = Eigen::Vector3d::Zero();
  Eigen::Matrix3d axes = Eigen::Matrix3d::Identity();
};

Moments moments(const Points3& pts, const std::vector<double>* w) {
  Moments m;
  for (size_t k = 0; k < pts.size(); ++k) {
    const double wk = w ? (*w)[k] : 1.0;
    m.W += wk;
    m.mean += wk * pts[k];
  }
  if (!(m.W > 0.0)) return m;
  m.mean /= m.W;
  Eigen::Matrix3d S = Eigen::Matrix3d::Zero();
  for (size_t k = 0; k < pts.size(); ++k)
    S += (w ? (*w)[k] : 1.0) * (pts[k] - m.mean) * (pts[k] - m.mean).transpose();
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(S);
  m.lambda = eig.eigenvalues().cwiseMax(0.0);
  m.axes = eig.eigenvectors();
  return m;
}

// Variance of one point's residual along the plane normal, from the thickness of the cloud.
double pointVariance(const Moments& m) {
  constexpr double kPlaneDof = 3.0;
  return m.W > kPlaneDof + 1.0 ? m.lambda(0) / (m.W - kPlaneDof) : 0.0;
}

// The residual block of one cluster. Paper model: r_0 = sqrt(w W) (offset at the mean) and
// r_k = n . R a_k with a_k = sqrt(w lambda_k) v_k (exactly the weighted sum of squared point
// residuals). Plane-error model (plane clusters): the offset at the mean and the two tilts
// n . R v_k whitened by their variances, offset_var + s^2/W and tilt_var + s^2/lambda_k
// (s^2 the point variance): generalised least squares over the view's shared plane error.
ceres::CostFunction* clusterCost(const Cluster& cl, const Moments& m, bool scaled,
                                 const PlaneErrorModel& model, const Eigen::Isometry3d& T) {
  double sqrt_weight = 0.0;
  Eigen::Matrix3d axes = Eigen::Matrix3d::Zero();
  if (model.enabled && cl.plane) {
    // A view the robust loss has all but rejected (weights summing to no more than the plane's
    // degrees of freedom) has no point variance, and the model's variances may be 0: its terms
    // then carry no weight rather than an infinite one.
    const double s2 = pointVariance(m), f = model.factor(T * m.mean);
    const double offset_var = f * model.offset_var + s2 / m.W;
    sqrt_weight = offset_var > 0.0 ? 1.0 / std::sqrt(offset_var) : 0.0;
    for (int k = 1; k < 3; ++k) {
      const double tilt_var = m.lambda(k) > 0.0 ? f * model.tilt_var + s2 / m.lambda(k) : 0.0;
      if (tilt_var > 0.0) axes.col(k) = m.axes.col(k) / std::sqrt(tilt_var);
    }
  } else {
    sqrt_weight = std::sqrt(cl.weight * m.W);
    axes = m.axes * (cl.weight * m.lambda).cwiseSqrt().asDiagonal();
  }
  if (scaled)
    return solvers_detail::ScaledClusterPlaneCost::Create(cl.normal, cl.offset, sqrt_weight, m.mean,
                                                          axes);
  return solvers_detail::ClusterPlaneCost::Create(cl.normal, cl.offset, sqrt_weight, m.mean, axes);
}

// The Ceres problem of the clusters in closed form (ClusterPlaneCost), one residual block per
// cluster, with per-point weights (robust IRLS weights; all 1 when null). `blocks` receives each
// residual block with its cluster id.
void buildProblem(const std::vector<Cluster>& clusters,
                  const std::vector<std::vector<double>>* point_weights, bool estimate_scale,
                  const PlaneErrorModel& model, Pose* pose, ceres::Problem* problem,
                  std::vector<std::pair<ceres::ResidualBlockId, int>>* blocks = nullptr) {
  problem->AddParameterBlock(pose->q, 4, new ceres::EigenQuaternionManifold());
  problem->AddParameterBlock(pose->t, 3);
  if (estimate_scale) {
    problem->AddParameterBlock(&pose->s, 1);
    problem->SetParameterLowerBound(&pose->s, 0, kPlaneScaleMin);
    problem->SetParameterUpperBound(&pose->s, 0, kPlaneScaleMax);
  }
  const Eigen::Isometry3d T = pose->isometry();
  for (size_t c = 0; c < clusters.size(); ++c) {
    const Cluster& cl = clusters[c];
    const Moments m = moments(*cl.points, point_weights ? &(*point_weights)[c] : nullptr);
    if (!(m.W > 0.0)) continue;
    const bool scaled = estimate_scale && cl.scaled;
    ceres::CostFunction* cost = clusterCost(cl, m, scaled, model, T);
    const ceres::ResidualBlockId id =
        scaled ? problem->AddResidualBlock(cost, nullptr, pose->q, pose->t, &pose->s)
               : problem->AddResidualBlock(cost, nullptr, pose->q, pose->t);
    if (blocks) blocks->emplace_back(id, cl.id);
  }
}

// One Ceres solve of the clusters.
SolveOutcome solveWeighted(const std::vector<Cluster>& clusters,
                           const std::vector<std::vector<double>>* point_weights,
                           bool estimate_scale, const PlaneErrorModel& model,
                           const SolverOptions& options, Pose* pose) {
  ceres::Problem problem;
  buildProblem(clusters, point_weights, estimate_scale, model, pose, &problem);
  ceres::Solver::Options solver_options;
  solver_options.linear_solver_type = ceres::DENSE_QR;
  solvers_detail::applyStopCriteria(options, &solver_options);
  return ceres_common::solveAndSummarize(solver_options, &problem);
}

double residualOf(const Cluster& cl, const Eigen::Isometry3d& T, double s,
                  const Eigen::Vector3d& p) {
  return cl.normal.dot(T * p) - (cl.scaled ? s : 1.0) * cl.offset;
}

// Robust cost 1/2 sum_c w_c sum_m rho(r^2), as Ceres would report it.
double robustCost(const std::vector<Cluster>& clusters, const Pose& pose, RobustLoss loss,
                  double a) {
  const Eigen::Isometry3d T = pose.isometry();
  const double a2 = a * a;
  double cost = 0.0;
  for (const Cluster& cl : clusters) {
    double sum = 0.0;
    for (const auto& p : *cl.points) {
      const double r = residualOf(cl, T, pose.s, p), sq = r * r;
      switch (loss) {
        case RobustLoss::kNone: sum += sq; break;
        case RobustLoss::kHuber: sum += sq <= a2 ? sq : 2.0 * a * std::sqrt(sq) - a2; break;
        case RobustLoss::kCauchy: sum += a2 * std::log1p(sq / a2); break;
        case RobustLoss::kTukey: {
          const double v = sq <= a2 ? 1.0 - sq / a2 : 0.0;
          sum += a2 / 3.0 * (1.0 - v * v * v);
          break;
        }
      }
    }
    cost += 0.5 * cl.weight * sum;
  }
  return cost;
}

// The robust loss's weight rho'(r^2) of every point at the pose (all 1 for the squared loss).
std::vector<std::vector<double>> robustWeights(const std::vector<Cluster>& clusters,
                                               const Pose& pose, const SolverOptions& options) {
  const Eigen::Isometry3d T = pose.isometry();
  std::vector<std::vector<double>> weights(clusters.size());
  for (size_t c = 0; c < clusters.size(); ++c) {
    weights[c].resize(clusters[c].points->size());
    for (size_t m = 0; m < clusters[c].points->size(); ++m) {
      const double r = residualOf(clusters[c], T, pose.s, (*clusters[c].points)[m]);
      weights[c][m] = solvers_detail::robustWeight(options.loss, options.loss_scale_m, r * r);
    }
  }
  return weights;
}

// A solve with the requested loss: squared loss in closed form, robust losses by iteratively
// reweighted least squares with the loss's weight rho'(r^2) per point (its fixed point is a
// stationary point of the robust cost), optionally after a squared-loss solve.
}  // namespace

SolveOutcome solveStage(const std::vector<Cluster>& clusters, bool estimate_scale,
                        const SolverOptions& options, bool warm, Pose* pose,
                        const PlaneErrorModel& model) {
  SolveOutcome out;
  int iterations = 0;
  if (options.loss == RobustLoss::kNone || (warm && options.warm_start_unrobust)) {
    out = solveWeighted(clusters, nullptr, estimate_scale, model, options, pose);
    iterations += out.iterations;
    if (!out.usable || options.loss == RobustLoss::kNone) {
      out.iterations = iterations;
      return out;
    }
  }
  for (int round = 0; round < kMaxIrlsRounds; ++round) {
    const std::vector<std::vector<double>> weights = robustWeights(clusters, *pose, options);
    const Pose before = *pose;
    out = solveWeighted(clusters, &weights, estimate_scale, model, options, pose);
    iterations += out.iterations;
    if (!out.usable) break;
    const Eigen::Isometry3d after = pose->isometry();
    if (rotationErrorDeg(after, before.isometry()) * kRadPerDeg < kIrlsTolerance &&
        translationErrorM(after, before.isometry()) < kIrlsTolerance &&
        std::abs(pose->s - before.s) < kIrlsTolerance)
      break;
  }
  out.iterations = iterations;
  out.cost = robustCost(clusters, *pose, options.loss, options.loss_scale_m);
  return out;
}

namespace {

// Variance components of the camera planes from the residuals at the pose, for a distance
// power: per plane cluster the squared offset at the mean of the (robustly weighted) points
// minus its LiDAR share s^2/W, and the squared tilts minus s^2/lambda_k, each divided by the
// view's distance factor, averaged with the degrees of freedom the pose takes (3 of the
// offsets for the translation, 3 of the tilts for the rotation). `nll` receives the Gaussian
// negative log-likelihood of those residuals under the model, to compare distance powers.
// Disabled when too few views.
PlaneErrorModel estimatePlaneErrorModel(const std::vector<Cluster>& clusters, const Pose& pose,
                                        const SolverOptions& options, double distance_power,
                                        double* nll) {
  constexpr double kPoseDofPerKind = 3.0;
  struct ViewTerms {
    double f, s2_offset, offset_sq;
    std::array<double, 2> s2_tilt, tilt_sq;
  };
  const auto weights = robustWeights(clusters, pose, options);
  const Eigen::Isometry3d T = pose.isometry();
  std::vector<ViewTerms> views;
  std::vector<double> distances;
  for (size_t c = 0; c < clusters.size(); ++c) {
    const Cluster& cl = clusters[c];
    if (!cl.plane) continue;
    const Moments m = moments(*cl.points, &weights[c]);
    const double s2 = pointVariance(m);
    if (!(s2 > 0.0) || !(m.lambda(1) > 0.0)) continue;  // no point variance: nothing to split
    const double ro = residualOf(cl, T, pose.s, m.mean);
    ViewTerms v{};
    v.f = (T * m.mean).norm();  // distance for now, the factor below
    v.s2_offset = s2 / m.W;
    v.offset_sq = ro * ro;
    for (int k = 1; k < 3; ++k) {
      const double tilt = cl.normal.dot(T.linear() * m.axes.col(k));
      v.s2_tilt[k - 1] = s2 / m.lambda(k);
      v.tilt_sq[k - 1] = tilt * tilt;
    }
    distances.push_back(v.f);
    views.push_back(v);
  }
  PlaneErrorModel model;
  if (views.size() <= kPoseDofPerKind) return model;
  model.distance_power = distance_power;
  model.reference_distance_m = medianOf(distances);
  double offset_sum = 0.0, tilt_sum = 0.0;
  for (ViewTerms& v : views) {
    v.f = std::pow(v.f / model.reference_distance_m, distance_power);
    offset_sum += (v.offset_sq - v.s2_offset) / v.f;
    for (int k = 0; k < 2; ++k) tilt_sum += (v.tilt_sq[k] - v.s2_tilt[k]) / v.f;
  }
  const double n = static_cast<double>(views.size());
  model.enabled = true;
  model.offset_var = std::max(offset_sum / (n - kPoseDofPerKind), 0.0);
  model.tilt_var = std::max(tilt_sum / (2.0 * n - kPoseDofPerKind), 0.0);
  *nll = 0.0;
  for (const ViewTerms& v : views) {
    const double vo = v.f * model.offset_var + v.s2_offset;
    *nll += std::log(vo) + v.offset_sq / vo;
    for (int k = 0; k < 2; ++k) {
      const double vt = v.f * model.tilt_var + v.s2_tilt[k];
      *nll += std::log(vt) + v.tilt_sq[k] / vt;
    }
  }
  return model;
}

}  // namespace

// The better (by likelihood) of a distance-independent camera plane error and one growing as a
// PnP's (distance^4 in variance).
PlaneErrorModel choosePlaneErrorModel(const std::vector<Cluster>& clusters, const Pose& pose,
                                      const SolverOptions& options) {
  constexpr double kPnpDistancePower = 4.0;
  double nll_flat = 0.0, nll_pnp = 0.0;
  const PlaneErrorModel flat = estimatePlaneErrorModel(clusters, pose, options, 0.0, &nll_flat);
  const PlaneErrorModel pnp =
      estimatePlaneErrorModel(clusters, pose, options, kPnpDistancePower, &nll_pnp);
  return pnp.enabled && nll_pnp < nll_flat ? pnp : flat;
}

// The covariance of the final problem (the clusters with the robust weights at the final pose,
// the same residual blocks as the last solve) from Ceres, cluster-robust.
bool finalCovariance(const std::vector<Cluster>& clusters, bool estimate_scale,
                     const PlaneErrorModel& model, const SolverOptions& options, Pose pose,
                     Matrix6d* covariance, double* scale_variance) {
  const auto weights = robustWeights(clusters, pose, options);
  ceres::Problem problem;
  std::vector<std::pair<ceres::ResidualBlockId, int>> blocks;
  buildProblem(clusters, &weights, estimate_scale, model, &pose, &problem, &blocks);
  std::vector<double*> parameters = {pose.q, pose.t};
  if (estimate_scale) parameters.push_back(&pose.s);
  std::vector<double> nuisance;
  if (!solvers_detail::clusterRobustCovariance(&problem, parameters, blocks, covariance, &nuisance))
    return false;
  if (scale_variance && estimate_scale && !nuisance.empty()) *scale_variance = nuisance.front();
  return true;
}

}  // namespace calibrate_detail
}  // namespace board_calib
