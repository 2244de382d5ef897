// The pairwise stages of the MSG graph: checks of the problem, usable observations, the
// plane-to-plane link of every sensor pair with per-sensor noise estimation, the spanning-tree
// initialisation and the loop consistency of the links.
#include "graph_internal.h"

#include <board_calib/core/common/board_geometry.h>
#include <board_calib/core/transform.h>

#include <Eigen/QR>

#include <algorithm>
#include <cmath>
#include <functional>

namespace board_calib {
namespace multi_sensor {
namespace graph_detail {

namespace {

bool validPlane(const Plane& p) {
  return p.normal.allFinite() && std::isfinite(p.offset) &&
         std::abs(p.normal.norm() - 1.0) <= kUnitTolerance && p.offset > 0.0;
}

// Pairwise plane-to-plane solve of one pair with gating of its correspondences by the pair's
// sigmas (so a noisy sensor's pairs gate more loosely, a precise one's more tightly).
void solvePair(const std::vector<std::vector<Obs>>& obs, const Sigmas& sa, const Sigmas& sb,
               const MsgGraphOptions& options, PairLink* link) {
  std::vector<PlaneCorrespondence> all;
  std::vector<BoardPointPair> all_points;
  for (size_t p = 0; p < obs.size(); ++p) {
    const Obs& a = obs[p][link->a];
    const Obs& b = obs[p][link->b];
    if (!a.active || !b.active) continue;
    PlaneCorrespondence pc;
    pc.in_a = a.plane;
    pc.in_b = b.plane;
    pc.view_id = static_cast<int>(p);
    all.push_back(pc);
    all_points.push_back({a.point, b.point});
  }
  link->shared_views = static_cast<int>(all.size());
  if (link->shared_views < options.min_shared_views) {
    link->success = false;
    link->reason = "only " + std::to_string(link->shared_views) + " shared board pose(s) (< " +
                   std::to_string(options.min_shared_views) + ")";
    return;
  }
  SolverOptions so;
  so.loss = options.loss;
  so.msg_normal_sigma_deg = pairNormalSigmaComponent(sa, sb) * kDegPerRad;
  so.msg_offset_sigma_m = pairOffsetSigma(sa, sb);
  so.loss_scale_m = options.loss_scale_sigma * so.msg_offset_sigma_m;
  so.max_iterations = options.max_iterations;
  so.function_tolerance = options.function_tolerance;
  so.gradient_tolerance = options.gradient_tolerance;
  so.parameter_tolerance = options.parameter_tolerance;
  so.num_threads = options.num_threads;
  so.min_normal_spread_deg = options.min_normal_spread_deg;
  so.compute_covariance = false;
  std::vector<PlaneCorrespondence> used = all;
  std::vector<BoardPointPair> used_points = all_points;
  PairwiseSolution sol = solvePlaneToPlane(used, used_points, so);
  for (int round = 0; sol.success && round < std::max(1, options.outlier_rounds); ++round) {
    std::vector<PlaneCorrespondence> kept;
    std::vector<BoardPointPair> kept_points;
    for (size_t k = 0; k < used.size(); ++k) {
      const Obs oa{true, used[k].in_a, used_points[k].in_a},
          ob{true, used[k].in_b, used_points[k].in_b};
      if (planePairError(oa, ob, sol.a_T_b, sa, sb).whitened <= options.outlier_gate_sigma) {
        kept.push_back(used[k]);
        kept_points.push_back(used_points[k]);
      }
    }
    if (kept.size() == used.size() || static_cast<int>(kept.size()) < options.min_shared_views)
      break;
    used = kept;
    used_points = kept_points;
    sol = solvePlaneToPlane(used, used_points, so, sol.a_T_b);
  }
  link->success = sol.success;
  link->reason = sol.reason;
  if (!sol.success) return;
  link->views_used = static_cast<int>(used.size());
  link->a_T_b = sol.a_T_b;
  link->normal_rms_deg = sol.normal_rms_deg;
  link->offset_rms_mm = sol.offset_rms_mm;
}

// Three-cornered hat: var(pair ab) = var(a) + var(b), least squares over all successful links.
// Returns false when the links do not determine every sensor's variance (no odd cycle).
bool estimateVariances(const std::vector<PairLink>& links, int n, bool normal,
                       std::vector<double>* var) {
  std::vector<const PairLink*> ok;
  for (const auto& l : links)
    if (l.success) ok.push_back(&l);
  if (static_cast<int>(ok.size()) < n) return false;
  Eigen::MatrixXd A = Eigen::MatrixXd::Zero(ok.size(), n);
  Eigen::VectorXd y(ok.size());
  for (size_t i = 0; i < ok.size(); ++i) {
    A(i, ok[i]->a) = 1.0;
    A(i, ok[i]->b) = 1.0;
    const double rms = normal ? ok[i]->normal_rms_deg * kRadPerDeg : ok[i]->offset_rms_mm / 1000.0;
    y(i) = rms * rms;
  }
  Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(A);
  if (qr.rank() < n) return false;
  const Eigen::VectorXd x = qr.solve(y);
  var->assign(x.data(), x.data() + n);
  return true;
}

}  // namespace

// Checks the problem's structure; empty when usable.
std::string checkProblem(const MsgProblem& problem,
                         const std::optional<std::vector<Eigen::Isometry3d>>& initial) {
  const int n = static_cast<int>(problem.sensors.size());
  if (n < kMinSensors) return "the graph needs >= 2 sensors, got " + std::to_string(n);
  if (problem.reference_sensor < 0 || problem.reference_sensor >= n)
    return "reference_sensor " + std::to_string(problem.reference_sensor) +
           " is not a sensor index (0.." + std::to_string(n - 1) + ")";
  std::set<std::string> frames;
  for (int s = 0; s < n; ++s) {
    const auto& spec = problem.sensors[s];
    if (spec.frame.empty()) return "sensor " + std::to_string(s) + " has no frame name";
    if (!frames.insert(spec.frame).second) return "frame '" + spec.frame + "' names two sensors";
    for (double v :
         {spec.normal_sigma_deg, spec.offset_sigma_m, spec.pixel_sigma_px, spec.edge_sigma_m})
      if (!std::isfinite(v)) return "sensor '" + spec.frame + "' has a non-finite sigma";
  }
  std::set<int> ids;
  for (const auto& pose : problem.poses) {
    if (!ids.insert(pose.id).second)
      return "board pose id " + std::to_string(pose.id) + " appears twice";
    for (const auto& [s, f] : pose.cameras) {
      (void)f;
      if (s < 0 || s >= n)
        return "board pose " + std::to_string(pose.id) +
               " has a camera observation of unknown sensor " + std::to_string(s);
      if (problem.sensors[s].kind != SensorKind::kCamera)
        return "board pose " + std::to_string(pose.id) + ": sensor '" + problem.sensors[s].frame +
               "' is a LiDAR but has a camera observation";
    }
    for (const auto& [s, f] : pose.lidars) {
      (void)f;
      if (s < 0 || s >= n)
        return "board pose " + std::to_string(pose.id) +
               " has a LiDAR observation of unknown sensor " + std::to_string(s);
      if (problem.sensors[s].kind != SensorKind::kLidar)
        return "board pose " + std::to_string(pose.id) + ": sensor '" + problem.sensors[s].frame +
               "' is a camera but has a LiDAR observation";
    }
  }
  if (initial) {
    if (static_cast<int>(initial->size()) != n)
      return "the initial guess has " + std::to_string(initial->size()) + " poses for " +
             std::to_string(n) + " sensors";
    for (const auto& T : *initial)
      if (!T.matrix().allFinite()) return "the initial guess is not finite";
  }
  return "";
}

Sigmas resolveSigmas(const SensorSpec& spec, const MsgGraphOptions& o) {
  const bool cam = spec.kind == SensorKind::kCamera;
  Sigmas s;
  s.normal_rad =
      (spec.normal_sigma_deg > 0 ? spec.normal_sigma_deg
                                 : (cam ? o.camera_normal_sigma_deg : o.lidar_normal_sigma_deg)) *
      kRadPerDeg;
  s.offset_m = spec.offset_sigma_m > 0 ? spec.offset_sigma_m
                                       : (cam ? o.camera_offset_sigma_m : o.lidar_offset_sigma_m);
  s.pixel_px = spec.pixel_sigma_px > 0 ? spec.pixel_sigma_px : o.camera_pixel_sigma_px;
  s.edge_m = spec.edge_sigma_m > 0 ? spec.edge_sigma_m : o.lidar_edge_sigma_m;
  return s;
}

std::vector<std::vector<Obs>> collectObservations(const MsgProblem& problem,
                                                  std::vector<std::string>* notes) {
  const int n = static_cast<int>(problem.sensors.size());
  std::vector<std::vector<Obs>> obs(problem.poses.size(), std::vector<Obs>(n));
  int skipped = 0;
  for (size_t p = 0; p < problem.poses.size(); ++p) {
    const auto& pose = problem.poses[p];
    for (const auto& [s, f] : pose.cameras) {
      if (!f.found || !validPlane(f.plane) || !f.K.allFinite()) {
        ++skipped;
        continue;
      }
      obs[p][s] = {true, f.plane, boardPoint(f), &f, nullptr};
    }
    for (const auto& [s, f] : pose.lidars) {
      if (!f.found || !validPlane(f.plane)) {
        ++skipped;
        continue;
      }
      obs[p][s] = {true, f.plane, boardPoint(f), nullptr, &f};
    }
  }
  if (skipped > 0)
    notes->push_back(std::to_string(skipped) +
                     " observation(s) skipped: board not found, or a non-finite / non-unit / "
                     "behind-the-sensor plane");
  return obs;
}

void solveLinks(const MsgProblem& problem, const MsgGraphOptions& options,
                const std::vector<std::vector<Obs>>& obs, std::vector<Sigmas>* sigmas,
                MsgSolution* sol) {
  const int n = static_cast<int>(problem.sensors.size());
  for (int a = 0; a < n; ++a)
    for (int b = a + 1; b < n; ++b) {
      PairLink link;
      link.a = a;
      link.b = b;
      sol->links.push_back(link);
    }
  const int passes = options.estimate_sensor_noise ? 2 : 1;
  for (int pass = 0; pass < passes; ++pass) {
    for (auto& link : sol->links)
      solvePair(obs, (*sigmas)[link.a], (*sigmas)[link.b], options, &link);
    if (pass + 1 == passes) break;
    std::vector<double> var_n, var_d;
    if (!estimateVariances(sol->links, n, true, &var_n) ||
        !estimateVariances(sol->links, n, false, &var_d)) {
      sol->notes.push_back(
          "sensor noise not estimated: the pairwise links contain no odd cycle; given sigmas used");
      break;
    }
    for (int s = 0; s < n; ++s) {
      const Sigmas given = resolveSigmas(problem.sensors[s], options);
      const double r = options.noise_estimate_max_ratio;
      (*sigmas)[s].normal_rad = std::clamp(std::sqrt(std::max(var_n[s], 0.0)), given.normal_rad / r,
                                           given.normal_rad * r);
      (*sigmas)[s].offset_m =
          std::clamp(std::sqrt(std::max(var_d[s], 0.0)), given.offset_m / r, given.offset_m * r);
    }
  }
}

bool spanningTreeInit(const MsgProblem& problem, const MsgGraphOptions& options, MsgSolution* sol,
                      std::vector<Eigen::Isometry3d>* init) {
  const int n = static_cast<int>(problem.sensors.size());
  const int ref = problem.reference_sensor;
  std::vector<int> parent(n, -2);
  init->assign(n, Eigen::Isometry3d::Identity());
  parent[ref] = -1;
  for (int added = 1; added < n; ++added) {
    PairLink* best = nullptr;
    for (auto& link : sol->links) {
      if (!link.success) continue;
      const bool a_in = parent[link.a] != -2, b_in = parent[link.b] != -2;
      if (a_in == b_in) continue;
      if (!best || link.views_used > best->views_used ||
          (link.views_used == best->views_used && link.offset_rms_mm < best->offset_rms_mm))
        best = &link;
    }
    if (!best) break;
    best->in_spanning_tree = true;
    if (parent[best->a] != -2) {
      parent[best->b] = best->a;
      (*init)[best->b] = (*init)[best->a] * best->a_T_b;
    } else {
      parent[best->a] = best->b;
      (*init)[best->a] = (*init)[best->b] * best->a_T_b.inverse();
    }
  }
  std::vector<std::string> unreachable;
  for (int s = 0; s < n; ++s)
    if (parent[s] == -2) unreachable.push_back(problem.sensors[s].frame);
  // The sensors to leave out: those outside the largest connected part of the graph (the
  // reference's on a tie). A reference that saw the board too rarely is itself the one cut off;
  // the others, linked among themselves, are not to blame.
  if (!unreachable.empty()) {
    std::vector<int> part(n);
    for (int s = 0; s < n; ++s) part[s] = s;
    const std::function<int(int)> root = [&](int s) {
      return part[s] == s ? s : part[s] = root(part[s]);
    };
    for (const auto& link : sol->links)
      if (link.success) part[root(link.a)] = root(link.b);
    std::vector<int> size(n, 0);
    for (int s = 0; s < n; ++s) ++size[root(s)];
    int keep = root(ref);
    for (int s = 0; s < n; ++s)
      if (size[root(s)] > size[keep]) keep = root(s);
    for (int s = 0; s < n; ++s) {
      if (root(s) == keep) continue;
      std::string own;  // why its links to the kept part failed
      for (const auto& link : sol->links)
        if ((link.a == s || link.b == s) && root(link.a == s ? link.b : link.a) == keep)
          own += (own.empty() ? "" : "; ") + problem.sensors[link.a].frame + "<->" +
                 problem.sensors[link.b].frame + ": " + link.reason;
      const std::string why = own.empty() ? "" : " (" + own + ")";
      std::string text;
      if (keep == root(ref))
        text = "cannot be reached from the reference '" + problem.sensors[ref].frame + "'" + why;
      else if (s == ref)
        text = "the reference shares too few board poses with the others" + why;
      else if (root(s) == root(ref))
        text = "linked only to the reference '" + problem.sensors[ref].frame +
               "', which the others do not reach" + why;
      else
        text = "cannot be reached from the other sensors" + why;
      sol->unplaced.push_back({s, text});
    }
  }
  if (!unreachable.empty()) {
    std::string list;
    for (const auto& u : unreachable) list += (list.empty() ? "" : ", ") + u;
    std::string why;
    for (const auto& link : sol->links)
      if (!link.success && link.shared_views > 0 &&
          (parent[link.a] == -2) != (parent[link.b] == -2))
        why += "; " + problem.sensors[link.a].frame + "<->" + problem.sensors[link.b].frame + ": " +
               link.reason;
    sol->reason = "the sensor graph is disconnected: " + list +
                  " cannot be reached from the reference '" + problem.sensors[ref].frame +
                  "' (a link needs >= " + std::to_string(options.min_shared_views) +
                  " shared board poses and a successful plane-to-plane solve)" + why;
    return false;
  }
  return true;
}

void loopErrors(int n, MsgSolution* sol) {
  auto linkOf = [&](int a, int b) -> const PairLink* {
    for (const auto& l : sol->links)
      if (l.a == std::min(a, b) && l.b == std::max(a, b)) return l.success ? &l : nullptr;
    return nullptr;
  };
  auto relative = [&](int a, int b) {
    const PairLink* l = linkOf(a, b);
    return a < b ? l->a_T_b : l->a_T_b.inverse();
  };
  for (int a = 0; a < n; ++a)
    for (int b = a + 1; b < n; ++b)
      for (int c = b + 1; c < n; ++c) {
        if (!linkOf(a, b) || !linkOf(b, c) || !linkOf(a, c)) continue;
        const Eigen::Isometry3d loop = relative(a, b) * relative(b, c) * relative(c, a);
        LoopError e;
        e.cycle = {a, b, c};
        e.rotation_deg = rotationErrorDeg(loop, Eigen::Isometry3d::Identity());
        e.translation_mm = 1000.0 * loop.translation().norm();
        sol->loop_rotation_max_deg = std::max(sol->loop_rotation_max_deg, e.rotation_deg);
        sol->loop_translation_max_mm = std::max(sol->loop_translation_max_mm, e.translation_mm);
        sol->loops.push_back(e);
      }
}

}  // namespace graph_detail
}  // namespace multi_sensor
}  // namespace board_calib
