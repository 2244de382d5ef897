// SPDX-License-Identifier: BSD-3-Clause
// The frame timeline of a simulated recording: board poses every sensor sees, holds and moves
// between them, the frames each sensor takes; the ground truth and the frame generator.
#include <board_calib/core/sim/scenario.h>
#include <board_calib/core/transform.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <random>

namespace board_calib {
namespace sim {
namespace {

constexpr int kMaxPoseAttempts = 20000;    // rejection sampling per pose
constexpr int kMinLidarRingsOnBoard = 3;   // fewer rings cannot give a plane with edges
constexpr double kCeilingClearance = 0.1;  // m
constexpr double kWallClearance = 0.5;     // m, board centre from the walls

// Smooth 0..1 ramp (zero velocity at both ends: the person starts and stops gently).
double smoothstep(double x) {
  x = std::clamp(x, 0.0, 1.0);
  return x * x * (3 - 2 * x);
}

Eigen::Isometry3d interpolate(const Eigen::Isometry3d& a, const Eigen::Isometry3d& b, double s) {
  const Eigen::Quaterniond qa(a.linear()), qb(b.linear());
  Eigen::Isometry3d out = Eigen::Isometry3d::Identity();
  out.linear() = qa.slerp(s, qb).toRotationMatrix();
  out.translation() = (1 - s) * a.translation() + s * b.translation();
  return out;
}

}  // namespace

Eigen::Isometry3d worldTCamera(const Scenario& scenario, int camera) {
  return scenario.world_T_rig * scenario.cameras[static_cast<size_t>(camera)].rig_T_sensor;
}

Eigen::Isometry3d worldTLidar(const Scenario& scenario, int lidar) {
  return scenario.world_T_rig * scenario.lidars[static_cast<size_t>(lidar)].rig_T_sensor;
}

namespace {

// Where the board is: above the floor, inside the room or street, clear of the clutter.
std::string placeProblem(const Scenario& s, const Eigen::Isometry3d& world_T_board) {
  const Target& target = s.scene.target;
  const auto outer = target.outerCorners();
  std::array<Eigen::Vector3d, 4> world;
  for (int i = 0; i < 4; ++i) world[i] = world_T_board * outer[i];
  double lowest = 1e9, highest = -1e9;
  for (const auto& p : world) {
    lowest = std::min(lowest, p.z());
    highest = std::max(highest, p.z());
  }
  if (s.scene.outdoor) {
    if (lowest < s.scene.floor_z_m + s.motion.min_board_height_m) return "board too low";
    const Eigen::Vector3d c = world_T_board * target.center();
    if (std::abs(c.x()) > s.scene.facade_distance_m - kWallClearance ||
        std::abs(c.y()) > s.scene.street_half_width_m - kWallClearance)
      return "board in a facade";
  } else if (s.scene.room) {
    if (lowest < s.scene.floor_z_m + s.motion.min_board_height_m) return "board too low";
    if (highest > s.scene.ceiling_z_m - kCeilingClearance) return "board above the ceiling";
    const Eigen::Vector3d c = world_T_board * target.center();
    if (std::abs(c.x()) > s.scene.room_half_size_m - kWallClearance ||
        std::abs(c.y()) > s.scene.room_half_size_m - kWallClearance)
      return "board in a wall";
  }
  if (!s.scene.panels.empty()) {
    // Clutter must neither cut the board nor hide a corner or the centre from any sensor.
    std::vector<Eigen::Vector3d> eyes;
    for (size_t k = 0; k < s.cameras.size(); ++k)
      eyes.push_back(worldTCamera(s, static_cast<int>(k)).translation());
    for (size_t k = 0; k < s.lidars.size(); ++k)
      eyes.push_back(worldTLidar(s, static_cast<int>(k)).translation());
    std::vector<Eigen::Vector3d> marks(world.begin(), world.end());
    marks.push_back(world_T_board * target.center());
    for (const Panel& panel : s.scene.panels) {
      const Eigen::Isometry3d panel_T_world = panel.world_T_panel.inverse();
      auto crosses = [&](const Eigen::Vector3d& a,
                         const Eigen::Vector3d& b) {  // segment a-b through the panel
        const Eigen::Vector3d pa = panel_T_world * a, pb = panel_T_world * b;
        if ((pa.z() > 0) == (pb.z() > 0)) return false;
        const Eigen::Vector3d q = pa + (pb - pa) * (pa.z() / (pa.z() - pb.z()));
        return std::abs(q.x()) <= 0.5 * panel.width_m && std::abs(q.y()) <= 0.5 * panel.height_m;
      };
      for (int e = 0; e < 4; ++e)
        if (crosses(world[e], world[(e + 1) % 4]) || crosses(world[e], world[(e + 2) % 4]))
          return "board cuts a panel";
      for (const auto& eye : eyes)
        for (const auto& m : marks)
          if (crosses(eye, m)) return "panel hides the board";
    }
  }
  return {};
}

// What the sensors see: the printed face, every corner inside each image, enough LiDAR rings
// and no edge parallel to the scan lines.
std::string sensorProblem(const Scenario& s, const std::vector<CameraModel>& models,
                          const Eigen::Isometry3d& world_T_board) {
  const Target& target = s.scene.target;
  const auto outer = target.outerCorners();
  std::array<Eigen::Vector3d, 4> world;
  for (int i = 0; i < 4; ++i) world[i] = world_T_board * outer[i];
  for (size_t k = 0; k < s.cameras.size(); ++k) {
    const Eigen::Isometry3d board_T_camera =
        world_T_board.inverse() * worldTCamera(s, static_cast<int>(k));
    if (!(board_T_camera.translation().z() < 0)) return "camera sees the back";
    const Eigen::Isometry3d camera_T_world = worldTCamera(s, static_cast<int>(k)).inverse();
    for (const auto& p : world)
      if (!models[k].isVisible(camera_T_world * p, -s.motion.image_margin_px))
        return "corner outside an image";
  }
  for (size_t k = 0; k < s.lidars.size(); ++k) {
    const LidarSpec& spec = s.lidars[k].spec;
    const Eigen::Isometry3d lidar_T_world = worldTLidar(s, static_cast<int>(k)).inverse();
    std::array<Eigen::Vector3d, 4> p;
    for (int i = 0; i < 4; ++i) p[i] = lidar_T_world * world[i];
    const Eigen::Vector3d centre = lidar_T_world * (world_T_board * target.center());
    double el_lo = 1e9, el_hi = -1e9;
    for (const auto& q : p) {
      const double el = std::atan2(q.z(), std::hypot(q.x(), q.y())) / kRadPerDeg;
      el_lo = std::min(el_lo, el);
      el_hi = std::max(el_hi, el);
      if (q.norm() < spec.min_range_m || q.norm() > spec.max_range_m)
        return "board out of LiDAR range";
    }
    int rings = 0;
    for (double e : spec.elevations_deg) rings += (e > el_lo && e < el_hi) ? 1 : 0;
    if (rings < kMinLidarRingsOnBoard) return "too few LiDAR rings on the board";
    // No edge near-parallel to the scan lines (horizontal, across the viewing direction).
    const Eigen::Vector3d view = centre.normalized();
    const Eigen::Vector3d scan = Eigen::Vector3d::UnitZ().cross(view);
    if (scan.norm() < 1e-6) return "board straight above the LiDAR";
    for (int e = 0; e < 4; ++e) {
      Eigen::Vector3d edge = p[(e + 1) % 4] - p[e];
      edge -= edge.dot(view) * view;
      const double cos_angle = std::abs(edge.normalized().dot(scan.normalized()));
      if (std::acos(std::min(1.0, cos_angle)) / kRadPerDeg < s.motion.min_edge_slope_deg)
        return "edge parallel to the scan lines";
    }
  }
  return {};
}

// Whether a board pose suits every sensor (see makeTimeline).
std::string poseProblem(const Scenario& s, const std::vector<CameraModel>& models,
                        const Eigen::Isometry3d& world_T_board) {
  const std::string place = placeProblem(s, world_T_board);
  return place.empty() ? sensorProblem(s, models, world_T_board) : place;
}

// One board pose drawn around the rig (facing its origin) with the motion's roll and tilts.
Eigen::Isometry3d drawRigTBoard(const MotionSpec& m, const Target& target, std::mt19937& rng,
                                std::uniform_real_distribution<double>& unit) {
  auto uniform = [&](double lo, double hi) { return lo + (hi - lo) * unit(rng); };
  const double d = uniform(m.min_distance_m, m.max_distance_m);
  const double az = uniform(-m.max_azimuth_deg, m.max_azimuth_deg) * kRadPerDeg;
  const double el = uniform(-m.max_elevation_deg, m.max_elevation_deg) * kRadPerDeg;
  const Eigen::Vector3d centre =
      d * Eigen::Vector3d(std::cos(el) * std::cos(az), std::cos(el) * std::sin(az), std::sin(el));
  // Facing the rig origin: z away from the rig, y down, x right as seen from the rig.
  const Eigen::Vector3d z = centre.normalized();
  const Eigen::Vector3d y =
      -(Eigen::Vector3d::UnitZ() - Eigen::Vector3d::UnitZ().dot(z) * z).normalized();
  Eigen::Matrix3d facing;
  facing.col(0) = y.cross(z);
  facing.col(1) = y;
  facing.col(2) = z;
  const double roll =
      (unit(rng) < 0.5 ? -1 : 1) * uniform(m.min_roll_deg, m.max_roll_deg) * kRadPerDeg;
  const double tilt_x = uniform(-m.max_tilt_deg, m.max_tilt_deg) * kRadPerDeg;
  const double tilt_y = uniform(-m.max_tilt_deg, m.max_tilt_deg) * kRadPerDeg;
  const Eigen::Matrix3d R = facing *
                            Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitZ()).toRotationMatrix() *
                            Eigen::AngleAxisd(tilt_x, Eigen::Vector3d::UnitX()).toRotationMatrix() *
                            Eigen::AngleAxisd(tilt_y, Eigen::Vector3d::UnitY()).toRotationMatrix();
  return makeTransform(R, centre - R * target.center());
}

// The held poses, by rejection sampling; fails naming the most frequent rejection.
Expected<std::vector<Eigen::Isometry3d>> drawBoardPoses(const Scenario& s,
                                                        const std::vector<CameraModel>& models) {
  std::mt19937 rng(s.seed);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  std::vector<Eigen::Isometry3d> poses;
  for (int i = 0; i < s.motion.poses; ++i) {
    std::map<std::string, int> rejections;
    bool placed = false;
    for (int attempt = 0; attempt < kMaxPoseAttempts && !placed; ++attempt) {
      const Eigen::Isometry3d world_T_board =
          s.world_T_rig * drawRigTBoard(s.motion, s.scene.target, rng, unit);
      const std::string problem = poseProblem(s, models, world_T_board);
      if (problem.empty()) {
        poses.push_back(world_T_board);
        placed = true;
      } else {
        ++rejections[problem];
      }
    }
    if (!placed) {
      std::string most;
      int count = 0;
      for (const auto& kv : rejections)
        if (kv.second > count) {
          most = kv.first;
          count = kv.second;
        }
      return Expected<std::vector<Eigen::Isometry3d>>::failure(
          "cannot place board pose " + std::to_string(i) + " after " +
          std::to_string(kMaxPoseAttempts) + " tries (mostly: " + most +
          "); check that the sensors' fields of view overlap at the motion's distances");
    }
  }
  return poses;
}

// The board at time t: a held pose (*pose = its index) or between two (*pose = -1).
Eigen::Isometry3d boardAt(const Timeline& timeline, const MotionSpec& m, double t, int* pose,
                          double* hold_end) {
  const double period = m.hold_s + m.move_s;
  const int k = std::clamp(static_cast<int>(std::floor(t / period)), 0, m.poses - 1);
  const double local = t - k * period;
  *hold_end = k * period + m.hold_s;
  if (local <= m.hold_s || k == m.poses - 1) {
    *pose = k;
    return timeline.world_T_board_poses[static_cast<size_t>(k)];
  }
  *pose = -1;
  const double sm = smoothstep((local - m.hold_s) / std::max(m.move_s, 1e-9));
  return interpolate(timeline.world_T_board_poses[static_cast<size_t>(k)],
                     timeline.world_T_board_poses[static_cast<size_t>(k + 1)], sm);
}

// Thin a sensor's frames: the last N still frames of each hold, N evenly spread frames of each
// move.
std::vector<Frame> thinFrames(const std::vector<Frame>& frames, const MotionSpec& m) {
  std::vector<Frame> kept;
  size_t i = 0;
  while (i < frames.size()) {
    size_t j = i;
    const bool still = frames[i].still;
    const int pose = frames[i].pose;
    while (j < frames.size() && frames[j].still == still && frames[j].pose == pose) ++j;
    const size_t n = j - i;
    if (still) {
      const size_t keep = m.still_frames_per_hold > 0
                              ? std::min(n, static_cast<size_t>(m.still_frames_per_hold))
                              : n;
      for (size_t q = j - keep; q < j; ++q) kept.push_back(frames[q]);
    } else if (m.frames_per_move < 0 || static_cast<size_t>(m.frames_per_move) >= n) {
      for (size_t q = i; q < j; ++q) kept.push_back(frames[q]);
    } else {
      for (int q = 0; q < m.frames_per_move; ++q)
        kept.push_back(frames[i + static_cast<size_t>((q + 0.5) * n / m.frames_per_move)]);
    }
    i = j;
  }
  return kept;
}

// Every frame one sensor takes over the recording, thinned.
std::vector<Frame> sensorFrames(const Timeline& timeline, const MotionSpec& m, bool is_camera,
                                int index, double rate, double offset) {
  std::vector<Frame> frames;
  const double dt = 1.0 / rate;
  // A LiDAR frame integrates one revolution; it is still only if the whole sweep is.
  const double exposure = is_camera ? 0.0 : dt;
  for (int k = 0;; ++k) {
    const double t = offset + k * dt;
    if (t > timeline.duration_s) break;
    Frame f;
    f.stamp = t;
    f.is_camera = is_camera;
    f.sensor = index;
    double hold_end = 0;
    f.world_T_board = boardAt(timeline, m, t, &f.pose, &hold_end);
    f.still = f.pose >= 0 && (t + exposure <= hold_end + 1e-9 || f.pose == m.poses - 1);
    if (!f.still) f.pose = -1;
    frames.push_back(f);
  }
  return thinFrames(frames, m);
}
}  // namespace

Expected<Timeline> makeTimeline(const Scenario& s) {
  const std::string why = s.validate();
  if (!why.empty()) return Expected<Timeline>::failure(why);
  std::vector<CameraModel> models;
  for (const auto& c : s.cameras) {
    auto m = CameraModel::create(c.intrinsics);
    if (!m) return Expected<Timeline>::failure("camera '" + c.name + "': " + m.error());
    models.push_back(*m);
  }
  auto poses = drawBoardPoses(s, models);
  if (!poses) return Expected<Timeline>::failure(poses.error());
  const MotionSpec& m = s.motion;
  Timeline timeline;
  timeline.world_T_board_poses = *poses;
  timeline.duration_s = m.poses * m.hold_s + (m.poses - 1) * m.move_s;
  auto add = [&](const std::vector<Frame>& frames) {
    timeline.frames.insert(timeline.frames.end(), frames.begin(), frames.end());
  };
  for (size_t k = 0; k < s.cameras.size(); ++k)
    add(sensorFrames(timeline, m, true, static_cast<int>(k), s.cameras[k].rate_hz,
                     s.cameras[k].stamp_offset_s));
  for (size_t k = 0; k < s.lidars.size(); ++k)
    add(sensorFrames(timeline, m, false, static_cast<int>(k), s.lidars[k].spec.rate_hz,
                     s.lidars[k].stamp_offset_s));
  std::stable_sort(timeline.frames.begin(), timeline.frames.end(),
                   [](const Frame& a, const Frame& b) { return a.stamp < b.stamp; });
  return timeline;
}

ResultFile groundTruth(const Scenario& s) {
  ResultFile r;
  r.method = "ground_truth";
  r.views_used = s.motion.poses;
  r.notes.push_back("simulated ground truth of scenario '" + s.name + "' (seed " +
                    std::to_string(s.seed) + ")");
  if (!s.cameras.empty() && !s.lidars.empty()) {
    r.camera_frame = s.cameras[0].frame_id;
    r.lidar_frame = s.lidars[0].frame_id;
    r.camera_T_lidar = worldTCamera(s, 0).inverse() * worldTLidar(s, 0);
  }
  // Reference: the first LiDAR (a frame that exists in TF), else the first camera.
  const Eigen::Isometry3d world_T_reference =
      s.lidars.empty() ? worldTCamera(s, 0) : worldTLidar(s, 0);
  r.reference_frame = s.lidars.empty() ? s.cameras[0].frame_id : s.lidars[0].frame_id;
  for (size_t k = 0; k < s.lidars.size(); ++k)
    r.sensors.push_back({s.lidars[k].frame_id, "lidar",
                         world_T_reference.inverse() * worldTLidar(s, static_cast<int>(k))});
  for (size_t k = 0; k < s.cameras.size(); ++k)
    r.sensors.push_back({s.cameras[k].frame_id, "camera",
                         world_T_reference.inverse() * worldTCamera(s, static_cast<int>(k))});
  for (size_t c = 0; c < s.cameras.size(); ++c) {
    for (size_t l = 0; l < s.lidars.size(); ++l) {
      PairEntry pair;
      pair.camera_frame = s.cameras[c].frame_id;
      pair.lidar_frame = s.lidars[l].frame_id;
      pair.camera_T_lidar =
          worldTCamera(s, static_cast<int>(c)).inverse() * worldTLidar(s, static_cast<int>(l));
      r.pairs.push_back(pair);
    }
  }
  return r;
}

Expected<FrameGenerator> FrameGenerator::create(const Scenario& scenario) {
  FrameGenerator g(scenario);
  for (const auto& c : scenario.cameras) {
    auto m = CameraModel::create(c.intrinsics);
    if (!m) return Expected<FrameGenerator>::failure("camera '" + c.name + "': " + m.error());
    g.models_.push_back(*m);
  }
  g.cache_.resize(scenario.cameras.size());
  return g;
}

namespace {
std::mt19937 frameRng(unsigned int seed, size_t frame_index) {
  std::seed_seq seq{seed, static_cast<unsigned int>(frame_index),
                    static_cast<unsigned int>(frame_index >> 32)};
  return std::mt19937(seq);
}
}  // namespace

cv::Mat FrameGenerator::image(const Frame& frame, size_t frame_index) {
  const auto k = static_cast<size_t>(frame.sensor);
  const CameraSensor& camera = scenario_->cameras[k];
  Cached& cached = cache_[k];
  cv::Mat radiance;
  if (frame.still && cached.pose == frame.pose && !cached.radiance.empty()) {
    radiance = cached.radiance;
  } else {
    radiance = renderCameraRadiance(models_[k], worldTCamera(*scenario_, frame.sensor),
                                    scenario_->scene, frame.world_T_board, camera.render);
    cached.pose = frame.still ? frame.pose : -2;
    cached.radiance = frame.still ? radiance : cv::Mat();
  }
  std::mt19937 rng = frameRng(scenario_->seed, frame_index);
  return finishCameraImage(radiance, models_[k], camera.render, rng);
}

LidarCloud FrameGenerator::cloud(const Frame& frame, size_t frame_index,
                                 std::vector<ReturnOrigin>* origins) {
  const LidarSensor& lidar = scenario_->lidars[static_cast<size_t>(frame.sensor)];
  std::mt19937 rng = frameRng(scenario_->seed, frame_index);
  LidarCloud cloud = simulateLidarScan(lidar.spec, worldTLidar(*scenario_, frame.sensor),
                                       scenario_->scene, frame.world_T_board, rng, origins);
  cloud.frame_id = lidar.frame_id;
  cloud.stamp = frame.stamp;
  return cloud;
}

}  // namespace sim
}  // namespace board_calib
