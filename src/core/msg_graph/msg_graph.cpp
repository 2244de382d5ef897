// MSG-Cal multi-sensor graph: pairwise initialisation, spanning tree, global Ceres solve with
// outlier-observation rejection (see msg_graph.h for the formulation).
#include "msg_costs.h"

#include <board_calib/core/common/board_geometry.h>
#include <board_calib/core/common/ceres_helpers.h>
#include <board_calib/core/common/edge_association.h>

#include <ceres/product_manifold.h>

#include <board_calib/core/msg_graph.h>
#include <board_calib/core/transform.h>

#include <Eigen/QR>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <memory>
#include <set>
#include <sstream>

namespace board_calib {
namespace msg {

namespace {

constexpr double kUnitTolerance = 1e-3;   // |n| - 1 accepted for a plane normal
constexpr double kMinCornerDepthM = 1e-3; // corner terms reject steps putting a corner behind
constexpr double kSqrtHalf = 0.70710678118654752;
constexpr int kMinSensors = 2;
constexpr double kRotationPerQuaternionTangent = 2.0;  // EigenQuaternionManifold: rotation vector = 2 d

constexpr int kPoseDim = 6;  // tangent size of a pose: rotation vector, translation

using Clock = std::chrono::steady_clock;
double msSince(Clock::time_point start) {
  return std::chrono::duration<double, std::milli>(Clock::now() - start).count();
}

// Covariance of a_T_b = reference_T_a^-1 * reference_T_b from the joint pose covariance (both
// poses perturbed on the left in the reference frame: R = Exp(w) R_hat, t = t_hat + v). To first
// order, with d = t_b - t_a,
//   a_T_b rotation (left, frame a):  Ra^T (w_b - w_a)
//   a_T_b translation:               Ra^T (v_b - v_a) + Ra^T [d]x w_a
// so C_ab = J [C_aa C_ab; C_ba C_bb] J^T with J = [J_a J_b].
Matrix6d relativeCovarianceOf(const MsgSolution& sol, int a, int b) {
  const Eigen::Isometry3d& Ta = sol.sensors[a].reference_T_sensor;
  const Eigen::Isometry3d& Tb = sol.sensors[b].reference_T_sensor;
  const Eigen::Matrix3d RaT = Ta.linear().transpose();
  const Eigen::Vector3d d = Tb.translation() - Ta.translation();
  Eigen::Matrix3d d_cross;
  d_cross << 0.0, -d.z(), d.y(), d.z(), 0.0, -d.x(), -d.y(), d.x(), 0.0;
  Eigen::Matrix<double, kPoseDim, 2 * kPoseDim> J = Eigen::Matrix<double, kPoseDim, 2 * kPoseDim>::Zero();
  J.block<3, 3>(0, 0) = -RaT;
  J.block<3, 3>(3, 0) = RaT * d_cross;
  J.block<3, 3>(3, 3) = -RaT;
  J.block<3, 3>(0, 6) = RaT;
  J.block<3, 3>(3, 9) = RaT;
  Eigen::Matrix<double, 2 * kPoseDim, 2 * kPoseDim> joint;
  const Eigen::MatrixXd& P = sol.pose_covariance;
  joint.block<kPoseDim, kPoseDim>(0, 0) = P.block<kPoseDim, kPoseDim>(kPoseDim * a, kPoseDim * a);
  joint.block<kPoseDim, kPoseDim>(0, kPoseDim) = P.block<kPoseDim, kPoseDim>(kPoseDim * a, kPoseDim * b);
  joint.block<kPoseDim, kPoseDim>(kPoseDim, 0) = P.block<kPoseDim, kPoseDim>(kPoseDim * b, kPoseDim * a);
  joint.block<kPoseDim, kPoseDim>(kPoseDim, kPoseDim) = P.block<kPoseDim, kPoseDim>(kPoseDim * b, kPoseDim * b);
  const Matrix6d C = J * joint * J.transpose();
  return 0.5 * (C + C.transpose());
}

bool validPlane(const Plane& p) {
  return p.normal.allFinite() && std::isfinite(p.offset) && std::abs(p.normal.norm() - 1.0) <= kUnitTolerance &&
         p.offset > 0.0;
}

std::string fmt(double v, int precision = 2) {
  std::ostringstream s;
  s.precision(precision);
  s << std::fixed << v;
  return s.str();
}

// Sigmas of one sensor in use (normal as an RMS angle in rad).
struct Sigmas {
  double normal_rad = 0.0, offset_m = 0.0, pixel_px = 0.0, edge_m = 0.0;
};

// One sensor's usable observation of one board pose.
struct Obs {
  bool active = false;
  Plane plane;
  Eigen::Vector3d point = Eigen::Vector3d::Zero();  // board point on the plane (boardPoint)
  const CameraBoardFeatures* camera = nullptr;
  const LidarBoardFeatures* lidar = nullptr;
};

struct Pose7 {
  double q[4] = {0, 0, 0, 1};
  double t[3] = {0, 0, 0};
  Eigen::Isometry3d iso() const {
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    T.linear() = Eigen::Quaterniond(q[3], q[0], q[1], q[2]).normalized().toRotationMatrix();
    T.translation() = Eigen::Vector3d(t[0], t[1], t[2]);
    return T;
  }
  void set(const Eigen::Isometry3d& T) {
    Eigen::Quaterniond qq(T.linear());
    qq.normalize();
    q[0] = qq.x();
    q[1] = qq.y();
    q[2] = qq.z();
    q[3] = qq.w();
    for (int i = 0; i < 3; ++i) t[i] = T.translation()(i);
  }
};

// A board pose as one block (quaternion x y z w, translation) so board poses form an
// independent set for the Schur elimination.
struct BoardPose {
  double x[7] = {0, 0, 0, 1, 0, 0, 0};
  Eigen::Isometry3d iso() const {
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    T.linear() = Eigen::Quaterniond(x[3], x[0], x[1], x[2]).normalized().toRotationMatrix();
    T.translation() = Eigen::Vector3d(x[4], x[5], x[6]);
    return T;
  }
  void set(const Eigen::Isometry3d& T) {
    Eigen::Quaterniond q(T.linear());
    q.normalize();
    x[0] = q.x();
    x[1] = q.y();
    x[2] = q.z();
    x[3] = q.w();
    for (int i = 0; i < 3; ++i) x[4 + i] = T.translation()(i);
  }
};
using BoardManifold = ceres::ProductManifold<ceres::EigenQuaternionManifold, ceres::EuclideanManifold<3>>;

// Pair sigmas: normal per component (the RMS angle spreads over two components), offset.
double pairNormalSigmaComponent(const Sigmas& a, const Sigmas& b) {
  return std::sqrt(a.normal_rad * a.normal_rad + b.normal_rad * b.normal_rad) * kSqrtHalf;
}
double pairOffsetSigma(const Sigmas& a, const Sigmas& b) {
  return std::sqrt(a.offset_m * a.offset_m + b.offset_m * b.offset_m);
}

// Whitened magnitude (about 1 for an inlier) of a plane pair under a relative pose a_T_b.
struct PlanePairError {
  double angle_rad = 0.0, offset_m = 0.0, whitened = 0.0;
};
PlanePairError planePairError(const Obs& oa, const Obs& ob, const Eigen::Isometry3d& a_T_b, const Sigmas& sa,
                              const Sigmas& sb) {
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

double median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  const size_t mid = v.size() / 2;
  std::nth_element(v.begin(), v.begin() + mid, v.end());
  double m = v[mid];
  if (v.size() % 2 == 0) {
    m = 0.5 * (m + *std::max_element(v.begin(), v.begin() + mid));
  }
  return m;
}

// The solver state shared by the stages.
class Graph {
 public:
  Graph(const MsgProblem& problem, const MsgGraphOptions& options, std::vector<Sigmas> sigmas,
        std::vector<std::vector<Obs>> obs)
      : problem_(problem), options_(options), sigmas_(std::move(sigmas)), obs_(std::move(obs)),
        n_(static_cast<int>(problem.sensors.size())), poses_(n_), boards_(problem.poses.size()) {}

  std::vector<Pose7>& poses() { return poses_; }
  std::vector<std::vector<Obs>>& observations() { return obs_; }

  // Board poses with corner terms: >= 2 active cameras with enough pattern points.
  std::vector<int> cornerCameras(size_t p) const {
    std::vector<int> cams;
    if (!options_.use_corner_terms) return cams;
    for (int s = 0; s < n_; ++s) {
      const Obs& o = obs_[p][s];
      if (o.active && o.camera && static_cast<int>(o.camera->pattern.size()) >= options_.min_shared_corners)
        cams.push_back(s);
    }
    if (cams.size() < 2) cams.clear();
    return cams;
  }

  // Image line matched to each LiDAR edge of (camera c, LiDAR l) at board pose p, by projection
  // with the current estimate (core/common/edge_association.h, as the pair solvers and the
  // overlay pair them); -1 when unmatched.
  std::array<int, kNumEdges> matchedLines(size_t p, int c, int l) const {
    const Eigen::Isometry3d c_T_l = poses_[c].iso().inverse() * poses_[l].iso();
    const EdgeAssociation a = associateEdges(*obs_[p][c].camera, *obs_[p][l].lidar, c_T_l, options_.min_edge_points);
    std::array<int, kNumEdges> match;
    match.fill(-1);
    for (int j = 0; j < kNumEdges; ++j)
      if (a.scored[j]) match[a.lidar_edge[j]] = j;
    return match;
  }

  struct StageResult {
    bool usable = false;
    double cost = 0.0;
    int iterations = 0;
    std::string termination, message;
  };

  // Builds and solves one stage. `planes_only`: squared loss, no corner or line terms.
  StageResult solve(bool planes_only, int reference, bool keep_problem) {
    auto problem = std::make_unique<ceres::Problem>();
    for (int s = 0; s < n_; ++s) {
      problem->AddParameterBlock(poses_[s].q, 4, new ceres::EigenQuaternionManifold());
      problem->AddParameterBlock(poses_[s].t, 3);
    }
    const RobustLoss loss = planes_only ? RobustLoss::kNone : options_.loss;
    const double scale = options_.loss_scale_sigma;
    bool any_board = false;
    std::vector<double*> board_blocks;
    for (size_t p = 0; p < obs_.size(); ++p) {
      const std::vector<int> cams = planes_only ? std::vector<int>{} : cornerCameras(p);
      const std::set<int> corner_set(cams.begin(), cams.end());
      // Plane pairs (camera pairs tied by corners are left to the corner terms). With K sensors
      // on a board pose each plane enters K - 1 pairs: K(K-1)/2 pair terms carry the
      // information of K - 1 independent ones, so each is inflated by sqrt(K / 2).
      int active = 0;
      for (int s = 0; s < n_; ++s) active += obs_[p][s].active ? 1 : 0;
      const double inflate = options_.balance_plane_pairs ? std::sqrt(std::max(1.0, 0.5 * active)) : 1.0;
      for (int a = 0; a < n_; ++a) {
        if (!obs_[p][a].active) continue;
        for (int b = a + 1; b < n_; ++b) {
          if (!obs_[p][b].active) continue;
          if (corner_set.count(a) && corner_set.count(b)) continue;
          problem->AddResidualBlock(
              detail::PlanePairCost::Create(obs_[p][a].plane.normal, obs_[p][a].plane.offset, obs_[p][a].point,
                                            obs_[p][b].plane.normal, obs_[p][b].plane.offset, obs_[p][b].point,
                                            inflate * pairNormalSigmaComponent(sigmas_[a], sigmas_[b]),
                                            inflate * pairOffsetSigma(sigmas_[a], sigmas_[b])),
              ceres_common::makeLoss(loss, scale), poses_[a].q, poses_[a].t, poses_[b].q, poses_[b].t);
        }
      }
      if (!cams.empty()) {
        // Free board pose, started from the camera with the most corners.
        int best = cams.front();
        for (int c : cams)
          if (obs_[p][c].camera->pattern.size() > obs_[p][best].camera->pattern.size()) best = c;
        boards_[p].set(poses_[best].iso() * obs_[p][best].camera->camera_T_board);
        problem->AddParameterBlock(boards_[p].x, 7, new BoardManifold());
        board_blocks.push_back(boards_[p].x);
        any_board = true;
        for (int c : cams) {
          const CameraBoardFeatures& cam = *obs_[p][c].camera;
          for (const auto& corner : cam.pattern)
            problem->AddResidualBlock(detail::CornerCost::Create(corner.board_point, corner.pixel, cam.K,
                                                                 sigmas_[c].pixel_px, kMinCornerDepthM),
                                      ceres_common::makeLoss(loss, scale), poses_[c].q, poses_[c].t, boards_[p].x);
        }
      }
      if (!planes_only && options_.use_line_terms) addLineTerms(p, problem.get(), loss, scale);
    }
    problem->SetParameterBlockConstant(poses_[reference].q);
    problem->SetParameterBlockConstant(poses_[reference].t);

    ceres::Solver::Options so;
    if (any_board) {
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
    ceres::Solver::Summary summary;
    ceres::Solve(so, problem.get(), &summary);
    StageResult r;
    r.usable = summary.IsSolutionUsable();
    r.cost = summary.final_cost;
    r.iterations = static_cast<int>(summary.iterations.size());
    r.termination = ceres::TerminationTypeToString(summary.termination_type);
    r.message = summary.message;
    if (keep_problem) problem_kept_ = std::move(problem);
    return r;
  }

  ceres::Problem* keptProblem() { return problem_kept_.get(); }

  // Whitened per-term magnitudes of each active observation, for rejection and statistics.
  // Fills `entries[p][s]` with one value per partner term (and one for the corners).
  void observationErrors(std::vector<std::vector<std::vector<double>>>* entries, GraphResiduals* stats) {
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
          const PlanePairError e = planePairError(obs_[p][a], obs_[p][b], a_T_b, sigmas_[a], sigmas_[b]);
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

 private:
  static Eigen::Vector3d lineNormal(const CameraBoardFeatures& cam, int j) {
    return (cam.K.transpose() * cam.edge_lines[j]).normalized();
  }

  void addLineTerms(size_t p, ceres::Problem* problem, RobustLoss loss, double scale) {
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
            problem->AddResidualBlock(detail::LineCost::Create(q, N, w), ceres_common::makeLoss(loss, scale), poses_[c].q,
                                      poses_[c].t, poses_[l].q, poses_[l].t);
        }
      }
    }
  }

  const MsgProblem& problem_;
  const MsgGraphOptions& options_;
  std::vector<Sigmas> sigmas_;
  std::vector<std::vector<Obs>> obs_;  // [pose][sensor]
  int n_;
  std::vector<Pose7> poses_;
  std::vector<BoardPose> boards_;
  std::unique_ptr<ceres::Problem> problem_kept_;
};

// Checks the problem's structure; empty when usable.
std::string checkProblem(const MsgProblem& problem,
                         const std::optional<std::vector<Eigen::Isometry3d>>& initial) {
  const int n = static_cast<int>(problem.sensors.size());
  if (n < kMinSensors) return "the graph needs >= 2 sensors, got " + std::to_string(n);
  if (problem.reference_sensor < 0 || problem.reference_sensor >= n)
    return "reference_sensor " + std::to_string(problem.reference_sensor) + " is not a sensor index (0.." +
           std::to_string(n - 1) + ")";
  std::set<std::string> frames;
  for (int s = 0; s < n; ++s) {
    const auto& spec = problem.sensors[s];
    if (spec.frame.empty()) return "sensor " + std::to_string(s) + " has no frame name";
    if (!frames.insert(spec.frame).second) return "frame '" + spec.frame + "' names two sensors";
    for (double v : {spec.normal_sigma_deg, spec.offset_sigma_m, spec.pixel_sigma_px, spec.edge_sigma_m})
      if (!std::isfinite(v)) return "sensor '" + spec.frame + "' has a non-finite sigma";
  }
  std::set<int> ids;
  for (const auto& pose : problem.poses) {
    if (!ids.insert(pose.id).second) return "board pose id " + std::to_string(pose.id) + " appears twice";
    for (const auto& [s, f] : pose.cameras) {
      (void)f;
      if (s < 0 || s >= n) return "board pose " + std::to_string(pose.id) + " has a camera observation of unknown sensor " + std::to_string(s);
      if (problem.sensors[s].kind != SensorKind::kCamera)
        return "board pose " + std::to_string(pose.id) + ": sensor '" + problem.sensors[s].frame +
               "' is a LiDAR but has a camera observation";
    }
    for (const auto& [s, f] : pose.lidars) {
      (void)f;
      if (s < 0 || s >= n) return "board pose " + std::to_string(pose.id) + " has a LiDAR observation of unknown sensor " + std::to_string(s);
      if (problem.sensors[s].kind != SensorKind::kLidar)
        return "board pose " + std::to_string(pose.id) + ": sensor '" + problem.sensors[s].frame +
               "' is a camera but has a LiDAR observation";
    }
  }
  if (initial) {
    if (static_cast<int>(initial->size()) != n)
      return "the initial guess has " + std::to_string(initial->size()) + " poses for " + std::to_string(n) + " sensors";
    for (const auto& T : *initial)
      if (!T.matrix().allFinite()) return "the initial guess is not finite";
  }
  return "";
}

Sigmas resolveSigmas(const SensorSpec& spec, const MsgGraphOptions& o) {
  const bool cam = spec.kind == SensorKind::kCamera;
  Sigmas s;
  s.normal_rad = (spec.normal_sigma_deg > 0 ? spec.normal_sigma_deg
                                             : (cam ? o.camera_normal_sigma_deg : o.lidar_normal_sigma_deg)) *
                 kRadPerDeg;
  s.offset_m = spec.offset_sigma_m > 0 ? spec.offset_sigma_m : (cam ? o.camera_offset_sigma_m : o.lidar_offset_sigma_m);
  s.pixel_px = spec.pixel_sigma_px > 0 ? spec.pixel_sigma_px : o.camera_pixel_sigma_px;
  s.edge_m = spec.edge_sigma_m > 0 ? spec.edge_sigma_m : o.lidar_edge_sigma_m;
  return s;
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
      const Obs oa{true, used[k].in_a, used_points[k].in_a}, ob{true, used[k].in_b, used_points[k].in_b};
      if (planePairError(oa, ob, sol.a_T_b, sa, sb).whitened <= options.outlier_gate_sigma) {
        kept.push_back(used[k]);
        kept_points.push_back(used_points[k]);
      }
    }
    if (kept.size() == used.size() || static_cast<int>(kept.size()) < options.min_shared_views) break;
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
bool estimateVariances(const std::vector<PairLink>& links, int n, bool normal, std::vector<double>* var) {
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

const char* sensorKindName(SensorKind kind) { return kind == SensorKind::kCamera ? "camera" : "lidar"; }

std::string MsgGraphOptions::validate() const {
  for (double v : {camera_normal_sigma_deg, camera_offset_sigma_m, camera_pixel_sigma_px, lidar_normal_sigma_deg,
                   lidar_offset_sigma_m, lidar_edge_sigma_m})
    if (!(v > 0) || !std::isfinite(v)) return "every default sigma must be > 0";
  if (!(noise_estimate_max_ratio >= 1.0)) return "noise_estimate_max_ratio must be >= 1";
  if (min_shared_corners < 3) return "min_shared_corners must be >= 3";
  if (min_edge_points < 2) return "min_edge_points must be >= 2";
  if (!(loss_scale_sigma > 0)) return "loss_scale_sigma must be > 0";
  if (min_shared_views < 3) return "min_shared_views must be >= 3 (plane-to-plane needs three non-coplanar planes)";
  if (!(outlier_gate_sigma > 0)) return "outlier_gate_sigma must be > 0";
  if (outlier_rounds < 0) return "outlier_rounds must be >= 0";
  if (max_iterations < 1) return "max_iterations must be >= 1";
  if (!(function_tolerance >= 0) || !(gradient_tolerance >= 0) || !(parameter_tolerance >= 0))
    return "tolerances must be >= 0";
  if (num_threads < 1) return "num_threads must be >= 1";
  if (!(min_normal_spread_deg >= 0)) return "min_normal_spread_deg must be >= 0";
  return "";
}

MsgSolution solveMsgGraph(const MsgProblem& problem, const MsgGraphOptions& options,
                          const std::optional<std::vector<Eigen::Isometry3d>>& initial_reference_T_sensor) {
  const auto start = Clock::now();
  MsgSolution sol;
  sol.reference_sensor = problem.reference_sensor;
  const std::string invalid = options.validate();
  if (!invalid.empty()) {
    sol.reason = "invalid MSG graph options: " + invalid;
    return sol;
  }
  const std::string bad = checkProblem(problem, initial_reference_T_sensor);
  if (!bad.empty()) {
    sol.reason = bad;
    return sol;
  }
  const int n = static_cast<int>(problem.sensors.size());
  const int ref = problem.reference_sensor;
  std::vector<Sigmas> sigmas;
  for (const auto& spec : problem.sensors) sigmas.push_back(resolveSigmas(spec, options));

  // Usable observations.
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
    sol.notes.push_back(std::to_string(skipped) +
                        " observation(s) skipped: board not found, or a non-finite / non-unit / behind-the-sensor plane");

  // Pairwise links (twice when the sensor noise is estimated: the second pass gates with it).
  for (int a = 0; a < n; ++a)
    for (int b = a + 1; b < n; ++b) {
      PairLink link;
      link.a = a;
      link.b = b;
      sol.links.push_back(link);
    }
  const int passes = options.estimate_sensor_noise ? 2 : 1;
  for (int pass = 0; pass < passes; ++pass) {
    for (auto& link : sol.links) solvePair(obs, sigmas[link.a], sigmas[link.b], options, &link);
    if (pass + 1 == passes) break;
    std::vector<double> var_n, var_d;
    if (!estimateVariances(sol.links, n, true, &var_n) || !estimateVariances(sol.links, n, false, &var_d)) {
      sol.notes.push_back("sensor noise not estimated: the pairwise links contain no odd cycle; given sigmas used");
      break;
    }
    for (int s = 0; s < n; ++s) {
      const Sigmas given = resolveSigmas(problem.sensors[s], options);
      const double r = options.noise_estimate_max_ratio;
      sigmas[s].normal_rad =
          std::clamp(std::sqrt(std::max(var_n[s], 0.0)), given.normal_rad / r, given.normal_rad * r);
      sigmas[s].offset_m = std::clamp(std::sqrt(std::max(var_d[s], 0.0)), given.offset_m / r, given.offset_m * r);
    }
  }

  // Maximum spanning tree from the reference (most shared views first).
  std::vector<int> parent(n, -2);
  std::vector<Eigen::Isometry3d> init(n, Eigen::Isometry3d::Identity());
  parent[ref] = -1;
  for (int added = 1; added < n; ++added) {
    PairLink* best = nullptr;
    for (auto& link : sol.links) {
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
      init[best->b] = init[best->a] * best->a_T_b;
    } else {
      parent[best->a] = best->b;
      init[best->a] = init[best->b] * best->a_T_b.inverse();
    }
  }
  std::vector<std::string> unreachable;
  for (int s = 0; s < n; ++s)
    if (parent[s] == -2) unreachable.push_back(problem.sensors[s].frame);
  if (!unreachable.empty()) {
    std::string list;
    for (const auto& u : unreachable) list += (list.empty() ? "" : ", ") + u;
    std::string why;
    for (const auto& link : sol.links)
      if (!link.success && link.shared_views > 0 &&
          (parent[link.a] == -2) != (parent[link.b] == -2))
        why += "; " + problem.sensors[link.a].frame + "<->" + problem.sensors[link.b].frame + ": " + link.reason;
    sol.reason = "the sensor graph is disconnected: " + list + " cannot be reached from the reference '" +
                 problem.sensors[ref].frame + "' (a link needs >= " + std::to_string(options.min_shared_views) +
                 " shared board poses and a successful plane-to-plane solve)" + why;
    sol.solve_time_ms = msSince(start);
    return sol;
  }
  if (initial_reference_T_sensor) {
    init = *initial_reference_T_sensor;
    sol.used_pairwise_init = false;
  }
  init[ref] = Eigen::Isometry3d::Identity();

  // Loop consistency of the pairwise estimates: every triangle.
  auto linkOf = [&](int a, int b) -> const PairLink* {
    for (const auto& l : sol.links)
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
        sol.loop_rotation_max_deg = std::max(sol.loop_rotation_max_deg, e.rotation_deg);
        sol.loop_translation_max_mm = std::max(sol.loop_translation_max_mm, e.translation_mm);
        sol.loops.push_back(e);
      }

  // Global solve: squared-loss plane stage, then every term with the robust loss, then
  // reject-and-resolve rounds.
  Graph graph(problem, options, sigmas, std::move(obs));
  for (int s = 0; s < n; ++s) graph.poses()[s].set(init[s]);
  const auto graph_start = Clock::now();
  auto stage = graph.solve(true, ref, false);
  sol.iterations += stage.iterations;
  if (!stage.usable) {
    sol.reason = "the plane stage of the graph solve failed: " + stage.message;
    sol.solve_time_ms = msSince(start);
    return sol;
  }
  std::vector<std::vector<std::vector<double>>> entries;
  for (int round = 0;; ++round) {
    stage = graph.solve(false, ref, true);
    sol.iterations += stage.iterations;
    if (!stage.usable) {
      sol.reason = "the graph solve failed: " + stage.message;
      sol.solve_time_ms = msSince(start);
      return sol;
    }
    graph.observationErrors(&entries, &sol.residuals);
    if (round >= options.outlier_rounds) break;
    int rejected = 0;
    auto& o = graph.observations();
    for (size_t p = 0; p < o.size(); ++p)
      for (int s = 0; s < n; ++s) {
        if (!o[p][s].active || entries[p][s].empty()) continue;
        const double m = median(entries[p][s]);
        if (m > options.outlier_gate_sigma) {
          o[p][s].active = false;
          sol.rejected.push_back({problem.poses[p].id, s, m});
          ++rejected;
        }
      }
    if (rejected == 0) break;
  }
  sol.graph_time_ms = msSince(graph_start);
  sol.final_cost = stage.cost;
  sol.termination = stage.termination;

  // Every sensor must still share enough board poses with another one.
  const auto& o = graph.observations();
  sol.sensors.resize(n);
  for (size_t p = 0; p < o.size(); ++p) {
    int active = 0;
    for (int s = 0; s < n; ++s) active += o[p][s].active ? 1 : 0;
    if (active >= 2) ++sol.poses_used;
    for (int s = 0; s < n; ++s)
      if (o[p][s].active && active >= 2) ++sol.sensors[s].observations;
  }
  for (const auto& r : sol.rejected) ++sol.sensors[r.sensor].observations_rejected;
  for (int s = 0; s < n; ++s) {
    SensorEstimate& e = sol.sensors[s];
    e.frame = problem.sensors[s].frame;
    e.kind = problem.sensors[s].kind;
    e.reference_T_sensor = graph.poses()[s].iso();
    e.initial_reference_T_sensor = init[s];
    e.normal_sigma_deg = sigmas[s].normal_rad * kDegPerRad;
    e.offset_sigma_m = sigmas[s].offset_m;
    e.pixel_sigma_px = sigmas[s].pixel_px;
    e.edge_sigma_m = sigmas[s].edge_m;
    if (e.observations < options.min_shared_views) {
      sol.reason = "sensor '" + e.frame + "' keeps only " + std::to_string(e.observations) +
                   " board pose(s) shared with another sensor after outlier rejection (< " +
                   std::to_string(options.min_shared_views) + ")";
      sol.solve_time_ms = msSince(start);
      return sol;
    }
  }

  // Covariance of every sensor pose (tangent space: left rotation perturbation, translation),
  // jointly: the pairs need the cross-covariance of their two poses.
  if (options.compute_covariance) {
    ceres_common::quietCeresLogging();
    ceres::Covariance::Options co;
    co.num_threads = options.num_threads;
    ceres::Covariance covariance(co);
    std::vector<const double*> blocks;
    std::vector<int> block_sensor;
    auto& poses = graph.poses();
    for (int s = 0; s < n; ++s) {
      if (s == ref) continue;
      blocks.push_back(poses[s].q);
      blocks.push_back(poses[s].t);
      block_sensor.push_back(s);
    }
    using RowMatrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
    const int free_dim = kPoseDim * static_cast<int>(block_sensor.size());
    RowMatrix tangent(free_dim, free_dim);
    if (covariance.Compute(blocks, graph.keptProblem()) &&
        covariance.GetCovarianceMatrixInTangentSpace(blocks, tangent.data())) {
      // Ceres' quaternion tangent d rotates by 2|d| (Plus: [cos|d|, sin|d| d/|d|] * q), so the
      // rotation vector is 2 d: rotation rows and columns x2.
      Eigen::VectorXd scale = Eigen::VectorXd::Ones(free_dim);
      for (size_t k = 0; k < block_sensor.size(); ++k)
        scale.segment<3>(kPoseDim * k).setConstant(kRotationPerQuaternionTangent);
      const Eigen::MatrixXd scaled = scale.asDiagonal() * tangent * scale.asDiagonal();
      sol.pose_covariance = Eigen::MatrixXd::Zero(kPoseDim * n, kPoseDim * n);
      for (size_t i = 0; i < block_sensor.size(); ++i)
        for (size_t j = 0; j < block_sensor.size(); ++j)
          sol.pose_covariance.block<kPoseDim, kPoseDim>(kPoseDim * block_sensor[i], kPoseDim * block_sensor[j]) =
              scaled.block<kPoseDim, kPoseDim>(kPoseDim * i, kPoseDim * j);
      for (int s = 0; s < n; ++s) {
        if (s == ref) continue;
        sol.sensors[s].covariance = sol.pose_covariance.block<kPoseDim, kPoseDim>(kPoseDim * s, kPoseDim * s);
        sol.sensors[s].stddev = stddevFromCovariance(sol.sensors[s].covariance);
      }
      sol.notes.push_back(
          "1-sigma figures follow from the sensors' noise sigmas (given or estimated); errors shared by every board pose "
          "(e.g. a LiDAR's ring range offsets, wrong intrinsics) are not in them: read them as a lower bound");
    } else {
      sol.notes.push_back("covariance not available: the graph is rank deficient at the solution");
      for (int s = 0; s < n; ++s)
        if (s != ref) sol.sensors[s].covariance.setConstant(std::numeric_limits<double>::infinity());
    }
  }

  // Every camera <- LiDAR pair, with its covariance when the poses have one.
  for (int c = 0; c < n; ++c) {
    if (sol.sensors[c].kind != SensorKind::kCamera) continue;
    for (int l = 0; l < n; ++l) {
      if (sol.sensors[l].kind != SensorKind::kLidar) continue;
      PairEstimate pair;
      pair.camera = c;
      pair.lidar = l;
      pair.camera_T_lidar = sol.sensors[c].reference_T_sensor.inverse() * sol.sensors[l].reference_T_sensor;
      if (sol.pose_covariance.size() > 0) {
        pair.covariance = relativeCovarianceOf(sol, c, l);
        pair.stddev = stddevFromCovariance(pair.covariance);
        pair.has_covariance = pair.covariance.allFinite();
      }
      sol.pairs.push_back(pair);
    }
  }

  // Pairwise against the graph.
  for (auto& link : sol.links) {
    if (!link.success) continue;
    const Eigen::Isometry3d g = sol.sensors[link.a].reference_T_sensor.inverse() * sol.sensors[link.b].reference_T_sensor;
    link.graph_rotation_diff_deg = rotationErrorDeg(g, link.a_T_b);
    link.graph_translation_diff_mm = 1000.0 * translationErrorM(g, link.a_T_b);
  }
  for (int s = 0; s < n; ++s) {
    const Sigmas given = resolveSigmas(problem.sensors[s], options);
    if (sigmas[s].normal_rad > 2.0 * given.normal_rad || sigmas[s].offset_m > 2.0 * given.offset_m)
      sol.notes.push_back("sensor '" + problem.sensors[s].frame + "' is noisier than configured (plane normal " +
                          fmt(sigmas[s].normal_rad * kDegPerRad) + " deg, offset " + fmt(1000.0 * sigmas[s].offset_m, 1) +
                          " mm): down-weighted");
  }
  if (!sol.rejected.empty())
    sol.notes.push_back(std::to_string(sol.rejected.size()) + " observation(s) rejected as outliers (> " +
                        fmt(options.outlier_gate_sigma, 1) + " sigma)");
  sol.success = true;
  sol.solve_time_ms = msSince(start);
  return sol;
}

Expected<Eigen::Isometry3d> sensorTSensor(const MsgSolution& solution, int a, int b) {
  const int n = static_cast<int>(solution.sensors.size());
  if (!solution.success) return Expected<Eigen::Isometry3d>::failure("the graph solve did not succeed: " + solution.reason);
  if (a < 0 || b < 0 || a >= n || b >= n)
    return Expected<Eigen::Isometry3d>::failure("sensor index out of range (0.." + std::to_string(n - 1) + ")");
  return Expected<Eigen::Isometry3d>(solution.sensors[a].reference_T_sensor.inverse() *
                                     solution.sensors[b].reference_T_sensor);
}

Expected<Matrix6d> relativeCovariance(const MsgSolution& solution, int a, int b) {
  const int n = static_cast<int>(solution.sensors.size());
  if (!solution.success) return Expected<Matrix6d>::failure("the graph solve did not succeed: " + solution.reason);
  if (a < 0 || b < 0 || a >= n || b >= n)
    return Expected<Matrix6d>::failure("sensor index out of range (0.." + std::to_string(n - 1) + ")");
  if (solution.pose_covariance.rows() != kPoseDim * n || solution.pose_covariance.cols() != kPoseDim * n)
    return Expected<Matrix6d>::failure("the solution carries no pose covariance");
  return Expected<Matrix6d>(relativeCovarianceOf(solution, a, b));
}

Expected<StereoConsistency> stereoConsistency(const MsgSolution& solution, int camera1, int camera2,
                                              const Eigen::Isometry3d& known_camera1_T_camera2) {
  auto T = sensorTSensor(solution, camera1, camera2);
  if (!T) return Expected<StereoConsistency>::failure(T.error());
  if (solution.sensors[camera1].kind != SensorKind::kCamera || solution.sensors[camera2].kind != SensorKind::kCamera)
    return Expected<StereoConsistency>::failure("the stereo check needs two cameras");
  if (!known_camera1_T_camera2.matrix().allFinite())
    return Expected<StereoConsistency>::failure("the known stereo extrinsic is not finite");
  StereoConsistency c;
  c.rotation_deg = rotationErrorDeg(*T, known_camera1_T_camera2);
  c.translation_mm = 1000.0 * translationErrorM(*T, known_camera1_T_camera2);
  return c;
}

std::optional<double> pairMlrePx(const MsgProblem& problem, int camera, int lidar,
                                 const Eigen::Isometry3d& camera_T_lidar) {
  std::vector<View> views;
  for (const auto& pose : problem.poses) {
    const auto c = pose.cameras.find(camera);
    const auto l = pose.lidars.find(lidar);
    if (c == pose.cameras.end() || l == pose.lidars.end() || !c->second.found || !l->second.found) continue;
    View v;
    v.id = pose.id;
    v.camera = c->second;
    v.lidar = l->second;
    views.push_back(std::move(v));
  }
  return meanLineReprojectionErrorPx(views, camera_T_lidar);
}

ResultFile msgResultFile(const MsgProblem& problem, const MsgSolution& solution) {
  ResultFile r;
  r.method = "msg";
  r.notes = solution.notes;
  if (!solution.success) {
    r.notes.push_back("MSG graph failed: " + solution.reason);
    return r;
  }
  r.reference_frame = solution.sensors[solution.reference_sensor].frame;
  r.views_used = solution.poses_used;
  for (const auto& s : solution.sensors) r.sensors.push_back({s.frame, sensorKindName(s.kind), s.reference_T_sensor});
  for (const PairEstimate& pair : solution.pairs) {
    PairEntry e;
    e.camera_frame = solution.sensors[pair.camera].frame;
    e.lidar_frame = solution.sensors[pair.lidar].frame;
    e.camera_T_lidar = pair.camera_T_lidar;
    e.mlre_px = pairMlrePx(problem, pair.camera, pair.lidar, e.camera_T_lidar);
    if (pair.has_covariance) e.stddev = pair.stddev;
    r.pairs.push_back(e);
  }
  if (!r.pairs.empty()) {
    const PairEntry& first = r.pairs.front();
    r.camera_frame = first.camera_frame;
    r.lidar_frame = first.lidar_frame;
    r.camera_T_lidar = first.camera_T_lidar;
    r.mlre_px = first.mlre_px;
    r.stddev = first.stddev;
  }
  r.quality["loop_rotation_max_deg"] = solution.loop_rotation_max_deg;
  r.quality["loop_translation_max_mm"] = solution.loop_translation_max_mm;
  r.quality["loops"] = static_cast<double>(solution.loops.size());
  r.quality["plane_normal_rms_deg"] = solution.residuals.normal_rms_deg;
  r.quality["plane_offset_rms_mm"] = solution.residuals.offset_rms_mm;
  if (solution.residuals.corner_terms) r.quality["corner_rms_px"] = solution.residuals.corner_rms_px;
  if (solution.residuals.line_terms) r.quality["line_rms_mm"] = solution.residuals.line_rms_mm;
  r.quality["rejected_observations"] = static_cast<double>(solution.rejected.size());
  r.quality["final_cost"] = solution.final_cost;
  r.quality["solve_time_ms"] = solution.solve_time_ms;
  for (const auto& s : solution.sensors) {
    if (&s == &solution.sensors[solution.reference_sensor]) continue;
    r.quality["stddev_rotation_max_deg." + s.frame] = s.stddev.rotation_deg.maxCoeff();
    r.quality["stddev_translation_max_mm." + s.frame] = 1000.0 * s.stddev.translation_m.maxCoeff();
  }
  return r;
}

}  // namespace msg
}  // namespace board_calib
