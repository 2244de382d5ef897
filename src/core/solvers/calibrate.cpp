// PPC-Cal and PBPC-Cal: view checks, closed-form initialiser, Ceres solves, quality figures.
#include "ceres_helpers.h"
#include "cost_functions.h"
#include "internal.h"

#include <board_calib/core/common/edge_association.h>
#include <board_calib/core/transform.h>

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <memory>
#include <numeric>
#include <sstream>

namespace board_calib {

namespace {

constexpr int kMinEdgePoints = 2;          // a line term needs two points to constrain anything
constexpr int kMinPpcViews = 3;            // 3 non-coplanar planes fix the translation
constexpr int kMinPbpcViews = 2;           // 8 line correspondences: DLT-lines needs 6
constexpr double kUnitNormalTolerance = 1e-3;
constexpr double kPlaneScaleMin = 0.5;     // bounds of the offset factor: a plausible board
constexpr double kPlaneScaleMax = 2.0;
constexpr double kSameScanLineRad = 0.05 * kRadPerDeg;  // elevation gap that separates scan lines
constexpr size_t kMinScanLinePoints = 3;
constexpr double kMinAzimuthGapRad = 1e-4 * kRadPerDeg;  // duplicates are not a step
constexpr double kMaxPlausibleStepRad = 2.0 * kRadPerDeg;
constexpr int kMaxIrlsRounds = 10;         // reweighting rounds of a robust solve
constexpr double kIrlsTolerance = 1e-9;    // rad / m / scale change that ends the rounds
constexpr int kPlaneErrorRounds = 3;       // PPC: re-estimations of the camera plane error

// A set of points that must lie on one plane n . x = s d in the camera frame: one view's board
// points (camera plane) or one edge's points (back-projected plane, d = 0). Points share the
// weight (1/p_i or line_weight/q_ij) and the plane's measurement error.
struct Cluster {
  Eigen::Vector3d normal;
  double offset = 0.0;
  double weight = 1.0;
  bool scaled = false;  // offset multiplied by the global factor s
  bool plane = false;   // a camera plane (not a back-projected line plane)
  int id = 0;
  const Points3* points = nullptr;
};

struct PreparedView {
  int index = 0;
  int id = 0;
  std::string reason;
  bool plane_ok = false;
  Eigen::Vector3d cam_normal = Eigen::Vector3d::UnitZ();
  double cam_offset = 0.0;
  bool lidar_plane_ok = false;
  Eigen::Vector3d lidar_normal = Eigen::Vector3d::UnitZ();
  double lidar_offset = 0.0;
  const Points3* board_points = nullptr;
  std::array<bool, kNumEdges> image_edge_ok{};
  std::array<Eigen::Vector3d, kNumEdges> backprojected_normal;  // unit K^T l
  std::array<bool, kNumEdges> lidar_edge_ok{};
  std::array<Points3, kNumEdges> lidar_edges;  // possibly shifted outward
  std::array<int, kNumEdges> association{{0, 1, 2, 3}};  // image edge -> LiDAR edge
  bool used = false;

  int lineCount() const {
    int n = 0;
    for (int j = 0; j < kNumEdges; ++j)
      if (image_edge_ok[j] && association[j] >= 0 && lidar_edge_ok[association[j]]) ++n;
    return n;
  }
};

bool finitePoints(const Points3& points, size_t* bad) {
  for (size_t i = 0; i < points.size(); ++i)
    if (!points[i].allFinite()) {
      *bad = i;
      return false;
    }
  return true;
}

bool unitNormal(const Plane& plane, Eigen::Vector3d* normal, double* offset) {
  if (!plane.normal.allFinite() || !std::isfinite(plane.offset)) return false;
  if (std::abs(plane.normal.norm() - 1.0) > kUnitNormalTolerance) return false;
  *normal = plane.normal.normalized();
  *offset = plane.offset;
  return true;
}

// Rotates a point about the LiDAR z axis (a horizontal step along its scan line).
Eigen::Vector3d rotateAboutZ(const Eigen::Vector3d& p, double angle) {
  const double c = std::cos(angle), s = std::sin(angle);
  return {c * p.x() - s * p.y(), s * p.x() + c * p.y(), p.z()};
}

double wrapAngle(double a) { return std::atan2(std::sin(a), std::cos(a)); }

PreparedView prepareView(const View& view, int index, Method method, const SolverOptions& options,
                         double horizontal_step_rad) {
  PreparedView pv;
  pv.index = index;
  pv.id = view.id;
  auto fail = [&](const std::string& why) {
    pv.reason = why;
    return pv;
  };
  if (!view.camera.found) return fail("camera found no board" + (view.camera.reason.empty() ? "" : ": " + view.camera.reason));
  if (!view.lidar.found) return fail("LiDAR found no board" + (view.lidar.reason.empty() ? "" : ": " + view.lidar.reason));
  const Eigen::Matrix3d& K = view.camera.K;
  if (!K.allFinite() || !(K(0, 0) > 0.0) || !(K(1, 1) > 0.0)) return fail("camera K is not a valid intrinsic matrix");
  size_t bad = 0;
  if (view.lidar.board_points.empty()) return fail("no LiDAR board points");
  if (!finitePoints(view.lidar.board_points, &bad))
    return fail("LiDAR board point " + std::to_string(bad) + " is not finite");
  for (int j = 0; j < kNumEdges; ++j)
    if (!finitePoints(view.lidar.edge_points[j], &bad))
      return fail(std::string("LiDAR ") + edgeName(j) + " edge point " + std::to_string(bad) + " is not finite");
  pv.board_points = &view.lidar.board_points;

  pv.plane_ok = unitNormal(view.camera.plane, &pv.cam_normal, &pv.cam_offset);
  pv.lidar_plane_ok = unitNormal(view.lidar.plane, &pv.lidar_normal, &pv.lidar_offset);
  if (method == Method::kPpc && !pv.plane_ok) return fail("camera board plane is not finite or its normal not unit");

  // LiDAR edges, optionally shifted outward along the scan line by a fraction of the step.
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  for (const auto& p : view.lidar.board_points) centroid += p;
  centroid /= static_cast<double>(view.lidar.board_points.size());
  const double centre_azimuth = std::atan2(centroid.y(), centroid.x());
  const double shift = options.edge_outward_shift_steps * horizontal_step_rad;
  for (int j = 0; j < kNumEdges; ++j) {
    pv.lidar_edge_ok[j] = view.lidar.edge_valid[j] && static_cast<int>(view.lidar.edge_points[j].size()) >= kMinEdgePoints;
    if (!pv.lidar_edge_ok[j]) continue;
    pv.lidar_edges[j] = view.lidar.edge_points[j];
    if (shift != 0.0) {
      for (auto& p : pv.lidar_edges[j]) {
        const double side = wrapAngle(std::atan2(p.y(), p.x()) - centre_azimuth) >= 0.0 ? 1.0 : -1.0;
        p = rotateAboutZ(p, side * shift);
      }
    }
  }
  for (int j = 0; j < kNumEdges; ++j) {
    const Eigen::Vector3d& l = view.camera.edge_lines[j];
    if (!view.camera.edge_valid[j] || !l.allFinite() || !(l.head<2>().norm() > 0.0)) continue;
    const Eigen::Vector3d N = K.transpose() * l;
    if (!(N.norm() > 0.0)) continue;
    pv.backprojected_normal[j] = N.normalized();
    pv.image_edge_ok[j] = true;
  }
  if (method == Method::kPbpc && pv.lineCount() == 0)
    return fail("no edge valid in both the image and the LiDAR");
  pv.used = true;
  return pv;
}

std::vector<Cluster> buildClusters(const std::vector<PreparedView>& views, bool planes, bool lines, bool scaled,
                                   double line_weight) {
  std::vector<Cluster> clusters;
  for (const PreparedView& v : views) {
    if (!v.used) continue;
    if (planes && v.plane_ok)
      clusters.push_back({v.cam_normal, v.cam_offset, 1.0 / static_cast<double>(v.board_points->size()), scaled,
                          true, v.index * (kNumEdges + 1), v.board_points});
    if (lines) {
      for (int j = 0; j < kNumEdges; ++j) {
        const int k = v.association[j];
        if (!v.image_edge_ok[j] || k < 0 || !v.lidar_edge_ok[k]) continue;
        clusters.push_back({v.backprojected_normal[j], 0.0, line_weight / static_cast<double>(v.lidar_edges[k].size()),
                            false, false, v.index * (kNumEdges + 1) + 1 + j, &v.lidar_edges[k]});
      }
    }
  }
  return clusters;
}

struct Pose {
  double q[4] = {0, 0, 0, 1};  // x y z w
  double t[3] = {0, 0, 0};
  double s = 1.0;

  static Pose from(const Eigen::Isometry3d& T) {
    Pose p;
    Eigen::Quaterniond q(T.linear());
    q.normalize();
    Eigen::Map<Eigen::Quaterniond>(p.q) = q;
    Eigen::Map<Eigen::Vector3d>(p.t) = T.translation();
    return p;
  }
  Eigen::Isometry3d isometry() const {
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    T.linear() = Eigen::Map<const Eigen::Quaterniond>(q).normalized().toRotationMatrix();
    T.translation() = Eigen::Map<const Eigen::Vector3d>(t);
    return T;
  }
};

struct SolveOutcome {
  bool usable = false;
  double cost = 0.0;
  int iterations = 0;
  std::string termination;
  std::string message;
};

// Per-view error of the camera plane (PPC): variance of its offset (m^2) and of its tilt about
// each in-plane axis (rad^2), shared by all points of the view, at the reference distance and
// scaled by (distance / reference)^distance_power (0: the same for every view; 4: as a PnP's
// error, which grows with the square of the distance). Disabled: the paper's model (every
// point an independent residual, weight 1/p_i).
struct PlaneErrorModel {
  bool enabled = false;
  double offset_var = 0.0;
  double tilt_var = 0.0;
  double distance_power = 0.0;
  double reference_distance_m = 1.0;

  double factor(const Eigen::Vector3d& point_in_camera) const {
    return distance_power == 0.0 ? 1.0 : std::pow(point_in_camera.norm() / reference_distance_m, distance_power);
  }
};

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
  for (size_t k = 0; k < pts.size(); ++k) S += (w ? (*w)[k] : 1.0) * (pts[k] - m.mean) * (pts[k] - m.mean).transpose();
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
ceres::CostFunction* clusterCost(const Cluster& cl, const Moments& m, bool scaled, const PlaneErrorModel& model,
                                 const Eigen::Isometry3d& T) {
  double sqrt_weight = 0.0;
  Eigen::Matrix3d axes = Eigen::Matrix3d::Zero();
  if (model.enabled && cl.plane) {
    const double s2 = pointVariance(m), f = model.factor(T * m.mean);
    sqrt_weight = 1.0 / std::sqrt(f * model.offset_var + s2 / m.W);
    for (int k = 1; k < 3; ++k)
      if (m.lambda(k) > 0.0) axes.col(k) = m.axes.col(k) / std::sqrt(f * model.tilt_var + s2 / m.lambda(k));
  } else {
    sqrt_weight = std::sqrt(cl.weight * m.W);
    axes = m.axes * (cl.weight * m.lambda).cwiseSqrt().asDiagonal();
  }
  if (scaled) return solvers_detail::ScaledClusterPlaneCost::Create(cl.normal, cl.offset, sqrt_weight, m.mean, axes);
  return solvers_detail::ClusterPlaneCost::Create(cl.normal, cl.offset, sqrt_weight, m.mean, axes);
}

// The Ceres problem of the clusters in closed form (ClusterPlaneCost), one residual block per
// cluster, with per-point weights (robust IRLS weights; all 1 when null). `blocks` receives each
// residual block with its cluster id.
void buildProblem(const std::vector<Cluster>& clusters, const std::vector<std::vector<double>>* point_weights,
                  bool estimate_scale, const PlaneErrorModel& model, Pose* pose, ceres::Problem* problem,
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
    const ceres::ResidualBlockId id = scaled ? problem->AddResidualBlock(cost, nullptr, pose->q, pose->t, &pose->s)
                                             : problem->AddResidualBlock(cost, nullptr, pose->q, pose->t);
    if (blocks) blocks->emplace_back(id, cl.id);
  }
}

// One Ceres solve of the clusters.
SolveOutcome solveWeighted(const std::vector<Cluster>& clusters, const std::vector<std::vector<double>>* point_weights,
                           bool estimate_scale, const PlaneErrorModel& model, const SolverOptions& options,
                           Pose* pose) {
  ceres::Problem problem;
  buildProblem(clusters, point_weights, estimate_scale, model, pose, &problem);
  ceres::Solver::Options solver_options;
  solver_options.linear_solver_type = ceres::DENSE_QR;
  solvers_detail::applyStopCriteria(options, &solver_options);
  ceres::Solver::Summary summary;
  ceres::Solve(solver_options, &problem, &summary);
  SolveOutcome out;
  out.usable = summary.IsSolutionUsable();
  out.cost = summary.final_cost;
  out.iterations = static_cast<int>(summary.iterations.size());
  out.termination = ceres::TerminationTypeToString(summary.termination_type);
  out.message = summary.message;
  return out;
}

double residualOf(const Cluster& cl, const Eigen::Isometry3d& T, double s, const Eigen::Vector3d& p) {
  return cl.normal.dot(T * p) - (cl.scaled ? s : 1.0) * cl.offset;
}

// Robust cost 1/2 sum_c w_c sum_m rho(r^2), as Ceres would report it.
double robustCost(const std::vector<Cluster>& clusters, const Pose& pose, RobustLoss loss, double a) {
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
std::vector<std::vector<double>> robustWeights(const std::vector<Cluster>& clusters, const Pose& pose,
                                               const SolverOptions& options) {
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
SolveOutcome solveStage(const std::vector<Cluster>& clusters, bool estimate_scale, const SolverOptions& options,
                        bool warm, Pose* pose, const PlaneErrorModel& model = PlaneErrorModel()) {
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
        translationErrorM(after, before.isometry()) < kIrlsTolerance && std::abs(pose->s - before.s) < kIrlsTolerance)
      break;
  }
  out.iterations = iterations;
  out.cost = robustCost(clusters, *pose, options.loss, options.loss_scale_m);
  return out;
}

// Variance components of the camera planes from the residuals at the pose, for a distance
// power: per plane cluster the squared offset at the mean of the (robustly weighted) points
// minus its LiDAR share s^2/W, and the squared tilts minus s^2/lambda_k, each divided by the
// view's distance factor, averaged with the degrees of freedom the pose takes (3 of the
// offsets for the translation, 3 of the tilts for the rotation). `nll` receives the Gaussian
// negative log-likelihood of those residuals under the model, to compare distance powers.
// Disabled when too few views.
PlaneErrorModel estimatePlaneErrorModel(const std::vector<Cluster>& clusters, const Pose& pose,
                                        const SolverOptions& options, double distance_power, double* nll) {
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
    if (!(m.W > 0.0) || !(m.lambda(1) > 0.0)) continue;
    const double s2 = pointVariance(m);
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
  std::nth_element(distances.begin(), distances.begin() + distances.size() / 2, distances.end());
  model.distance_power = distance_power;
  model.reference_distance_m = distances[distances.size() / 2];
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

// The better (by likelihood) of a distance-independent camera plane error and one growing as a
// PnP's (distance^4 in variance).
PlaneErrorModel choosePlaneErrorModel(const std::vector<Cluster>& clusters, const Pose& pose,
                                      const SolverOptions& options) {
  constexpr double kPnpDistancePower = 4.0;
  double nll_flat = 0.0, nll_pnp = 0.0;
  const PlaneErrorModel flat = estimatePlaneErrorModel(clusters, pose, options, 0.0, &nll_flat);
  const PlaneErrorModel pnp = estimatePlaneErrorModel(clusters, pose, options, kPnpDistancePower, &nll_pnp);
  return pnp.enabled && nll_pnp < nll_flat ? pnp : flat;
}

// The covariance of the final problem (the clusters with the robust weights at the final pose,
// the same residual blocks as the last solve) from Ceres, cluster-robust.
bool finalCovariance(const std::vector<Cluster>& clusters, bool estimate_scale, const PlaneErrorModel& model,
                     const SolverOptions& options, Pose pose, Matrix6d* covariance) {
  const auto weights = robustWeights(clusters, pose, options);
  ceres::Problem problem;
  std::vector<std::pair<ceres::ResidualBlockId, int>> blocks;
  buildProblem(clusters, &weights, estimate_scale, model, &pose, &problem, &blocks);
  std::vector<double*> parameters = {pose.q, pose.t};
  if (estimate_scale) parameters.push_back(&pose.s);
  return solvers_detail::clusterRobustCovariance(&problem, parameters, blocks, covariance);
}

// Re-assigns LiDAR edges to image lines by projection (core/common/edge_association.h, the
// association the MLRE figures and the overlay use); true if any view changed.
bool reassociateEdges(const std::vector<View>& views, std::vector<PreparedView>* prepared, const Eigen::Isometry3d& T,
                      std::vector<std::string>* notes) {
  bool changed = false;
  for (PreparedView& v : *prepared) {
    if (!v.used) continue;
    const View& view = views[v.index];
    const EdgeAssociation a = associateEdges(view.camera, view.lidar, T, kMinEdgePoints);
    if (a.lidar_edge == v.association) continue;
    std::ostringstream note;
    note << "view " << v.id << ": LiDAR edges re-associated to image lines by projection (";
    for (int j = 0; j < kNumEdges; ++j) note << (j ? ", " : "") << edgeName(j) << "<-" << edgeName(a.lidar_edge[j]);
    note << ")";
    notes->push_back(note.str());
    v.association = a.lidar_edge;
    changed = true;
  }
  return changed;
}

ResidualStats stats(const std::vector<double>& r) {
  ResidualStats s;
  s.count = static_cast<int>(r.size());
  if (r.empty()) return s;
  double sq = 0.0, abs_sum = 0.0;
  for (double v : r) {
    sq += v * v;
    abs_sum += std::abs(v);
    s.max_abs_m = std::max(s.max_abs_m, std::abs(v));
  }
  s.rms_m = std::sqrt(sq / r.size());
  s.mean_abs_m = abs_sum / r.size();
  return s;
}

std::string usableSummary(const std::vector<PreparedView>& prepared) {
  std::ostringstream text;
  int shown = 0;
  constexpr int kMaxReasonsShown = 5;
  for (const auto& v : prepared) {
    if (v.used || v.reason.empty()) continue;
    if (shown++ < kMaxReasonsShown) text << "; view " << v.id << ": " << v.reason;
  }
  if (shown > kMaxReasonsShown) text << "; ... (" << shown - kMaxReasonsShown << " more)";
  return text.str();
}

Expected<Eigen::Isometry3d> closedForm(const std::vector<PreparedView>& prepared, Method method,
                                       const SolverOptions& options) {
  std::vector<Eigen::Vector3d> cam_normals, lidar_normals;
  std::vector<double> weights;
  for (const auto& v : prepared)
    if (v.used && v.plane_ok && v.lidar_plane_ok) {
      cam_normals.push_back(v.cam_normal);
      lidar_normals.push_back(v.lidar_normal);
      weights.push_back(1.0);
    }
  if (cam_normals.size() < 2)
    return Expected<Eigen::Isometry3d>::failure("closed-form initialiser needs >= 2 views with planes in both sensors");
  auto R = solvers_detail::alignVectors(cam_normals, lidar_normals, weights);
  if (!R) return Expected<Eigen::Isometry3d>::failure("closed-form initialiser: " + R.error());
  // Translation: n_C . t = d_C - n_C . R (point on the LiDAR plane) per view; lines (PBPC):
  // N . t = -N . R Q for the centroid of each edge's points.
  Eigen::Matrix3d A = Eigen::Matrix3d::Zero();
  Eigen::Vector3d b = Eigen::Vector3d::Zero();
  for (const auto& v : prepared) {
    if (!v.used) continue;
    if (v.plane_ok && v.lidar_plane_ok) {
      const double rhs = v.cam_offset - v.lidar_offset * v.cam_normal.dot(*R * v.lidar_normal);
      A += v.cam_normal * v.cam_normal.transpose();
      b += v.cam_normal * rhs;
    }
    if (method == Method::kPbpc) {
      for (int j = 0; j < kNumEdges; ++j) {
        const int k = v.association[j];
        if (!v.image_edge_ok[j] || !v.lidar_edge_ok[k]) continue;
        Eigen::Vector3d c = Eigen::Vector3d::Zero();
        for (const auto& q : v.lidar_edges[k]) c += q;
        c /= static_cast<double>(v.lidar_edges[k].size());
        const Eigen::Vector3d& N = v.backprojected_normal[j];
        A += options.pbpc_line_weight * N * N.transpose();
        b += options.pbpc_line_weight * N * (-N.dot(*R * c));
      }
    }
  }
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(A);
  constexpr double kMinRelativeEigen = 1e-9;
  if (!(eig.eigenvalues()(0) > kMinRelativeEigen * eig.eigenvalues()(2)))
    return Expected<Eigen::Isometry3d>::failure("closed-form initialiser: the translation is not constrained");
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = *R;
  T.translation() = A.ldlt().solve(b);
  return T;
}

// The LiDAR's horizontal step from the board points: points of one scan line share their
// elevation, and the smallest azimuth gaps along a line are one step (even after subsampling
// some neighbours survive). Median over scan lines; 0 when it cannot be told.
double estimateHorizontalStepRad(const std::vector<View>& views) {
  std::vector<double> line_minima;
  for (const View& v : views) {
    if (!v.lidar.found) continue;
    std::vector<std::pair<double, double>> elev_az;
    for (const auto& p : v.lidar.board_points) {
      if (!p.allFinite()) continue;
      elev_az.emplace_back(std::atan2(p.z(), p.head<2>().norm()), std::atan2(p.y(), p.x()));
    }
    std::sort(elev_az.begin(), elev_az.end());
    size_t begin = 0;
    for (size_t i = 1; i <= elev_az.size(); ++i) {
      if (i < elev_az.size() && elev_az[i].first - elev_az[i - 1].first < kSameScanLineRad) continue;
      if (i - begin >= kMinScanLinePoints) {
        std::vector<double> az;
        for (size_t k = begin; k < i; ++k) az.push_back(elev_az[k].second);
        std::sort(az.begin(), az.end());
        double gap = std::numeric_limits<double>::infinity();
        for (size_t k = 1; k < az.size(); ++k)
          if (az[k] - az[k - 1] > kMinAzimuthGapRad) gap = std::min(gap, az[k] - az[k - 1]);
        if (std::isfinite(gap)) line_minima.push_back(gap);
      }
      begin = i;
    }
  }
  if (line_minima.empty()) return 0.0;
  std::nth_element(line_minima.begin(), line_minima.begin() + line_minima.size() / 2, line_minima.end());
  const double step = line_minima[line_minima.size() / 2];
  return step <= kMaxPlausibleStepRad ? step : 0.0;
}

std::vector<PreparedView> prepareAll(const std::vector<View>& views, Method method, const SolverOptions& options,
                                     double* step_used = nullptr) {
  double step = 0.0;
  if (options.edge_outward_shift_steps != 0.0)
    step = options.lidar_horizontal_resolution_deg > 0.0 ? options.lidar_horizontal_resolution_deg * kRadPerDeg
                                                         : estimateHorizontalStepRad(views);
  if (step_used) *step_used = step;
  std::vector<PreparedView> prepared;
  prepared.reserve(views.size());
  for (size_t i = 0; i < views.size(); ++i)
    prepared.push_back(prepareView(views[i], static_cast<int>(i), method, options, step));
  return prepared;
}

// Degeneracy checks; empty when the views can be solved.
std::string checkGeometry(const std::vector<PreparedView>& prepared, Method method, const SolverOptions& options,
                          int* used) {
  std::vector<Eigen::Vector3d> normals;
  *used = 0;
  for (const auto& v : prepared) {
    if (!v.used) continue;
    ++*used;
    if (v.plane_ok) normals.push_back(v.cam_normal);
  }
  const int needed = method == Method::kPpc ? kMinPpcViews : kMinPbpcViews;
  if (*used < needed) {
    std::ostringstream text;
    text << "only " << *used << " usable view(s) of " << prepared.size() << "; " << methodName(method)
         << " needs >= " << needed << (method == Method::kPpc ? " non-coplanar views" : " views with edges")
         << usableSummary(prepared);
    return text.str();
  }
  const double parallel = solvers_detail::normalSpreadDeg(normals, 1);
  if (normals.size() >= 2 && parallel < options.min_normal_spread_deg) {
    std::ostringstream text;
    text.precision(2);
    text << std::fixed << "all board normals are parallel (spread " << parallel << " deg < "
         << options.min_normal_spread_deg << " deg): tilt the board differently between views";
    return text.str();
  }
  if (method == Method::kPpc) {
    const double coplanar = solvers_detail::normalSpreadDeg(normals, 2);
    if (coplanar < options.min_normal_spread_deg) {
      std::ostringstream text;
      text.precision(2);
      text << std::fixed << "the board normals are coplanar (out-of-plane spread " << coplanar << " deg < "
           << options.min_normal_spread_deg
           << " deg): PPC needs >= 3 non-coplanar views; tilt the board about two different axes";
      return text.str();
    }
  }
  if (method == Method::kPbpc && normals.size() < 2) {
    // Rotation from lines alone is not attempted by the initialiser.
    return "PBPC needs the camera board plane in >= 2 views (for the initial rotation)";
  }
  return "";
}

}  // namespace

Expected<Eigen::Isometry3d> closedFormInitialGuess(const std::vector<View>& views, Method method,
                                                   const SolverOptions& options) {
  const std::string invalid = options.validate();
  if (!invalid.empty()) return Expected<Eigen::Isometry3d>::failure("invalid solver options: " + invalid);
  if (method == Method::kMsgPair) return closedFormPlaneToPlane(planeCorrespondences(views), options);
  const auto prepared = prepareAll(views, method, options);
  int used = 0;
  const std::string why = checkGeometry(prepared, method, options, &used);
  if (!why.empty()) return Expected<Eigen::Isometry3d>::failure(why);
  return closedForm(prepared, method, options);
}

namespace {

void fillResidualFigures(const std::vector<View>& views, const std::vector<PreparedView>& prepared, Method method,
                         CalibrationSolution* sol) {
  const Eigen::Isometry3d& T = sol->camera_T_lidar;
  const Eigen::Matrix3d R = T.linear();
  double mlre_sum = 0.0, line_sq = 0.0, plane_sq = 0.0;
  int mlre_count = 0, line_count = 0, plane_count = 0;
  sol->views.clear();
  for (const PreparedView& v : prepared) {
    ViewResidual vr;
    vr.view_id = v.id;
    vr.used = v.used;
    vr.reason = v.reason;
    if (v.board_points && v.plane_ok) {
      std::vector<double> r;
      r.reserve(v.board_points->size());
      for (const auto& p : *v.board_points) r.push_back(v.cam_normal.dot(R * p + T.translation()) - v.cam_offset);
      vr.plane = stats(r);
      if (v.used) {
        plane_sq += vr.plane.rms_m * vr.plane.rms_m * vr.plane.count;
        plane_count += vr.plane.count;
      }
    }
    double view_sum = 0.0;
    int view_count = 0;
    for (int j = 0; j < kNumEdges; ++j) {
      const int k = v.association[j];
      EdgeResidual& er = vr.edges[j];
      er.lidar_edge = k;
      if (!v.used || !v.image_edge_ok[j] || !v.lidar_edge_ok[k]) continue;
      er.used = method == Method::kPbpc;
      std::vector<double> r;
      for (const auto& q : v.lidar_edges[k]) r.push_back(v.backprojected_normal[j].dot(R * q + T.translation()));
      er.distance = stats(r);
      line_sq += er.distance.rms_m * er.distance.rms_m * er.distance.count;
      line_count += er.distance.count;
      int count = 0;
      const double mean = edgeLineDistancePx(views[v.index].camera, j, views[v.index].lidar.edge_points[k], T, &count);
      if (count > 0) {
        er.mlre_px = mean;
        view_sum += mean * count;
        view_count += count;
      }
    }
    if (view_count > 0) vr.mlre_px = view_sum / view_count;
    mlre_sum += view_sum;
    mlre_count += view_count;
    sol->views.push_back(vr);
  }
  if (mlre_count > 0) sol->mlre_px = mlre_sum / mlre_count;
  sol->plane_rms_mm = plane_count ? 1000.0 * std::sqrt(plane_sq / plane_count) : 0.0;
  sol->line_rms_mm = line_count ? 1000.0 * std::sqrt(line_sq / line_count) : 0.0;
}

}  // namespace

CalibrationSolution calibrate(const std::vector<View>& views, Method method, const SolverOptions& options,
                              const std::optional<Eigen::Isometry3d>& initial_guess) {
  const auto start = std::chrono::steady_clock::now();
  auto elapsed_ms = [&] {
    return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
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

  double step_rad = 0.0;
  std::vector<PreparedView> prepared = prepareAll(views, method, options, &step_rad);
  if (method == Method::kPbpc && options.edge_outward_shift_steps != 0.0) {
    std::ostringstream note;
    note.precision(3);
    if (step_rad > 0.0)
      note << "LiDAR edge points shifted outward by " << options.edge_outward_shift_steps << " x "
           << step_rad * kDegPerRad << " deg horizontal step"
           << (options.lidar_horizontal_resolution_deg > 0.0 ? "" : " (step estimated from the board points)");
    else
      note << "LiDAR horizontal step could not be estimated: edge points not shifted";
    sol.notes.push_back(note.str());
  }
  int used = 0;
  const std::string why = checkGeometry(prepared, method, options, &used);
  for (const auto& v : prepared)
    if (!v.used) sol.notes.push_back("view " + std::to_string(v.id) + " skipped: " + v.reason);
  if (!why.empty()) {
    sol.reason = why;
    fillResidualFigures(views, prepared, method, &sol);
    return sol;
  }
  sol.views_used = used;

  if (initial_guess) {
    sol.initial_guess = *initial_guess;
  } else {
    auto guess = closedForm(prepared, method, options);
    if (!guess) {
      sol.reason = guess.error();
      return sol;
    }
    sol.initial_guess = *guess;
    sol.used_closed_form_init = true;
  }

  Pose pose = Pose::from(sol.initial_guess);
  const bool use_scale = method == Method::kPbpc && options.estimate_plane_scale && options.pbpc_use_plane_terms;
  const double lw = options.pbpc_line_weight;
  SolveOutcome outcome;
  auto run = [&](const std::vector<Cluster>& terms, bool scale, bool warm) {
    outcome = solveStage(terms, scale, options, warm, &pose);
    sol.iterations += outcome.iterations;
    return outcome.usable;
  };
  std::vector<Cluster> final_terms;
  PlaneErrorModel plane_model;
  bool ok = true;
  if (method == Method::kPpc) {
    final_terms = buildClusters(prepared, true, false, false, lw);
    ok = run(final_terms, false, true);
    // Then weight each view's offset and tilts by the camera plane error estimated from the
    // residuals (a few rounds: the estimate and the pose settle together).
    for (int round = 0; ok && options.ppc_plane_error_model && round < kPlaneErrorRounds; ++round) {
      plane_model = choosePlaneErrorModel(final_terms, pose, options);
      if (!plane_model.enabled) break;
      outcome = solveStage(final_terms, false, options, false, &pose, plane_model);
      sol.iterations += outcome.iterations;
      ok = outcome.usable;
    }
    if (plane_model.enabled) {
      std::ostringstream note;
      note.precision(3);
      note << "PPC views weighted by the camera plane error estimated from the residuals: offset "
           << 1000.0 * std::sqrt(plane_model.offset_var) << " mm, tilt " << std::sqrt(plane_model.tilt_var) * kDegPerRad
           << " deg per axis (1 sigma"
           << (plane_model.distance_power > 0.0
                   ? ", at " + std::to_string(plane_model.reference_distance_m).substr(0, 4) + " m, growing with distance^2)"
                   : ", the same for every view)");
      sol.notes.push_back(note.str());
    }
  } else {
    const bool planes = options.pbpc_use_plane_terms;
    if (options.pbpc_schedule == PbpcSchedule::kSequential) {
      // The paper: PPC first, then the line terms alone, then both.
      const auto plane_terms = buildClusters(prepared, true, false, false, lw);
      ok = plane_terms.empty() || run(plane_terms, false, true);
      ok = ok && run(buildClusters(prepared, false, true, false, lw), false, plane_terms.empty());
    }
    final_terms = buildClusters(prepared, planes, true, use_scale, lw);
    ok = ok && run(final_terms, use_scale, options.pbpc_schedule == PbpcSchedule::kJoint);
    if (ok && options.edge_reassociation && reassociateEdges(views, &prepared, pose.isometry(), &sol.notes)) {
      final_terms = buildClusters(prepared, planes, true, use_scale, lw);
      ok = run(final_terms, use_scale, false);
    }
  }
  sol.camera_T_lidar = pose.isometry();
  sol.final_cost = outcome.cost;
  sol.termination = outcome.termination;
  sol.plane_scale = use_scale ? pose.s : 1.0;
  if (!ok || !sol.camera_T_lidar.matrix().allFinite()) {
    sol.reason = "Ceres solution not usable: " + outcome.message;
    return sol;
  }
  fillResidualFigures(views, prepared, method, &sol);

  if (options.compute_covariance) {
    const bool cov_ok = finalCovariance(final_terms, use_scale, plane_model, options, pose, &sol.covariance);
    if (!cov_ok) sol.covariance.setConstant(std::numeric_limits<double>::infinity());
    sol.stddev = stddevFromCovariance(sol.covariance);
    sol.observability =
        solvers_detail::analyseObservability(sol.covariance, cov_ok, options.observability_max_stddev, "camera");
    if (!sol.observability.well_conditioned)
      sol.notes.push_back("weakly observable: " + sol.observability.weakest_description);
  }
  if (use_scale && std::abs(sol.plane_scale - 1.0) > options.plane_scale_note_threshold) {
    std::ostringstream note;
    note.precision(3);
    note << "camera board planes fit best scaled by " << sol.plane_scale
         << (sol.plane_scale > 1.0 ? ": the board is larger than declared or LiDAR edges bloom"
                                   : ": the board is smaller than declared or LiDAR edges are eroded");
    sol.notes.push_back(note.str());
  }
  sol.success = true;
  sol.solve_time_ms = elapsed_ms();
  return sol;
}

}  // namespace board_calib
