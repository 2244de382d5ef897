// SPDX-License-Identifier: BSD-3-Clause
// Synthetic multi-sensor rigs for the MSG graph (see msg_synthetic.h).
#include "support/synthetic_rig.h"
#include <board_calib/core/transform.h>

#include <ceres/ceres.h>
#include <ceres/rotation.h>

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <cmath>

namespace board_calib {
namespace sim {

namespace {

constexpr double kMinDepthM = 0.1;         // points nearer than this are not imaged
constexpr double kMinIncidenceCos = 1e-3;  // rays (almost) parallel to the board miss it
constexpr int kPnpIterations = 50;

Eigen::Isometry3d opticalTLidarBase() {
  // LiDAR x forward = optical z, LiDAR y left = -optical x, LiDAR z up = -optical y.
  Eigen::Matrix3d R;
  R.col(0) = Eigen::Vector3d(0, 0, 1);
  R.col(1) = Eigen::Vector3d(-1, 0, 0);
  R.col(2) = Eigen::Vector3d(0, -1, 0);
  return makeTransform(R, Eigen::Vector3d::Zero());
}

Eigen::Isometry3d lidarPose(const Eigen::Vector3d& translation,
                            const Eigen::Vector3d& extra_rpy_deg) {
  Eigen::Isometry3d T = opticalTLidarBase();
  T.linear() = T.linear() * fromRollPitchYaw(extra_rpy_deg * kRadPerDeg);
  T.translation() = translation;
  return T;
}

// Reprojection of a board point through camera_T_board (angle-axis + translation), in px.
struct PnpCost {
  PnpCost(const Eigen::Vector3d& board_point, const Eigen::Vector2d& pixel,
          const Eigen::Matrix3d& K)
      : board_point_(board_point), pixel_(pixel), K_(K) {}
  template <typename T>
  bool operator()(const T* const rotation, const T* const translation, T* residual) const {
    T p[3];
    const T X[3] = {T(board_point_.x()), T(board_point_.y()), T(board_point_.z())};
    ceres::AngleAxisRotatePoint(rotation, X, p);
    for (int i = 0; i < 3; ++i) p[i] += translation[i];
    if (p[2] <= T(kMinDepthM)) return false;
    residual[0] = T(K_(0, 0)) * p[0] / p[2] + T(K_(0, 2)) - T(pixel_.x());
    residual[1] = T(K_(1, 1)) * p[1] / p[2] + T(K_(1, 2)) - T(pixel_.y());
    return true;
  }
  const Eigen::Vector3d board_point_;
  const Eigen::Vector2d pixel_;
  const Eigen::Matrix3d K_;
};

// Refines camera_T_board from the noisy corners, starting at `start` (PnP as a detector does).
Eigen::Isometry3d refinePnp(const std::vector<PatternObservation>& pattern,
                            const Eigen::Matrix3d& K, const Eigen::Isometry3d& start,
                            double* rms_px) {
  Eigen::AngleAxisd aa(start.linear());
  Eigen::Vector3d r = aa.angle() * aa.axis();
  Eigen::Vector3d t = start.translation();
  ceres::Problem problem;
  for (const auto& obs : pattern)
    problem.AddResidualBlock(new ceres::AutoDiffCostFunction<PnpCost, 2, 3, 3>(
                                 new PnpCost(obs.board_point, obs.pixel, K)),
                             nullptr, r.data(), t.data());
  ceres::Solver::Options so;
  so.linear_solver_type = ceres::DENSE_QR;
  so.max_num_iterations = kPnpIterations;
  so.logging_type = ceres::SILENT;
  ceres::Solver::Summary summary;
  ceres::Solve(so, &problem, &summary);
  *rms_px = std::sqrt(2.0 * summary.final_cost / std::max<size_t>(1, 2 * pattern.size()));
  return makeTransform(expSO3(r), t);
}

Eigen::Vector2d project(const RigSensor& s, const Eigen::Vector3d& p) {
  return {s.fx * p.x() / p.z() + s.cx, s.fy * p.y() / p.z() + s.cy};
}

bool insideImage(const RigSensor& s, const Eigen::Vector2d& uv) {
  return uv.x() >= 0 && uv.y() >= 0 && uv.x() <= s.image_width - 1 && uv.y() <= s.image_height - 1;
}

// Camera observation; nullopt when the board is not completely in view.
std::optional<CameraBoardFeatures> observeCamera(const RigSensor& s, const Target& target,
                                                 const Eigen::Isometry3d& sensor_T_board,
                                                 std::mt19937& rng) {
  std::normal_distribution<double> noise(0.0, s.pixel_noise_px * s.noise_scale);
  const auto outer = target.outerCorners();
  std::array<Eigen::Vector2d, 4> outer_px;
  for (int k = 0; k < 4; ++k) {
    const Eigen::Vector3d p = sensor_T_board * outer[k];
    if (p.z() < kMinDepthM) return std::nullopt;
    outer_px[k] = project(s, p);
    if (!insideImage(s, outer_px[k])) return std::nullopt;
  }
  CameraBoardFeatures f;
  f.frame_id = s.frame;
  f.found = true;
  f.K << s.fx, 0, s.cx, 0, s.fy, s.cy, 0, 0, 1;
  f.image_width = s.image_width;
  f.image_height = s.image_height;
  for (const auto& tag : target.aprilTagCorners()) {
    for (int c = 0; c < 4; ++c) {
      PatternObservation obs;
      obs.id = tag.id * 4 + c;
      obs.board_point = tag.corners[c];
      obs.pixel =
          project(s, sensor_T_board * tag.corners[c]) + Eigen::Vector2d(noise(rng), noise(rng));
      f.pattern.push_back(obs);
    }
  }
  f.camera_T_board = refinePnp(f.pattern, f.K, sensor_T_board, &f.reprojection_rms_px);
  f.plane.normal = f.camera_T_board.linear().col(2);
  f.plane.offset = f.plane.normal.dot(f.camera_T_board.translation());
  // Edge lines through the noisy outer corners; (a, b) outward (the centre gives < 0).
  std::array<Eigen::Vector2d, 4> noisy;
  for (int k = 0; k < 4; ++k) noisy[k] = outer_px[k] + Eigen::Vector2d(noise(rng), noise(rng));
  const Eigen::Vector2d centre = project(s, sensor_T_board * target.center());
  for (int k = 0; k < 4; ++k) {
    Eigen::Vector3d l = noisy[k].homogeneous().cross(noisy[(k + 1) % 4].homogeneous());
    l /= l.head<2>().norm();
    if (l.dot(centre.homogeneous()) > 0) l = -l;
    f.edge_lines[k] = l;
    f.edge_valid[k] = true;
  }
  for (int k = 0; k < 4; ++k) {
    const Eigen::Vector3d c = f.edge_lines[k].cross(f.edge_lines[(k + 1) % 4]);
    f.corners_px[k] = c.hnormalized();
  }
  return f;
}

// Plane by PCA of the hits (normal away from the sensor) and a line through each edge's points.
void fitPlaneAndEdges(const Points3& hits, LidarBoardFeatures* out) {
  LidarBoardFeatures& f = *out;
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const auto& p : hits) mean += p;
  mean /= static_cast<double>(hits.size());
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
  for (const auto& p : hits) cov += (p - mean) * (p - mean).transpose();
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(cov);
  Eigen::Vector3d n = eig.eigenvectors().col(0);
  if (n.dot(mean) < 0) n = -n;
  f.plane.normal = n;
  f.plane.offset = n.dot(mean);
  double sq = 0;
  for (const auto& p : hits) sq += std::pow(f.plane.signedDistance(p), 2);
  f.plane_rms_m = std::sqrt(sq / hits.size());
  for (int e = 0; e < kNumEdges; ++e) {
    const auto& pts = f.edge_points[e];
    if (pts.size() < 2) continue;
    Eigen::Vector3d m = Eigen::Vector3d::Zero();
    for (const auto& p : pts) m += p;
    m /= static_cast<double>(pts.size());
    Eigen::Matrix3d c = Eigen::Matrix3d::Zero();
    for (const auto& p : pts) c += (p - m) * (p - m).transpose();
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> le(c);
    f.edge_line_point[e] = m;
    f.edge_line_direction[e] = le.eigenvectors().col(2);
    f.edge_valid[e] = true;
  }
  // Corner j joins edge j and edge j + 1 (as the detector gives them): the middle of the two
  // lines' common perpendicular.
  if (!f.allEdgesValid()) return;
  for (int j = 0; j < kNumEdges; ++j) {
    const int k = (j + 1) % kNumEdges;
    const Eigen::Vector3d &p = f.edge_line_point[j], &q = f.edge_line_point[k];
    const Eigen::Vector3d &u = f.edge_line_direction[j], &v = f.edge_line_direction[k];
    const Eigen::Vector3d w = p - q;
    const double b = u.dot(v), d = u.dot(w), e = v.dot(w), den = 1.0 - b * b;
    const double sj = den > 1e-9 ? (b * e - d) / den : 0.0;
    const double sk = den > 1e-9 ? (e - b * d) / den : 0.0;
    f.corners[j] = 0.5 * ((p + sj * u) + (q + sk * v));
  }
}

// LiDAR observation by ray casting; nullopt when too few rings / points hit the board.
std::optional<LidarBoardFeatures> observeLidar(const RigSensor& s, const RigSceneOptions& opt,
                                               const std::vector<double>& ring_bias,
                                               const Eigen::Isometry3d& sensor_T_board,
                                               std::mt19937& rng) {
  const Target& target = opt.target;
  const Eigen::Isometry3d board_T_sensor = sensor_T_board.inverse();
  Plane plane;
  plane.normal = sensor_T_board.linear().col(2);
  plane.offset = plane.normal.dot(sensor_T_board.translation());
  if (plane.offset <= 0) return std::nullopt;  // seen from the back
  // Azimuth window around the board (relative to its centre azimuth, so no wrap-around).
  const Eigen::Vector3d centre = sensor_T_board * target.center();
  const double centre_az = std::atan2(centre.y(), centre.x());
  double lo = 0, hi = 0;
  for (const auto& c : target.outerCorners()) {
    const Eigen::Vector3d p = sensor_T_board * c;
    double rel = std::atan2(p.y(), p.x()) - centre_az;
    rel = std::atan2(std::sin(rel), std::cos(rel));
    lo = std::min(lo, rel);
    hi = std::max(hi, rel);
  }
  const double step = s.horizontal_resolution_deg * kRadPerDeg;
  std::normal_distribution<double> range_noise(0.0, s.range_noise_m * s.noise_scale);
  LidarBoardFeatures f;
  f.frame_id = s.frame;
  Points3 hits;
  int rings_hit = 0;
  for (int ring = 0; ring < s.rings; ++ring) {
    const double el =
        (s.rings == 1 ? s.min_elevation_deg
                      : s.min_elevation_deg +
                            (s.max_elevation_deg - s.min_elevation_deg) * ring / (s.rings - 1)) *
        kRadPerDeg;
    Points3 ring_hits;
    Points3 ring_true;
    const long k0 = static_cast<long>(std::floor((centre_az + lo) / step));
    const long k1 = static_cast<long>(std::ceil((centre_az + hi) / step));
    for (long k = k0; k <= k1; ++k) {
      const double az = k * step;
      const Eigen::Vector3d u(std::cos(el) * std::cos(az), std::cos(el) * std::sin(az),
                              std::sin(el));
      const double cos_inc = plane.normal.dot(u);
      if (cos_inc < kMinIncidenceCos) continue;
      const double range = plane.offset / cos_inc;
      if (range > s.max_range_m) continue;
      const Eigen::Vector3d b = board_T_sensor * (range * u);
      if (b.x() < 0 || b.y() < 0 || b.x() > target.width || b.y() > target.height) continue;
      ring_true.push_back(range * u);
      ring_hits.push_back((range + ring_bias[ring] + range_noise(rng)) * u);
    }
    if (ring_hits.empty()) continue;
    ++rings_hit;
    hits.insert(hits.end(), ring_hits.begin(), ring_hits.end());
    // Per-ring extremes are edge points, assigned to the nearest physical board edge.
    for (size_t idx : {size_t{0}, ring_hits.size() - 1}) {
      const Eigen::Vector3d b = board_T_sensor * ring_true[idx];
      const std::array<double, 4> dist = {b.y(), target.width - b.x(), target.height - b.y(),
                                          b.x()};
      const int edge = static_cast<int>(std::min_element(dist.begin(), dist.end()) - dist.begin());
      f.edge_points[edge].push_back(ring_hits[idx]);
      if (ring_hits.size() == 1) break;
    }
  }
  if (rings_hit < opt.min_lidar_rings || static_cast<int>(hits.size()) < opt.min_lidar_points)
    return std::nullopt;
  fitPlaneAndEdges(hits, &f);
  // Uniform subsample of the board points (the plane above used all of them).
  if (s.max_board_points > 0 && static_cast<int>(hits.size()) > s.max_board_points) {
    std::shuffle(hits.begin(), hits.end(), rng);
    hits.resize(s.max_board_points);
  }
  f.board_points = std::move(hits);
  f.found = true;
  return f;
}

Eigen::Isometry3d drawBoardPose(const RigSceneOptions& opt, std::mt19937& rng) {
  std::uniform_real_distribution<double> uni(0.0, 1.0);
  const double two_pi = 2.0 * M_PI;
  // Centre direction inside a cone around the optical axis (z).
  const double off = opt.max_off_axis_deg * kRadPerDeg * std::sqrt(uni(rng));
  const double phi = two_pi * uni(rng);
  const Eigen::Vector3d dir(std::sin(off) * std::cos(phi), std::sin(off) * std::sin(phi),
                            std::cos(off));
  const double dist = opt.min_distance_m + (opt.max_distance_m - opt.min_distance_m) * uni(rng);
  // Normal: the viewing ray tilted by up to max_tilt about a random perpendicular axis.
  Eigen::Vector3d perp = dir.cross(Eigen::Vector3d::UnitX()).normalized();
  perp = Eigen::AngleAxisd(two_pi * uni(rng), dir) * perp;
  const double tilt = opt.max_tilt_deg * kRadPerDeg * std::sqrt(uni(rng));
  const Eigen::Vector3d n = Eigen::AngleAxisd(tilt, perp) * dir;
  // Board x: image right projected into the plane, turned into a diamond.
  Eigen::Vector3d x = (Eigen::Vector3d::UnitX() - n * n.x()).normalized();
  const double spin = (45.0 + opt.diamond_jitter_deg * (2.0 * uni(rng) - 1.0)) * kRadPerDeg;
  x = Eigen::AngleAxisd(spin, n) * x;
  const Eigen::Vector3d y = n.cross(x);
  Eigen::Matrix3d R;
  R << x, y, n;
  const Eigen::Vector3d centre = dist * dir;
  const Eigen::Vector3d origin = centre - R * opt.target.center();
  return makeTransform(R, origin);
}

}  // namespace

std::vector<RigSensor> defaultRig() {
  std::vector<RigSensor> rig;
  RigSensor left;
  left.frame = "camera_left";
  left.kind = multi_sensor::SensorKind::kCamera;
  rig.push_back(left);
  RigSensor right = left;
  right.frame = "camera_right";
  right.reference_T_sensor =
      makeTransform(fromRollPitchYaw(Eigen::Vector3d(0.3, -0.4, 0.2) * kRadPerDeg),
                    Eigen::Vector3d(0.12, 0.002, -0.001));
  rig.push_back(right);
  RigSensor vlp;
  vlp.frame = "vlp32c";
  vlp.kind = multi_sensor::SensorKind::kLidar;
  vlp.reference_T_sensor =
      lidarPose(Eigen::Vector3d(0.06, -0.18, -0.05), Eigen::Vector3d(1.5, -2.0, 3.0));
  vlp.rings = 32;
  vlp.min_elevation_deg = -25.0;
  vlp.max_elevation_deg = 15.0;
  vlp.horizontal_resolution_deg = 0.2;
  vlp.range_noise_m = 0.01;
  rig.push_back(vlp);
  RigSensor os1 = vlp;
  os1.frame = "os1_64";
  os1.reference_T_sensor =
      lidarPose(Eigen::Vector3d(0.04, 0.15, 0.02), Eigen::Vector3d(-1.0, 2.5, -4.0));
  os1.rings = 64;
  os1.min_elevation_deg = -22.5;
  os1.max_elevation_deg = 22.5;
  os1.horizontal_resolution_deg = 360.0 / 1024.0;
  os1.range_noise_m = 0.01;
  rig.push_back(os1);
  return rig;
}

RigSensor extraLidar16(const std::string& frame, double noise_scale) {
  RigSensor s;
  s.frame = frame;
  s.kind = multi_sensor::SensorKind::kLidar;
  s.reference_T_sensor =
      lidarPose(Eigen::Vector3d(-0.35, -0.10, 0.10), Eigen::Vector3d(0.5, 1.0, 6.0));
  s.rings = 16;
  s.min_elevation_deg = -15.0;
  s.max_elevation_deg = 15.0;
  s.horizontal_resolution_deg = 0.2;
  s.range_noise_m = 0.01;
  s.noise_scale = noise_scale;
  return s;
}

RigSceneOptions::RigSceneOptions() {
  target.type = TargetType::kAprilTagGrid;
  target.width = 1.0;
  target.height = 1.0;
  target.apriltag_grid.cols = 4;
  target.apriltag_grid.rows = 4;
  target.apriltag_grid.tag_size = 0.2;
  target.apriltag_grid.spacing = 0.04;
  target.apriltag_grid.origin = Eigen::Vector2d(0.04, 0.04);
}

std::string RigSceneOptions::validate() const {
  if (num_poses < 1) return "num_poses must be >= 1";
  const std::string t = target.validate();
  if (!t.empty()) return "target: " + t;
  if (target.type != TargetType::kAprilTagGrid) return "target must be an AprilTag grid";
  if (!(min_distance_m > 0) || !(max_distance_m >= min_distance_m))
    return "need 0 < min_distance_m <= max_distance_m";
  if (!(max_tilt_deg >= 0 && max_tilt_deg < 80)) return "max_tilt_deg must be in [0, 80)";
  if (!(max_off_axis_deg >= 0 && max_off_axis_deg < 80))
    return "max_off_axis_deg must be in [0, 80)";
  if (min_lidar_rings < 1 || min_lidar_points < 3)
    return "min_lidar_rings >= 1 and min_lidar_points >= 3";
  if (max_attempts < num_poses) return "max_attempts must be >= num_poses";
  return "";
}

Expected<RigScene> generateRigScene(const std::vector<RigSensor>& sensors,
                                    const RigSceneOptions& options, std::mt19937& rng) {
  const std::string invalid = options.validate();
  if (!invalid.empty()) return Expected<RigScene>::failure("invalid synthetic options: " + invalid);
  if (sensors.size() < 2) return Expected<RigScene>::failure("a rig needs >= 2 sensors");
  for (const auto& s : sensors)
    if (s.kind == multi_sensor::SensorKind::kLidar &&
        (s.rings < 1 || !(s.horizontal_resolution_deg > 0)))
      return Expected<RigScene>::failure("LiDAR '" + s.frame +
                                         "' needs >= 1 ring and a resolution > 0");
  RigScene scene;
  scene.sensors = sensors;
  for (const auto& s : sensors) {
    multi_sensor::SensorSpec spec;
    spec.frame = s.frame;
    spec.kind = s.kind;
    scene.problem.sensors.push_back(spec);
  }
  // Fixed per-ring range offsets of every LiDAR.
  std::vector<std::vector<double>> ring_bias(sensors.size());
  for (size_t i = 0; i < sensors.size(); ++i) {
    std::normal_distribution<double> bias(0.0, sensors[i].ring_bias_m * sensors[i].noise_scale);
    if (sensors[i].kind == multi_sensor::SensorKind::kLidar)
      for (int r = 0; r < sensors[i].rings; ++r) ring_bias[i].push_back(bias(rng));
  }
  // Board poses are drawn around the reference sensor's (sensor 0) optical axis.
  const Eigen::Isometry3d ref_T_s0 = sensors[0].reference_T_sensor;
  int attempts = 0;
  while (static_cast<int>(scene.problem.poses.size()) < options.num_poses) {
    if (++attempts > options.max_attempts)
      return Expected<RigScene>::failure("only " + std::to_string(scene.problem.poses.size()) +
                                         " of " + std::to_string(options.num_poses) +
                                         " board poses fit every sensor's field of view after " +
                                         std::to_string(options.max_attempts) + " draws");
    const Eigen::Isometry3d ref_T_board = ref_T_s0 * drawBoardPose(options, rng);
    multi_sensor::BoardPoseObservation obs;
    obs.id = static_cast<int>(scene.problem.poses.size());
    bool all = true;
    for (size_t i = 0; i < sensors.size() && all; ++i) {
      const Eigen::Isometry3d s_T_board = sensors[i].reference_T_sensor.inverse() * ref_T_board;
      if (sensors[i].kind == multi_sensor::SensorKind::kCamera) {
        auto f = observeCamera(sensors[i], options.target, s_T_board, rng);
        if (f)
          obs.cameras[static_cast<int>(i)] = std::move(*f);
        else
          all = false;
      } else {
        auto f = observeLidar(sensors[i], options, ring_bias[i], s_T_board, rng);
        if (f)
          obs.lidars[static_cast<int>(i)] = std::move(*f);
        else
          all = false;
      }
    }
    if (!all) continue;
    const double stamp = static_cast<double>(obs.id);
    for (auto& [i, f] : obs.cameras) f.stamp = stamp;
    for (auto& [i, f] : obs.lidars) f.stamp = stamp;
    scene.problem.poses.push_back(std::move(obs));
    scene.reference_T_board.push_back(ref_T_board);
  }
  return scene;
}

Expected<RigScene> rigScene(const std::vector<RigSensor>& sensors, int num_poses, unsigned seed) {
  std::mt19937 rng(seed);
  RigSceneOptions options;
  options.num_poses = num_poses;
  return generateRigScene(sensors, options, rng);
}

Expected<RigScene> defaultRigScene(int num_poses, unsigned seed) {
  return rigScene(defaultRig(), num_poses, seed);
}

RigConfig rigConfigOf(const RigScene& scene) {
  RigConfig rig;
  rig.target_path = "board.yaml";
  for (const auto& sensor : scene.sensors) {
    const std::string& f = sensor.frame;
    if (sensor.kind == multi_sensor::SensorKind::kCamera)
      rig.cameras.push_back({f, f + "/image_raw", f + "/camera_info", f + "/camera_board"});
    else
      rig.lidars.push_back({f, f + "/points", f + "/lidar_board"});
  }
  rig.reference = scene.sensors.front().frame;
  return rig;
}

}  // namespace sim
}  // namespace board_calib
