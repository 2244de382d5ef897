// The results of the MSG graph: every sensor's estimate, the joint pose covariance, the
// camera <- LiDAR pairs and their covariance, the links against the graph, notes; and the
// public read-outs (relative poses, stereo check, pair MLRE, the result file).
#include "graph_internal.h"

#include <board_calib/core/common/ceres_helpers.h>
#include <board_calib/core/common/format.h>
#include <board_calib/core/transform.h>

#include <limits>

namespace board_calib {
namespace multi_sensor {
namespace graph_detail {

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
  Eigen::Matrix<double, kPoseDim, 2 * kPoseDim> J =
      Eigen::Matrix<double, kPoseDim, 2 * kPoseDim>::Zero();
  J.block<3, 3>(0, 0) = -RaT;
  J.block<3, 3>(3, 0) = RaT * d_cross;
  J.block<3, 3>(3, 3) = -RaT;
  J.block<3, 3>(0, 6) = RaT;
  J.block<3, 3>(3, 9) = RaT;
  Eigen::Matrix<double, 2 * kPoseDim, 2 * kPoseDim> joint;
  const Eigen::MatrixXd& P = sol.pose_covariance;
  joint.block<kPoseDim, kPoseDim>(0, 0) = P.block<kPoseDim, kPoseDim>(kPoseDim * a, kPoseDim * a);
  joint.block<kPoseDim, kPoseDim>(0, kPoseDim) =
      P.block<kPoseDim, kPoseDim>(kPoseDim * a, kPoseDim * b);
  joint.block<kPoseDim, kPoseDim>(kPoseDim, 0) =
      P.block<kPoseDim, kPoseDim>(kPoseDim * b, kPoseDim * a);
  joint.block<kPoseDim, kPoseDim>(kPoseDim, kPoseDim) =
      P.block<kPoseDim, kPoseDim>(kPoseDim * b, kPoseDim * b);
  const Matrix6d C = J * joint * J.transpose();
  return 0.5 * (C + C.transpose());
}

bool fillSensors(const MsgProblem& problem, const MsgGraphOptions& options, Graph& graph,
                 const std::vector<Sigmas>& sigmas, const std::vector<Eigen::Isometry3d>& init,
                 MsgSolution* sol) {
  const int n = static_cast<int>(problem.sensors.size());
  const auto& o = graph.observations();
  sol->sensors.resize(n);
  for (size_t p = 0; p < o.size(); ++p) {
    int active = 0;
    for (int s = 0; s < n; ++s) active += o[p][s].active ? 1 : 0;
    if (active >= 2) ++sol->poses_used;
    for (int s = 0; s < n; ++s)
      if (o[p][s].active && active >= 2) ++sol->sensors[s].observations;
  }
  for (const auto& r : sol->rejected) ++sol->sensors[r.sensor].observations_rejected;
  for (int s = 0; s < n; ++s) {
    SensorEstimate& e = sol->sensors[s];
    e.frame = problem.sensors[s].frame;
    e.kind = problem.sensors[s].kind;
    e.reference_T_sensor = graph.poses()[s].iso();
    e.initial_reference_T_sensor = init[s];
    e.normal_sigma_deg = sigmas[s].normal_rad * kDegPerRad;
    e.offset_sigma_m = sigmas[s].offset_m;
    e.pixel_sigma_px = sigmas[s].pixel_px;
    e.edge_sigma_m = sigmas[s].edge_m;
    if (e.observations < options.min_shared_views) {
      const std::string why = "keeps only " + std::to_string(e.observations) +
                              " board pose(s) shared with another sensor after outlier "
                              "rejection (< " +
                              std::to_string(options.min_shared_views) + ")";
      if (sol->reason.empty()) sol->reason = "sensor '" + e.frame + "' " + why;
      sol->unplaced.push_back({s, why});
    }
  }
  return sol->unplaced.empty();
}

// Covariance of every sensor pose (tangent space: left rotation perturbation, translation),
// jointly: the pairs need the cross-covariance of their two poses.
void poseCovariance(const MsgGraphOptions& options, Graph& graph, MsgSolution* sol) {
  const int n = static_cast<int>(sol->sensors.size());
  const int ref = sol->reference_sensor;
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
    sol->pose_covariance = Eigen::MatrixXd::Zero(kPoseDim * n, kPoseDim * n);
    for (size_t i = 0; i < block_sensor.size(); ++i)
      for (size_t j = 0; j < block_sensor.size(); ++j)
        sol->pose_covariance.block<kPoseDim, kPoseDim>(kPoseDim * block_sensor[i],
                                                       kPoseDim * block_sensor[j]) =
            scaled.block<kPoseDim, kPoseDim>(kPoseDim * i, kPoseDim * j);
    for (int s = 0; s < n; ++s) {
      if (s == ref) continue;
      sol->sensors[s].covariance =
          sol->pose_covariance.block<kPoseDim, kPoseDim>(kPoseDim * s, kPoseDim * s);
      sol->sensors[s].stddev = stddevFromCovariance(sol->sensors[s].covariance);
    }
    sol->notes.push_back(
        "1-sigma figures follow from the sensors' noise sigmas (given or estimated); errors shared "
        "by every board pose "
        "(e.g. a LiDAR's ring range offsets, wrong intrinsics) are not in them: read them as a "
        "lower bound");
  } else {
    sol->notes.push_back("covariance not available: the graph is rank deficient at the solution");
    for (int s = 0; s < n; ++s)
      if (s != ref) sol->sensors[s].covariance.setConstant(std::numeric_limits<double>::infinity());
  }
}

// Every camera <- LiDAR pair, with its covariance when the poses have one.
void pairEstimates(MsgSolution* sol) {
  const int n = static_cast<int>(sol->sensors.size());
  for (int c = 0; c < n; ++c) {
    if (sol->sensors[c].kind != SensorKind::kCamera) continue;
    for (int l = 0; l < n; ++l) {
      if (sol->sensors[l].kind != SensorKind::kLidar) continue;
      PairEstimate pair;
      pair.camera = c;
      pair.lidar = l;
      pair.camera_T_lidar =
          sol->sensors[c].reference_T_sensor.inverse() * sol->sensors[l].reference_T_sensor;
      if (sol->pose_covariance.size() > 0) {
        pair.covariance = relativeCovarianceOf(*sol, c, l);
        pair.stddev = stddevFromCovariance(pair.covariance);
        pair.has_covariance = pair.covariance.allFinite();
      }
      sol->pairs.push_back(pair);
    }
  }
}

// Pairwise links against the graph, noisier-than-configured sensors, rejections.
void finalNotes(const MsgProblem& problem, const MsgGraphOptions& options,
                const std::vector<Sigmas>& sigmas, MsgSolution* sol) {
  const int n = static_cast<int>(problem.sensors.size());
  for (auto& link : sol->links) {
    if (!link.success) continue;
    const Eigen::Isometry3d g =
        sol->sensors[link.a].reference_T_sensor.inverse() * sol->sensors[link.b].reference_T_sensor;
    link.graph_rotation_diff_deg = rotationErrorDeg(g, link.a_T_b);
    link.graph_translation_diff_mm = 1000.0 * translationErrorM(g, link.a_T_b);
  }
  for (int s = 0; s < n; ++s) {
    const Sigmas given = resolveSigmas(problem.sensors[s], options);
    if (sigmas[s].normal_rad > 2.0 * given.normal_rad || sigmas[s].offset_m > 2.0 * given.offset_m)
      sol->notes.push_back("sensor '" + problem.sensors[s].frame +
                           "' is noisier than configured (plane normal " +
                           formatFixed(sigmas[s].normal_rad * kDegPerRad) + " deg, offset " +
                           formatFixed(1000.0 * sigmas[s].offset_m, 1) + " mm): down-weighted");
  }
  if (!sol->rejected.empty())
    sol->notes.push_back(std::to_string(sol->rejected.size()) +
                         " observation(s) rejected as outliers (> " +
                         formatFixed(options.outlier_gate_sigma, 1) + " sigma)");
}

}  // namespace graph_detail

using graph_detail::kPoseDim;

Expected<Eigen::Isometry3d> sensorTSensor(const MsgSolution& solution, int a, int b) {
  const int n = static_cast<int>(solution.sensors.size());
  if (!solution.success)
    return Expected<Eigen::Isometry3d>::failure("the graph solve did not succeed: " +
                                                solution.reason);
  if (a < 0 || b < 0 || a >= n || b >= n)
    return Expected<Eigen::Isometry3d>::failure("sensor index out of range (0.." +
                                                std::to_string(n - 1) + ")");
  return Expected<Eigen::Isometry3d>(solution.sensors[a].reference_T_sensor.inverse() *
                                     solution.sensors[b].reference_T_sensor);
}

Expected<Matrix6d> relativeCovariance(const MsgSolution& solution, int a, int b) {
  const int n = static_cast<int>(solution.sensors.size());
  if (!solution.success)
    return Expected<Matrix6d>::failure("the graph solve did not succeed: " + solution.reason);
  if (a < 0 || b < 0 || a >= n || b >= n)
    return Expected<Matrix6d>::failure("sensor index out of range (0.." + std::to_string(n - 1) +
                                       ")");
  if (solution.pose_covariance.rows() != kPoseDim * n ||
      solution.pose_covariance.cols() != kPoseDim * n)
    return Expected<Matrix6d>::failure("the solution carries no pose covariance");
  return Expected<Matrix6d>(graph_detail::relativeCovarianceOf(solution, a, b));
}

Expected<StereoConsistency> stereoConsistency(const MsgSolution& solution, int camera1, int camera2,
                                              const Eigen::Isometry3d& known_camera1_T_camera2) {
  auto T = sensorTSensor(solution, camera1, camera2);
  if (!T) return Expected<StereoConsistency>::failure(T.error());
  if (solution.sensors[camera1].kind != SensorKind::kCamera ||
      solution.sensors[camera2].kind != SensorKind::kCamera)
    return Expected<StereoConsistency>::failure("the stereo check needs two cameras");
  if (!known_camera1_T_camera2.matrix().allFinite())
    return Expected<StereoConsistency>::failure("the known stereo extrinsic is not finite");
  StereoConsistency c;
  c.rotation_deg = rotationErrorDeg(*T, known_camera1_T_camera2);
  c.translation_mm = 1000.0 * translationErrorM(*T, known_camera1_T_camera2);
  return c;
}

std::vector<View> pairViews(const MsgProblem& problem, int camera, int lidar) {
  std::vector<View> views;
  for (const auto& pose : problem.poses) {
    const auto c = pose.cameras.find(camera);
    const auto l = pose.lidars.find(lidar);
    if (c == pose.cameras.end() || l == pose.lidars.end() || !c->second.found || !l->second.found)
      continue;
    View v;
    v.id = pose.id;
    v.camera = c->second;
    v.lidar = l->second;
    views.push_back(std::move(v));
  }
  return views;
}

std::optional<double> pairMlrePx(const MsgProblem& problem, int camera, int lidar,
                                 const Eigen::Isometry3d& camera_T_lidar) {
  return meanLineReprojectionErrorPx(pairViews(problem, camera, lidar), camera_T_lidar);
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
  for (const auto& s : solution.sensors)
    r.sensors.push_back({s.frame, sensorKindName(s.kind), s.reference_T_sensor});
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
  if (solution.residuals.corner_terms)
    r.quality["corner_rms_px"] = solution.residuals.corner_rms_px;
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

}  // namespace multi_sensor
}  // namespace board_calib
