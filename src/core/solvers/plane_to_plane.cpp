// MSG-Cal pairwise: plane-to-plane solve between any two sensors, and its LiDAR<->camera use.
#include "ceres_helpers.h"
#include "cost_functions.h"
#include "internal.h"

#include <board_calib/core/common/edge_association.h>
#include <board_calib/core/transform.h>

#include <cmath>
#include <sstream>

namespace board_calib {

namespace {

constexpr int kMinCorrespondences = 3;  // three non-coplanar planes fix the translation
constexpr double kUnitTolerance = 1e-3;
// Per-view weights: a view's distance counts at least this fraction of the RMS distance (no
// runaway weight for a board next to the sensor).
constexpr double kMinRelativeDistance = 0.2;

bool validPlane(const Plane& p) {
  return p.normal.allFinite() && std::isfinite(p.offset) &&
         std::abs(p.normal.norm() - 1.0) <= kUnitTolerance;
}

// The board point of correspondence k (the origins when none are given).
BoardPointPair pointsOf(const std::vector<BoardPointPair>& points, size_t k) {
  return points.empty() ? BoardPointPair() : points[k];
}

// Checks the correspondences; empty when solvable.
std::string checkCorrespondences(const std::vector<PlaneCorrespondence>& c,
                                 const std::vector<BoardPointPair>& points,
                                 const SolverOptions& options) {
  if (!points.empty() && points.size() != c.size())
    return std::to_string(points.size()) + " board point pairs for " + std::to_string(c.size()) +
           " plane correspondences";
  if (c.size() < static_cast<size_t>(kMinCorrespondences))
    return "only " + std::to_string(c.size()) + " plane correspondence(s); MSG pairwise needs >= " +
           std::to_string(kMinCorrespondences) + " non-coplanar board poses";
  std::vector<Eigen::Vector3d> normals;
  for (size_t i = 0; i < c.size(); ++i) {
    if (!validPlane(c[i].in_a) || !validPlane(c[i].in_b))
      return "plane correspondence " + std::to_string(i) + " (view " +
             std::to_string(c[i].view_id) + ") has a non-finite plane or a non-unit normal";
    if (!std::isfinite(c[i].weight) || c[i].weight <= 0.0)
      return "plane correspondence " + std::to_string(i) + " has a non-positive weight";
    if (!pointsOf(points, i).in_a.allFinite() || !pointsOf(points, i).in_b.allFinite())
      return "plane correspondence " + std::to_string(i) + " (view " +
             std::to_string(c[i].view_id) + ") has a non-finite board point";
    normals.push_back(c[i].in_a.normal);
  }
  const double parallel = solvers_detail::normalSpreadDeg(normals, 1);
  const double coplanar = solvers_detail::normalSpreadDeg(normals, 2);
  std::ostringstream text;
  text.precision(2);
  text << std::fixed;
  if (parallel < options.min_normal_spread_deg) {
    text << "all board normals are parallel (spread " << parallel << " deg < "
         << options.min_normal_spread_deg << " deg)";
    return text.str();
  }
  if (coplanar < options.min_normal_spread_deg) {
    text << "the board normals are coplanar (out-of-plane spread " << coplanar << " deg < "
         << options.min_normal_spread_deg << " deg): plane-to-plane needs non-coplanar normals";
    return text.str();
  }
  return "";
}

// Per-correspondence 1-sigma of the normal and gap residuals relative to the options' sigmas.
struct ViewScale {
  double normal = 1.0, gap = 1.0;
};

// Per-view weights at the boards: a camera plane from PnP has a normal error growing with the
// board distance D and an offset error at the board growing with D^2 (docs/BENCHMARKS.md,
// PnP Monte Carlo), so each view's normal residual sigma is scaled by D / D_rms and its gap
// sigma by (D / D_rms)^2. Measured over the 10 bench seeds against flat weights and against the
// most likely mix of flat and growing errors (estimated from the residuals, too noisy with 30
// views): this law gave the smallest worst-case error (docs/BENCHMARKS.md, Solvers).
std::vector<ViewScale> distanceScales(const std::vector<BoardPointPair>& points) {
  if (points.empty()) return {};
  double d2 = 0.0;
  for (const auto& at : points) d2 += std::pow(0.5 * (at.in_a.norm() + at.in_b.norm()), 2);
  const double d_ref = std::sqrt(d2 / points.size());
  if (!(d_ref > 0.0)) return {};
  std::vector<ViewScale> scales(points.size());
  for (size_t k = 0; k < points.size(); ++k) {
    const double u = std::max(0.5 * (points[k].in_a.norm() + points[k].in_b.norm()) / d_ref,
                              kMinRelativeDistance);
    scales[k].normal = u;
    scales[k].gap = u * u;
  }
  return scales;
}

struct PairOutcome : ceres_common::SolveOutcome {
  bool covariance_ok = false;
  Matrix6d covariance = Matrix6d::Zero();
  double scale_variance = 0.0;  ///< with a free scale: its variance
};

// One solve; with `covariance`, also the cluster-robust covariance of the solved problem (each
// correspondence's normal and offset residuals share the plane errors: one cluster). With
// `scale`, the a-side plane offsets and board points are multiplied by *scale, solved too.
PairOutcome solvePair(const std::vector<PlaneCorrespondence>& c,
                      const std::vector<BoardPointPair>& points,
                      const std::vector<ViewScale>& scales, RobustLoss loss,
                      const SolverOptions& options, double* q, double* t, bool covariance = false,
                      double* scale = nullptr) {
  ceres::Problem problem;
  problem.AddParameterBlock(q, 4, new ceres::EigenQuaternionManifold());
  problem.AddParameterBlock(t, 3);
  if (scale) problem.AddParameterBlock(scale, 1);
  // Whitening: normal residuals (unit-less) become metres-equivalent via sigma_d / sigma_n.
  const double normal_weight =
      options.msg_offset_sigma_m / (options.msg_normal_sigma_deg * kRadPerDeg);
  std::vector<std::pair<ceres::ResidualBlockId, int>> blocks;
  for (size_t k = 0; k < c.size(); ++k) {
    const PlaneCorrespondence& pc = c[k];
    const double w = pc.weight;
    const BoardPointPair at = pointsOf(points, k);
    const double sn = scales.empty() ? 1.0 : 1.0 / scales[k].normal;
    const double sd = scales.empty() ? 1.0 : 1.0 / scales[k].gap;
    blocks.emplace_back(
        problem.AddResidualBlock(
            solvers_detail::NormalAlignmentCost::Create(pc.in_a.normal, pc.in_b.normal,
                                                        normal_weight * sn),
            new ceres::ScaledLoss(solvers_detail::makeLoss(loss, options.loss_scale_m), w,
                                  ceres::TAKE_OWNERSHIP),
            q),
        static_cast<int>(k));
    auto* gap_loss = new ceres::ScaledLoss(solvers_detail::makeLoss(loss, options.loss_scale_m), w,
                                           ceres::TAKE_OWNERSHIP);
    blocks.emplace_back(
        scale ? problem.AddResidualBlock(solvers_detail::PlaneGapCost::CreateScaled(
                                             pc.in_a.normal, pc.in_a.offset, at.in_a,
                                             pc.in_b.normal, pc.in_b.offset, at.in_b, sd),
                                         gap_loss, q, t, scale)
              : problem.AddResidualBlock(solvers_detail::PlaneGapCost::Create(
                                             pc.in_a.normal, pc.in_a.offset, at.in_a,
                                             pc.in_b.normal, pc.in_b.offset, at.in_b, sd),
                                         gap_loss, q, t),
        static_cast<int>(k));
  }
  ceres::Solver::Options so;
  so.linear_solver_type = ceres::DENSE_QR;
  solvers_detail::applyStopCriteria(options, &so);
  PairOutcome out;
  static_cast<ceres_common::SolveOutcome&>(out) = ceres_common::solveAndSummarize(so, &problem);
  if (covariance && out.usable) {
    std::vector<double*> parameters{q, t};
    if (scale) parameters.push_back(scale);
    std::vector<double> nuisance;
    out.covariance_ok = solvers_detail::clusterRobustCovariance(&problem, parameters, blocks,
                                                                &out.covariance, &nuisance);
    if (scale && !nuisance.empty()) out.scale_variance = nuisance.front();
  }
  return out;
}

Eigen::Isometry3d poseOf(const double* q, const double* t) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = Eigen::Quaterniond(q[3], q[0], q[1], q[2]).normalized().toRotationMatrix();
  T.translation() = Eigen::Vector3d(t[0], t[1], t[2]);
  return T;
}

}  // namespace

std::vector<PlaneCorrespondence> planeCorrespondences(const std::vector<View>& views) {
  std::vector<PlaneCorrespondence> out;
  for (const View& v : views) {
    if (!v.camera.found || !v.lidar.found) continue;
    PlaneCorrespondence pc;
    pc.in_a = v.camera.plane;
    pc.in_b = v.lidar.plane;
    pc.view_id = v.id;
    out.push_back(pc);
  }
  return out;
}

namespace {

// Rotation by Kabsch on the normals; translation from the gaps at the boards (PlaneGapCost is
// linear in t for a fixed rotation: m . t = d_a - d_b - (n_a - R n_b) . (c_a + R c_b) / 2).
Expected<Eigen::Isometry3d> closedFormAtBoards(
    const std::vector<PlaneCorrespondence>& correspondences,
    const std::vector<BoardPointPair>& points, const SolverOptions& options) {
  const std::string why = checkCorrespondences(correspondences, points, options);
  if (!why.empty()) return Expected<Eigen::Isometry3d>::failure(why);
  std::vector<Eigen::Vector3d> a, b;
  std::vector<double> w;
  for (const auto& c : correspondences) {
    a.push_back(c.in_a.normal);
    b.push_back(c.in_b.normal);
    w.push_back(c.weight);
  }
  auto R = solvers_detail::alignVectors(a, b, w);
  if (!R) return Expected<Eigen::Isometry3d>::failure(R.error());
  Eigen::Matrix3d A = Eigen::Matrix3d::Zero();
  Eigen::Vector3d rhs = Eigen::Vector3d::Zero();
  for (size_t k = 0; k < correspondences.size(); ++k) {
    const PlaneCorrespondence& c = correspondences[k];
    const BoardPointPair at = pointsOf(points, k);
    const Eigen::Vector3d rnb = *R * c.in_b.normal;
    const Eigen::Vector3d m = 0.5 * (c.in_a.normal + rnb);
    const double y =
        c.in_a.offset - c.in_b.offset - 0.5 * (c.in_a.normal - rnb).dot(at.in_a + *R * at.in_b);
    A += c.weight * m * m.transpose();
    rhs += c.weight * m * y;
  }
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = *R;
  T.translation() = A.ldlt().solve(rhs);
  return T;
}

}  // namespace

Expected<Eigen::Isometry3d> closedFormPlaneToPlane(
    const std::vector<PlaneCorrespondence>& correspondences, const SolverOptions& options) {
  return closedFormAtBoards(correspondences, {}, options);
}

PairwiseSolution solvePlaneToPlane(const std::vector<PlaneCorrespondence>& correspondences,
                                   const SolverOptions& options,
                                   const std::optional<Eigen::Isometry3d>& initial_guess) {
  return solvePlaneToPlane(correspondences, std::vector<BoardPointPair>{}, options, initial_guess);
}

namespace {

// RMS normal angle and plane gap of the correspondences under sol->a_T_b.
void residualFigures(const std::vector<PlaneCorrespondence>& correspondences,
                     const std::vector<BoardPointPair>& points, PairwiseSolution* sol) {
  const Eigen::Matrix3d R = sol->a_T_b.linear();
  double angle_sq = 0.0, offset_sq = 0.0;
  for (size_t k = 0; k < correspondences.size(); ++k) {
    const PlaneCorrespondence& c = correspondences[k];
    const Eigen::Vector3d rnb = R * c.in_b.normal;
    const double angle = std::atan2(c.in_a.normal.cross(rnb).norm(), c.in_a.normal.dot(rnb));
    angle_sq += angle * angle;
    const BoardPointPair at = pointsOf(points, k);
    const double ro = planeGapM(c.in_a, at.in_a, c.in_b, at.in_b, sol->a_T_b);
    offset_sq += ro * ro;
  }
  const double n = static_cast<double>(correspondences.size());
  sol->normal_rms_deg = std::sqrt(angle_sq / n) * kDegPerRad;
  sol->offset_rms_mm = 1000.0 * std::sqrt(offset_sq / n);
}

}  // namespace

PairwiseSolution solvePlaneToPlane(const std::vector<PlaneCorrespondence>& correspondences,
                                   const std::vector<BoardPointPair>& points,
                                   const SolverOptions& options,
                                   const std::optional<Eigen::Isometry3d>& initial_guess) {
  PairwiseSolution sol;
  const std::string invalid = options.validate();
  if (!invalid.empty()) {
    sol.reason = "invalid solver options: " + invalid;
    return sol;
  }
  const std::string why = checkCorrespondences(correspondences, points, options);
  if (!why.empty()) {
    sol.reason = why;
    return sol;
  }
  if (initial_guess) {
    if (!initial_guess->matrix().allFinite()) {
      sol.reason = "the initial guess is not finite";
      return sol;
    }
    sol.initial_guess = *initial_guess;
  } else {
    auto guess = closedFormAtBoards(correspondences, points, options);
    if (!guess) {
      sol.reason = guess.error();
      return sol;
    }
    sol.initial_guess = *guess;
    sol.used_closed_form_init = true;
  }
  Eigen::Quaterniond q0(sol.initial_guess.linear());
  q0.normalize();
  double q[4] = {q0.x(), q0.y(), q0.z(), q0.w()};
  double t[3] = {sol.initial_guess.translation().x(), sol.initial_guess.translation().y(),
                 sol.initial_guess.translation().z()};
  const std::vector<ViewScale> scales = distanceScales(points);
  PairOutcome outcome;
  if (options.warm_start_unrobust && options.loss != RobustLoss::kNone) {
    outcome = solvePair(correspondences, points, scales, RobustLoss::kNone, options, q, t);
    sol.iterations += outcome.iterations;
  }
  if (!(options.warm_start_unrobust && options.loss != RobustLoss::kNone) || outcome.usable) {
    outcome = solvePair(correspondences, points, scales, options.loss, options, q, t,
                        options.compute_covariance);
    sol.iterations += outcome.iterations;
  }
  sol.final_cost = outcome.cost;
  sol.termination = outcome.termination;
  sol.a_T_b = poseOf(q, t);
  if (!outcome.usable || !sol.a_T_b.matrix().allFinite()) {
    sol.reason = "Ceres solution not usable: " + outcome.message;
    return sol;
  }
  sol.correspondences_used = static_cast<int>(correspondences.size());

  residualFigures(correspondences, points, &sol);
  if (options.compute_covariance) {
    const bool cov_ok = outcome.covariance_ok;
    sol.covariance = outcome.covariance;
    if (!cov_ok) sol.covariance.setConstant(std::numeric_limits<double>::infinity());
    sol.stddev = stddevFromCovariance(sol.covariance);
    sol.observability = solvers_detail::analyseObservability(sol.covariance, cov_ok,
                                                             options.observability_max_stddev, "a");
    if (!sol.observability.well_conditioned)
      sol.notes.push_back("weakly observable: " + sol.observability.weakest_description);
  }
  sol.success = true;
  return sol;
}

namespace solvers_detail {

namespace {

// Quality figures on the raw features, as for the other methods: plane and edge distances and
// the MLRE of every used view at the solved pose.
void fillMsgPairFigures(const std::vector<View>& views, CalibrationSolution* sol) {
  const Eigen::Isometry3d& T = sol->camera_T_lidar;
  double mlre_sum = 0.0, plane_sq = 0.0, line_sq = 0.0;
  int mlre_count = 0, plane_count = 0, line_count = 0;
  for (size_t i = 0; i < views.size(); ++i) {
    ViewResidual& vr = sol->views[i];
    if (!vr.used) continue;
    const View& v = views[i];
    std::vector<double> r;
    for (const auto& p : v.lidar.board_points) {
      const double d = v.camera.plane.signedDistance(T * p);
      if (std::isfinite(d)) r.push_back(d);
    }
    vr.plane = residualStats(r);
    plane_sq += vr.plane.rms_m * vr.plane.rms_m * vr.plane.count;
    plane_count += vr.plane.count;
    double view_sum = 0.0;
    int view_count = 0;
    // Edges paired at the solved pose, as the MLRE and the overlay pair them (the detectors'
    // names differ when a sensor is rolled).
    const EdgeAssociation pairs = associateEdges(v.camera, v.lidar, T);
    for (int j = 0; j < kNumEdges; ++j) {
      const int k = pairs.lidar_edge[j];
      vr.edges[j].lidar_edge = k;
      // Point-to-back-projected-plane distances as a figure (MSG does not use the lines).
      const Eigen::Vector3d N = v.camera.K.transpose() * v.camera.edge_lines[j];
      if (v.camera.edge_valid[j] && v.lidar.edge_valid[k] && N.allFinite() && N.norm() > 0.0) {
        std::vector<double> e;
        for (const auto& q : v.lidar.edge_points[k]) {
          const double d = N.normalized().dot(T * q);
          if (std::isfinite(d)) e.push_back(d);
        }
        if (!e.empty()) {
          vr.edges[j].distance = residualStats(e);
          line_sq += vr.edges[j].distance.rms_m * vr.edges[j].distance.rms_m * e.size();
          line_count += static_cast<int>(e.size());
        }
      }
      if (!pairs.scored[j]) continue;
      int count = 0;
      const double e = edgeLineDistancePx(v.camera, j, v.lidar.edge_points[k], T, &count);
      if (count == 0) continue;
      vr.edges[j].mlre_px = e;
      view_sum += e * count;
      view_count += count;
    }
    if (view_count > 0) vr.mlre_px = view_sum / view_count;
    mlre_sum += view_sum;
    mlre_count += view_count;
  }
  if (mlre_count > 0) sol->mlre_px = mlre_sum / mlre_count;
  sol->plane_rms_mm = plane_count ? 1000.0 * std::sqrt(plane_sq / plane_count) : 0.0;
  sol->line_rms_mm = line_count ? 1000.0 * std::sqrt(line_sq / line_count) : 0.0;
}

}  // namespace

namespace {

// As PPC (calibrate.cpp, checkDeclaredScale): camera planes at a common wrong depth (the
// declared board size, the focal length) move the translation while the residuals barely show
// it; the same correspondences solved with a free scale on the camera side measure it.
DeclaredScaleCheck checkCameraScale(const std::vector<PlaneCorrespondence>& correspondences,
                                    const std::vector<BoardPointPair>& points,
                                    const SolverOptions& options,
                                    const Eigen::Isometry3d& camera_T_lidar) {
  DeclaredScaleCheck check;
  Eigen::Quaterniond q0(camera_T_lidar.linear());
  q0.normalize();
  double q[4] = {q0.x(), q0.y(), q0.z(), q0.w()};
  double t[3] = {camera_T_lidar.translation().x(), camera_T_lidar.translation().y(),
                 camera_T_lidar.translation().z()};
  double s = 1.0;
  const PairOutcome scaled = solvePair(correspondences, points, distanceScales(points),
                                       options.loss, options, q, t, options.compute_covariance, &s);
  if (!scaled.usable || !std::isfinite(s)) return check;
  if (!options.compute_covariance) {  // a fold: the scale alone
    check.estimated = true;
    check.scale = s;
    return check;
  }
  if (!scaled.covariance_ok || !(scaled.scale_variance > 0.0)) return check;
  check.checked = true;
  check.estimated = true;
  check.scale = s;
  check.stddev = std::sqrt(scaled.scale_variance);
  check.shift = poseDelta(poseOf(q, t), camera_T_lidar);
  return check;
}

}  // namespace

CalibrationSolution calibrateMsgPair(const std::vector<View>& views, const SolverOptions& options,
                                     const std::optional<Eigen::Isometry3d>& initial_guess) {
  CalibrationSolution sol;
  sol.method = Method::kMsgPair;
  std::vector<PlaneCorrespondence> correspondences;
  std::vector<BoardPointPair> points;
  for (const View& v : views) {
    std::string why;
    if (!v.camera.found)
      why = "camera found no board";
    else if (!v.lidar.found)
      why = "LiDAR found no board";
    else if (!validPlane(v.camera.plane))
      why = "camera board plane is not finite or its normal not unit";
    else if (!validPlane(v.lidar.plane))
      why = "LiDAR board plane is not finite or its normal not unit";
    ViewResidual vr;
    vr.view_id = v.id;
    vr.used = why.empty();
    vr.reason = why;
    sol.views.push_back(vr);
    if (!why.empty()) {
      sol.notes.push_back("view " + std::to_string(v.id) + " skipped: " + why);
      continue;
    }
    PlaneCorrespondence pc;
    pc.in_a = v.camera.plane;
    pc.in_b = v.lidar.plane;
    pc.view_id = v.id;
    correspondences.push_back(pc);
    points.push_back({boardPoint(v.camera), boardPoint(v.lidar)});
  }
  const PairwiseSolution pair = solvePlaneToPlane(correspondences, points, options, initial_guess);
  sol.camera_T_lidar = pair.a_T_b;
  sol.initial_guess = pair.initial_guess;
  sol.used_closed_form_init = pair.used_closed_form_init;
  sol.final_cost = pair.final_cost;
  sol.iterations = pair.iterations;
  sol.termination = pair.termination;
  sol.covariance = pair.covariance;
  sol.stddev = pair.stddev;
  sol.observability = pair.observability;
  sol.notes.insert(sol.notes.end(), pair.notes.begin(), pair.notes.end());
  if (!pair.success) {
    sol.reason = pair.reason;
    return sol;
  }
  sol.views_used = pair.correspondences_used;
  fillMsgPairFigures(views, &sol);
  if (options.check_declared_scale &&
      (options.compute_covariance || options.declared_scale_without_covariance))
    sol.declared_scale = checkCameraScale(correspondences, points, options, sol.camera_T_lidar);
  // The solve took the declared size as exact; its 1 sigma gets the scale's.
  if (sol.covariance.allFinite()) {
    sol.covariance += declaredScaleUncertainty(sol.declared_scale);
    sol.stddev = stddevFromCovariance(sol.covariance);
  }
  sol.success = true;
  return sol;
}

}  // namespace solvers_detail
}  // namespace board_calib
