// The global solve of the MSG graph: plane-pair, corner and line terms of every board pose,
// the Ceres solve of one stage, and the per-observation errors for outlier rejection.
#include "graph_internal.h"

#include <board_calib/core/common/board_geometry.h>
#include <board_calib/core/common/ceres_helpers.h>
#include <board_calib/core/common/edge_association.h>
#include <board_calib/core/transform.h>

#include <algorithm>
#include <cmath>
#include <limits>

namespace board_calib {
namespace multi_sensor {
namespace graph_detail {

double msSince(Clock::time_point start) {
  return std::chrono::duration<double, std::milli>(Clock::now() - start).count();
}

double pairNormalSigmaComponent(const Sigmas& a, const Sigmas& b) {
  return std::sqrt(a.normal_rad * a.normal_rad + b.normal_rad * b.normal_rad) * kSqrtHalf;
}
double pairOffsetSigma(const Sigmas& a, const Sigmas& b) {
  return std::sqrt(a.offset_m * a.offset_m + b.offset_m * b.offset_m);
}

PlanePairError planePairError(const Obs& oa, const Obs& ob, const Eigen::Isometry3d& a_T_b,
                              const Sigmas& sa, const Sigmas& sb) {
  PlanePairError e;
  const Plane& pa = oa.plane;
  const Eigen::Vector3d rnb = a_T_b.linear() * ob.plane.normal;
  e.angle_rad = std::atan2(pa.normal.cross(rnb).norm(), pa.normal.dot(rnb));
  e.offset_m = planeGapM(pa, oa.point, ob.plane, ob.point, a_T_b);
  const double sn = std::sqrt(sa.normal_rad * sa.normal_rad + sb.normal_rad * sb.normal_rad);
  const double sd = pairOffsetSigma(sa, sb);
  e.whitened = std::sqrt(0.5 * (std::pow(e.angle_rad / sn, 2) + std::pow(e.offset_m / sd, 2)));
  return e;
}

// Board poses with corner terms: >= 2 active cameras with enough pattern points.
std::vector<int> Graph::cornerCameras(size_t p) const {
  std::vector<int> cams;
  if (!options_.use_corner_terms) return cams;
  for (int s = 0; s < n_; ++s) {
    const Obs& o = obs_[p][s];
    if (o.active && o.camera &&
        static_cast<int>(o.camera->pattern.size()) >= options_.min_shared_corners)
      cams.push_back(s);
  }
  if (cams.size() < 2) cams.clear();
  return cams;
}

// Image line matched to each LiDAR edge of (camera c, LiDAR l) at board pose p, by projection
// with the current estimate (core/common/edge_association.h, as the pair solvers and the
// overlay pair them); -1 when unmatched.
std::array<int, kNumEdges> Graph::matchedLines(size_t p, int c, int l) const {
  const Eigen::Isometry3d c_T_l = poses_[c].iso().inverse() * poses_[l].iso();
  const EdgeAssociation a =
      associateEdges(*obs_[p][c].camera, *obs_[p][l].lidar, c_T_l, options_.min_edge_points);
  std::array<int, kNumEdges> match;
  match.fill(-1);
  for (int j = 0; j < kNumEdges; ++j)
    if (a.scored[j]) match[a.lidar_edge[j]] = j;
  return match;
}

// Plane pairs of board pose p (camera pairs tied by corners are left to the corner terms).
// With K sensors on a board pose each plane enters K - 1 pairs: K(K-1)/2 pair terms carry the
// information of K - 1 independent ones, so each is inflated by sqrt(K / 2).
void Graph::addPlaneTerms(size_t p, const std::set<int>& corner_set, RobustLoss loss,
                          ceres::Problem* problem) {
  int active = 0;
  for (int s = 0; s < n_; ++s) active += obs_[p][s].active ? 1 : 0;
  const double inflate =
      options_.balance_plane_pairs ? std::sqrt(std::max(1.0, 0.5 * active)) : 1.0;
  for (int a = 0; a < n_; ++a) {
    if (!obs_[p][a].active) continue;
    for (int b = a + 1; b < n_; ++b) {
      if (!obs_[p][b].active) continue;
      if (corner_set.count(a) && corner_set.count(b)) continue;
      problem->AddResidualBlock(
          detail::PlanePairCost::Create(obs_[p][a].plane.normal, obs_[p][a].plane.offset,
                                        obs_[p][a].point, obs_[p][b].plane.normal,
                                        obs_[p][b].plane.offset, obs_[p][b].point,
                                        inflate * pairNormalSigmaComponent(sigmas_[a], sigmas_[b]),
                                        inflate * pairOffsetSigma(sigmas_[a], sigmas_[b])),
          ceres_common::makeLoss(loss, options_.loss_scale_sigma), poses_[a].q, poses_[a].t,
          poses_[b].q, poses_[b].t);
    }
  }
}

// Corner terms of board pose p: a free board pose, started from the camera with the most
// corners, and every corner of every camera in `cams` reprojected through it.
void Graph::addCornerTerms(size_t p, const std::vector<int>& cams, RobustLoss loss,
                           ceres::Problem* problem) {
  int best = cams.front();
  for (int c : cams)
    if (obs_[p][c].camera->pattern.size() > obs_[p][best].camera->pattern.size()) best = c;
  boards_[p].set(poses_[best].iso() * obs_[p][best].camera->camera_T_board);
  problem->AddParameterBlock(boards_[p].x, 7, new BoardManifold());
  for (int c : cams) {
    const CameraBoardFeatures& cam = *obs_[p][c].camera;
    for (const auto& corner : cam.pattern)
      problem->AddResidualBlock(detail::CornerCost::Create(corner.board_point, corner.pixel, cam.K,
                                                           sigmas_[c].pixel_px, kMinCornerDepthM),
                                ceres_common::makeLoss(loss, options_.loss_scale_sigma),
                                poses_[c].q, poses_[c].t, boards_[p].x);
  }
}

Graph::StageResult Graph::solve(bool planes_only, int reference, bool keep_problem) {
  auto problem = std::make_unique<ceres::Problem>();
  for (int s = 0; s < n_; ++s) {
    problem->AddParameterBlock(poses_[s].q, 4, new ceres::EigenQuaternionManifold());
    problem->AddParameterBlock(poses_[s].t, 3);
  }
  const RobustLoss loss = planes_only ? RobustLoss::kNone : options_.loss;
  std::vector<double*> board_blocks;
  for (size_t p = 0; p < obs_.size(); ++p) {
    const std::vector<int> cams = planes_only ? std::vector<int>{} : cornerCameras(p);
    addPlaneTerms(p, std::set<int>(cams.begin(), cams.end()), loss, problem.get());
    if (!cams.empty()) {
      addCornerTerms(p, cams, loss, problem.get());
      board_blocks.push_back(boards_[p].x);
    }
    if (!planes_only && options_.use_line_terms)
      addLineTerms(p, problem.get(), loss, options_.loss_scale_sigma);
  }
  problem->SetParameterBlockConstant(poses_[reference].q);
  problem->SetParameterBlockConstant(poses_[reference].t);

  ceres::Solver::Options so;
  if (!board_blocks.empty()) {
    // Board poses are independent of each other: eliminate them first (Schur complement on
    // the few sensor poses).
    so.linear_solver_type = ceres::DENSE_SCHUR;
    auto ordering = std::make_shared<ceres::ParameterBlockOrdering>();
    for (double* b : board_blocks) ordering->AddElementToGroup(b, 0);
    for (int s = 0; s < n_; ++s) {
      ordering->AddElementToGroup(poses_[s].q, 1);
      ordering->AddElementToGroup(poses_[s].t, 1);
    }
    so.linear_solver_ordering = ordering;
  } else {
    so.linear_solver_type = ceres::DENSE_QR;
  }
  ceres_common::applyStopCriteria(options_, &so);
  StageResult r = ceres_common::solveAndSummarize(so, problem.get());
  if (keep_problem) problem_kept_ = std::move(problem);
  return r;
}

// Whitened per-term magnitudes of each active observation, for rejection and statistics.
// Fills `entries[p][s]` with one value per partner term (and one for the corners).
void Graph::observationErrors(std::vector<std::vector<std::vector<double>>>* entries,
                              GraphResiduals* stats) {
  entries->assign(obs_.size(), std::vector<std::vector<double>>(n_));
  GraphResiduals g;
  double n_sq = 0, d_sq = 0, c_sq = 0, l_sq = 0;
  for (size_t p = 0; p < obs_.size(); ++p) {
    const std::vector<int> cams = cornerCameras(p);
    const std::set<int> corner_set(cams.begin(), cams.end());
    for (int a = 0; a < n_; ++a) {
      if (!obs_[p][a].active) continue;
      for (int b = a + 1; b < n_; ++b) {
        if (!obs_[p][b].active) continue;
        const Eigen::Isometry3d a_T_b = poses_[a].iso().inverse() * poses_[b].iso();
        const PlanePairError e =
            planePairError(obs_[p][a], obs_[p][b], a_T_b, sigmas_[a], sigmas_[b]);
        (*entries)[p][a].push_back(e.whitened);
        (*entries)[p][b].push_back(e.whitened);
        if (corner_set.count(a) && corner_set.count(b)) continue;  // not a graph term
        ++g.plane_terms;
        n_sq += e.angle_rad * e.angle_rad;
        d_sq += e.offset_m * e.offset_m;
      }
    }
    for (int c : cams) {
      const CameraBoardFeatures& cam = *obs_[p][c].camera;
      const Eigen::Isometry3d c_T_b = poses_[c].iso().inverse() * boards_[p].iso();
      double sq = 0.0;
      for (const auto& corner : cam.pattern) {
        const Eigen::Vector3d pc = c_T_b * corner.board_point;
        const double e2 = (pc.z() > kMinCornerDepthM)
                              ? ((cam.K * pc).hnormalized() - corner.pixel).squaredNorm()
                              : std::numeric_limits<double>::infinity();
        sq += e2;
        ++g.corner_terms;
        c_sq += e2;
      }
      (*entries)[p][c].push_back(std::sqrt(sq / (2.0 * cam.pattern.size())) / sigmas_[c].pixel_px);
    }
    if (options_.use_line_terms) {
      for (int c = 0; c < n_; ++c) {
        if (!obs_[p][c].active || !obs_[p][c].camera) continue;
        for (int l = 0; l < n_; ++l) {
          if (!obs_[p][l].active || !obs_[p][l].lidar) continue;
          const auto match = matchedLines(p, c, l);
          const Eigen::Isometry3d c_T_l = poses_[c].iso().inverse() * poses_[l].iso();
          for (int e = 0; e < kNumEdges; ++e) {
            if (match[e] < 0) continue;
            const Eigen::Vector3d N = lineNormal(*obs_[p][c].camera, match[e]);
            for (const auto& q : obs_[p][l].lidar->edge_points[e]) {
              const double r = N.dot(c_T_l * q);
              l_sq += r * r;
              ++g.line_terms;
            }
          }
        }
      }
    }
  }
  if (g.plane_terms) {
    g.normal_rms_deg = std::sqrt(n_sq / g.plane_terms) * kDegPerRad;
    g.offset_rms_mm = 1000.0 * std::sqrt(d_sq / g.plane_terms);
  }
  if (g.corner_terms) g.corner_rms_px = std::sqrt(c_sq / g.corner_terms);
  if (g.line_terms) g.line_rms_mm = 1000.0 * std::sqrt(l_sq / g.line_terms);
  *stats = g;
}

Eigen::Vector3d Graph::lineNormal(const CameraBoardFeatures& cam, int j) {
  return (cam.K.transpose() * cam.edge_lines[j]).normalized();
}

void Graph::addLineTerms(size_t p, ceres::Problem* problem, RobustLoss loss, double scale) {
  for (int c = 0; c < n_; ++c) {
    if (!obs_[p][c].active || !obs_[p][c].camera) continue;
    const CameraBoardFeatures& cam = *obs_[p][c].camera;
    for (int l = 0; l < n_; ++l) {
      if (!obs_[p][l].active || !obs_[p][l].lidar) continue;
      const LidarBoardFeatures& lid = *obs_[p][l].lidar;
      const auto match = matchedLines(p, c, l);
      for (int e = 0; e < kNumEdges; ++e) {
        if (match[e] < 0) continue;
        const Eigen::Vector3d N = lineNormal(cam, match[e]);
        // The image line's own uncertainty in metres at the board's depth, plus the LiDAR's.
        const double depth = obs_[p][c].plane.offset;
        const double line_m = depth * sigmas_[c].pixel_px / cam.K(0, 0);
        const double sigma = std::sqrt(sigmas_[l].edge_m * sigmas_[l].edge_m + line_m * line_m);
        const double w = 1.0 / (sigma * std::sqrt(static_cast<double>(lid.edge_points[e].size())));
        for (const auto& q : lid.edge_points[e])
          problem->AddResidualBlock(detail::LineCost::Create(q, N, w),
                                    ceres_common::makeLoss(loss, scale), poses_[c].q, poses_[c].t,
                                    poses_[l].q, poses_[l].t);
      }
    }
  }
}

}  // namespace graph_detail
}  // namespace multi_sensor
}  // namespace board_calib
