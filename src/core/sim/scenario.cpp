// Scenario file parsing, board motion and the frame timeline of a simulated recording.
#include <board_calib/core/sim/scenario.h>
#include <board_calib/core/transform.h>

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <random>
#include <set>
#include <sstream>

namespace board_calib {
namespace sim {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr int kMaxPoseAttempts = 20000;   // rejection sampling per pose
constexpr int kMinLidarRingsOnBoard = 3;  // fewer rings cannot give a plane with edges
constexpr double kCeilingClearance = 0.1; // m
constexpr double kWallClearance = 0.5;    // m, board centre from the walls

// Seeded clutter (scene.posters) and printed marks (scene.board_marks).
constexpr double kPosterSizeMin = 0.8, kPosterSizeMax = 1.3;  // of the board's sides: board-sized
constexpr double kPosterStandoffMin = 0.02, kPosterStandoffMax = 0.3;  // m off the wall (poster .. screen, cabinet)
constexpr double kDoorWidth = 0.9, kDoorHeight = 2.0;  // m
constexpr double kDoorFraction = 0.2;        // of the wall panels
constexpr double kFreeStandingFraction = 0.4;
constexpr double kDiamondFraction = 0.3;     // of the free-standing panels: rolled like a held board
constexpr double kClutterClearance = 1.5;    // m beyond the farthest board pose / off the motion's cone (plus 15 deg)
constexpr double kClutterConeMarginDeg = 15.0;
constexpr double kFacadeClutterReach = 30.0; // m along a facade from the rig (the LiDAR's useful range)
constexpr int kClutterAttempts = 200;
constexpr double kMarkInset = 0.06;          // m, marks stay this far inside the board's edges
constexpr double kMarkMinW = 0.02, kMarkMaxW = 0.12, kMarkMinH = 0.01, kMarkMaxH = 0.05;  // m

// ---------------------------------------------------------------------------------------------
// YAML helpers: strict keys, errors that name the key.
// ---------------------------------------------------------------------------------------------
struct ScenarioError {
  std::string message;
};

void rejectUnknownKeys(const YAML::Node& node, const std::set<std::string>& allowed, const std::string& where) {
  if (!node.IsMap()) throw ScenarioError{"'" + where + "' must be a map"};
  for (const auto& kv : node) {
    const std::string key = kv.first.as<std::string>();
    if (!allowed.count(key)) {
      std::string list;
      for (const auto& a : allowed) list += (list.empty() ? "" : ", ") + a;
      throw ScenarioError{"unknown key '" + where + "." + key + "' (allowed: " + list + ")"};
    }
  }
}

template <typename T>
T readValue(const YAML::Node& node, const std::string& key, const std::string& where, const char* type_name) {
  const YAML::Node value = node[key];
  if (!value) throw ScenarioError{"missing key '" + where + "." + key + "'"};
  if (!value.IsScalar()) throw ScenarioError{"key '" + where + "." + key + "' must be a " + type_name};
  try {
    return value.as<T>();
  } catch (const YAML::Exception&) {
    throw ScenarioError{"key '" + where + "." + key + "' must be a " + type_name + ", got '" + value.Scalar() + "'"};
  }
}

template <typename T>
void readOptional(const YAML::Node& node, const std::string& key, const std::string& where, const char* type_name,
                  T* out) {
  if (node[key]) *out = readValue<T>(node, key, where, type_name);
}

std::vector<double> readNumbers(const YAML::Node& node, const std::string& key, const std::string& where) {
  const YAML::Node value = node[key];
  if (!value || !value.IsSequence()) throw ScenarioError{"key '" + where + "." + key + "' must be a list of numbers"};
  std::vector<double> out;
  for (size_t i = 0; i < value.size(); ++i) {
    try {
      out.push_back(value[i].as<double>());
    } catch (const YAML::Exception&) {
      throw ScenarioError{"key '" + where + "." + key + "' must be a list of numbers"};
    }
  }
  return out;
}

// Camera body (x forward, y left, z up) -> optical (z forward, x right, y down).
Eigen::Matrix3d bodyROptical() {
  Eigen::Matrix3d R;
  R.col(0) = -Eigen::Vector3d::UnitY();
  R.col(1) = -Eigen::Vector3d::UnitZ();
  R.col(2) = Eigen::Vector3d::UnitX();
  return R;
}

// pose: {translation: [x, y, z], rpy_deg: [r, p, y]} or {translation, rotation_xyzw}. For a
// camera, rpy_deg orients its body frame (x forward) and the optical frame follows; a
// quaternion gives the optical frame directly.
Eigen::Isometry3d readPose(const YAML::Node& parent, const std::string& where, bool camera) {
  const YAML::Node node = parent["pose"];
  if (!node) return camera ? makeTransform(bodyROptical(), Eigen::Vector3d::Zero()) : Eigen::Isometry3d::Identity();
  const std::string at = where + ".pose";
  rejectUnknownKeys(node, {"translation", "rpy_deg", "rotation_xyzw"}, at);
  Eigen::Vector3d t = Eigen::Vector3d::Zero();
  if (node["translation"]) {
    const auto v = readNumbers(node, "translation", at);
    if (v.size() != 3) throw ScenarioError{"key '" + at + ".translation' must be [x, y, z] in metres"};
    t = Eigen::Vector3d(v[0], v[1], v[2]);
  }
  if (node["rpy_deg"] && node["rotation_xyzw"])
    throw ScenarioError{"'" + at + "': give either rpy_deg or rotation_xyzw, not both"};
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
  if (node["rotation_xyzw"]) {
    const auto q = readNumbers(node, "rotation_xyzw", at);
    if (q.size() != 4 || Eigen::Vector4d(q[0], q[1], q[2], q[3]).norm() < 1e-9)
      throw ScenarioError{"key '" + at + ".rotation_xyzw' must be a non-zero quaternion [qx, qy, qz, qw]"};
    return makeTransform(t, Eigen::Vector4d(q[0], q[1], q[2], q[3]));
  }
  if (node["rpy_deg"]) {
    const auto rpy = readNumbers(node, "rpy_deg", at);
    if (rpy.size() != 3) throw ScenarioError{"key '" + at + ".rpy_deg' must be [roll, pitch, yaw] in degrees"};
    R = fromRollPitchYaw(Eigen::Vector3d(rpy[0], rpy[1], rpy[2]) * kRadPerDeg);
  }
  if (camera) R = R * bodyROptical();
  return makeTransform(R, t);
}

RenderOptions readRender(const YAML::Node& parent, const std::string& where) {
  RenderOptions r;
  const YAML::Node node = parent["render"];
  if (!node) return r;
  const std::string at = where + ".render";
  rejectUnknownKeys(node, {"supersampling", "noise_sigma", "vignetting", "blur_sigma_px"}, at);
  readOptional(node, "supersampling", at, "integer", &r.supersampling);
  readOptional(node, "noise_sigma", at, "number", &r.noise_sigma);
  readOptional(node, "vignetting", at, "number", &r.vignetting);
  readOptional(node, "blur_sigma_px", at, "number", &r.blur_sigma_px);
  const std::string why = r.validate();
  if (!why.empty()) throw ScenarioError{"'" + at + "': " + why};
  return r;
}

CameraSensor readCamera(const YAML::Node& node, const std::string& where) {
  rejectUnknownKeys(node, {"name", "frame_id", "width", "height", "fx", "fy", "cx", "cy", "distortion_model", "D",
                           "rate_hz", "stamp_offset_s", "pose", "render"},
                    where);
  CameraSensor c;
  c.name = readValue<std::string>(node, "name", where, "string");
  c.frame_id = c.name + "_optical";
  readOptional(node, "frame_id", where, "string", &c.frame_id);
  auto& in = c.intrinsics;
  in.width = readValue<int>(node, "width", where, "integer");
  in.height = readValue<int>(node, "height", where, "integer");
  in.fx = readValue<double>(node, "fx", where, "number");
  in.fy = readValue<double>(node, "fy", where, "number");
  in.cx = readValue<double>(node, "cx", where, "number");
  in.cy = readValue<double>(node, "cy", where, "number");
  std::string model;
  readOptional(node, "distortion_model", where, "string", &model);
  const auto parsed = parseDistortionModel(model);
  if (!parsed) throw ScenarioError{"key '" + where + ".distortion_model': " + parsed.error()};
  in.model = *parsed;
  if (node["D"]) in.coeffs = readNumbers(node, "D", where);
  const auto check = CameraModel::create(in);
  if (!check) throw ScenarioError{"'" + where + "': " + check.error()};
  readOptional(node, "rate_hz", where, "number", &c.rate_hz);
  readOptional(node, "stamp_offset_s", where, "number", &c.stamp_offset_s);
  c.rig_T_sensor = readPose(node, where, true);
  c.render = readRender(node, where);
  return c;
}

LidarSensor readLidar(const YAML::Node& node, const std::string& where) {
  rejectUnknownKeys(node, {"name", "frame_id", "preset", "rate_hz", "stamp_offset_s", "pose", "range_noise_m",
                           "min_range_m", "max_range_m", "dropout_probability", "beam_divergence_deg", "organized",
                           "with_ring", "mixed_return_max_gap_m", "intensity_noise", "horizontal_resolution_deg",
                           "elevations_deg", "azimuth_offsets_deg"},
                    where);
  LidarSensor l;
  l.name = readValue<std::string>(node, "name", where, "string");
  l.frame_id = l.name;
  readOptional(node, "frame_id", where, "string", &l.frame_id);
  if (node["preset"]) {
    const auto preset = lidarPreset(readValue<std::string>(node, "preset", where, "string"));
    if (!preset) throw ScenarioError{"key '" + where + ".preset': " + preset.error()};
    l.spec = *preset;
  } else {
    l.spec.name = "custom";
    if (!node["elevations_deg"]) throw ScenarioError{"'" + where + "' needs a preset or elevations_deg"};
  }
  auto& s = l.spec;
  if (node["elevations_deg"]) s.elevations_deg = readNumbers(node, "elevations_deg", where);
  if (node["azimuth_offsets_deg"]) s.azimuth_offsets_deg = readNumbers(node, "azimuth_offsets_deg", where);
  readOptional(node, "horizontal_resolution_deg", where, "number", &s.horizontal_resolution_deg);
  readOptional(node, "range_noise_m", where, "number", &s.range_noise_m);
  readOptional(node, "min_range_m", where, "number", &s.min_range_m);
  readOptional(node, "max_range_m", where, "number", &s.max_range_m);
  readOptional(node, "dropout_probability", where, "number", &s.dropout_probability);
  readOptional(node, "beam_divergence_deg", where, "number", &s.beam_divergence_deg);
  readOptional(node, "organized", where, "bool", &s.organized);
  readOptional(node, "with_ring", where, "bool", &s.with_ring);
  readOptional(node, "mixed_return_max_gap_m", where, "number", &s.mixed_return_max_gap_m);
  readOptional(node, "intensity_noise", where, "number", &s.intensity_noise);
  readOptional(node, "rate_hz", where, "number", &s.rate_hz);
  readOptional(node, "stamp_offset_s", where, "number", &l.stamp_offset_s);
  const std::string why = s.validate();
  if (!why.empty()) throw ScenarioError{"'" + where + "': " + why};
  l.rig_T_sensor = readPose(node, where, false);
  return l;
}

MotionSpec readMotion(const YAML::Node& node) {
  MotionSpec m;
  if (!node) return m;
  const std::string at = "motion";
  rejectUnknownKeys(node, {"poses", "min_distance_m", "max_distance_m", "max_azimuth_deg", "max_elevation_deg",
                           "min_roll_deg", "max_roll_deg", "max_tilt_deg", "min_edge_slope_deg",
                           "min_board_height_m", "hold_s", "move_s", "still_frames_per_hold", "frames_per_move",
                           "image_margin_px"},
                    at);
  readOptional(node, "poses", at, "integer", &m.poses);
  readOptional(node, "min_distance_m", at, "number", &m.min_distance_m);
  readOptional(node, "max_distance_m", at, "number", &m.max_distance_m);
  readOptional(node, "max_azimuth_deg", at, "number", &m.max_azimuth_deg);
  readOptional(node, "max_elevation_deg", at, "number", &m.max_elevation_deg);
  readOptional(node, "min_roll_deg", at, "number", &m.min_roll_deg);
  readOptional(node, "max_roll_deg", at, "number", &m.max_roll_deg);
  readOptional(node, "max_tilt_deg", at, "number", &m.max_tilt_deg);
  readOptional(node, "min_edge_slope_deg", at, "number", &m.min_edge_slope_deg);
  readOptional(node, "min_board_height_m", at, "number", &m.min_board_height_m);
  readOptional(node, "hold_s", at, "number", &m.hold_s);
  readOptional(node, "move_s", at, "number", &m.move_s);
  readOptional(node, "still_frames_per_hold", at, "integer", &m.still_frames_per_hold);
  readOptional(node, "frames_per_move", at, "integer", &m.frames_per_move);
  readOptional(node, "image_margin_px", at, "number", &m.image_margin_px);
  const std::string why = m.validate();
  if (!why.empty()) throw ScenarioError{"'motion': " + why};
  return m;
}

// Board-like clutter and printed marks drawn from the scenario seed (or scene.clutter_seed).
struct SceneRandom {
  int posters = 0;
  int board_marks = 0;
  bool have_seed = false;
  unsigned int seed = 0;
};

Eigen::Vector3d readColour(const YAML::Node& node, const std::string& key, const std::string& where) {
  const auto v = readNumbers(node, key, where);
  if (v.size() != 3) throw ScenarioError{"key '" + where + "." + key + "' must be [r, g, b] factors"};
  return {v[2], v[1], v[0]};  // stored b, g, r as the renderer's colours
}

// Panel orientation: with rpy 0 it stands upright facing the rig (normal along world +x, x to
// world -y, y down), like the board; roll turns it in its plane.
Eigen::Matrix3d facingRig() {
  Eigen::Matrix3d R;
  R.col(0) = -Eigen::Vector3d::UnitY();
  R.col(1) = -Eigen::Vector3d::UnitZ();
  R.col(2) = Eigen::Vector3d::UnitX();
  return R;
}

Panel readPanel(const YAML::Node& node, const std::string& where) {
  rejectUnknownKeys(node, {"center", "rpy_deg", "width", "height", "grey", "tint", "intensity"}, where);
  Panel panel;
  const auto c = readNumbers(node, "center", where);
  if (c.size() != 3) throw ScenarioError{"key '" + where + ".center' must be [x, y, z] in metres"};
  Eigen::Vector3d rpy = Eigen::Vector3d::Zero();
  if (node["rpy_deg"]) {
    const auto v = readNumbers(node, "rpy_deg", where);
    if (v.size() != 3) throw ScenarioError{"key '" + where + ".rpy_deg' must be [roll, pitch, yaw] in degrees"};
    rpy = Eigen::Vector3d(v[0], v[1], v[2]);
  }
  panel.world_T_panel = makeTransform(fromRollPitchYaw(rpy * kRadPerDeg) * facingRig(), Eigen::Vector3d(c[0], c[1], c[2]));
  panel.width_m = readValue<double>(node, "width", where, "number");
  panel.height_m = readValue<double>(node, "height", where, "number");
  readOptional(node, "grey", where, "number", &panel.grey);
  if (node["tint"]) panel.tint = readColour(node, "tint", where);
  readOptional(node, "intensity", where, "number", &panel.intensity);
  const std::string why = panel.validate();
  if (!why.empty()) throw ScenarioError{"'" + where + "': " + why};
  return panel;
}

void readScene(const YAML::Node& node, SceneSpec* scene, SceneRandom* random) {
  if (!node) return;
  const std::string at = "scene";
  rejectUnknownKeys(node, {"room", "room_half_size_m", "floor_z_m", "ceiling_z_m", "occluder", "board_intensity",
                           "background_intensity", "outdoor", "street_half_width_m", "facade_distance_m",
                           "ground_grey", "board_grey", "board_tint", "board_texture", "board_marks", "posters",
                           "panels", "clutter_seed"},
                    at);
  readOptional(node, "outdoor", at, "bool", &scene->outdoor);
  readOptional(node, "street_half_width_m", at, "number", &scene->street_half_width_m);
  readOptional(node, "facade_distance_m", at, "number", &scene->facade_distance_m);
  readOptional(node, "ground_grey", at, "number", &scene->ground_grey);
  readOptional(node, "board_grey", at, "number", &scene->board_grey);
  if (node["board_tint"]) scene->board_tint = readColour(node, "board_tint", at);
  readOptional(node, "board_texture", at, "number", &scene->board_texture);
  if (node["board_marks"]) {
    const YAML::Node marks = node["board_marks"];
    if (marks.IsScalar()) {
      random->board_marks = readValue<int>(node, "board_marks", at, "integer or a list of {min, max}");
      if (random->board_marks < 0) throw ScenarioError{"key 'scene.board_marks' must be >= 0"};
    } else if (marks.IsSequence()) {
      for (size_t i = 0; i < marks.size(); ++i) {
        const std::string where = at + ".board_marks[" + std::to_string(i) + "]";
        rejectUnknownKeys(marks[i], {"min", "max"}, where);
        const auto lo = readNumbers(marks[i], "min", where), hi = readNumbers(marks[i], "max", where);
        if (lo.size() != 2 || hi.size() != 2) throw ScenarioError{"'" + where + "': min and max must be [x, y] in metres"};
        scene->board_marks.push_back({Eigen::Vector2d(lo[0], lo[1]), Eigen::Vector2d(hi[0], hi[1])});
      }
    } else {
      throw ScenarioError{"key 'scene.board_marks' must be an integer or a list of {min, max}"};
    }
  }
  readOptional(node, "posters", at, "integer", &random->posters);
  if (random->posters < 0) throw ScenarioError{"key 'scene.posters' must be >= 0"};
  if (node["panels"]) {
    if (!node["panels"].IsSequence()) throw ScenarioError{"key 'scene.panels' must be a list"};
    for (size_t i = 0; i < node["panels"].size(); ++i)
      scene->panels.push_back(readPanel(node["panels"][i], at + ".panels[" + std::to_string(i) + "]"));
  }
  if (node["clutter_seed"]) {
    random->seed = readValue<unsigned int>(node, "clutter_seed", at, "non-negative integer");
    random->have_seed = true;
  }
  readOptional(node, "room", at, "bool", &scene->room);
  readOptional(node, "room_half_size_m", at, "number", &scene->room_half_size_m);
  readOptional(node, "floor_z_m", at, "number", &scene->floor_z_m);
  readOptional(node, "ceiling_z_m", at, "number", &scene->ceiling_z_m);
  readOptional(node, "occluder", at, "bool", &scene->occluder);
  readOptional(node, "board_intensity", at, "number", &scene->board_intensity);
  readOptional(node, "background_intensity", at, "number", &scene->background_intensity);
}

std::string joinPath(const std::string& base_dir, const std::string& path) {
  if (path.empty() || path[0] == '/' || base_dir.empty()) return path;
  return base_dir + "/" + path;
}

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

double uniformIn(std::mt19937& rng, double lo, double hi) {
  return lo + (hi - lo) * std::uniform_real_distribution<double>(0.0, 1.0)(rng);
}

void addRandomMarks(int n, std::mt19937& rng, SceneSpec* scene) {
  const Target& t = scene->target;
  for (int i = 0; i < n; ++i) {
    const double w = std::min(uniformIn(rng, kMarkMinW, kMarkMaxW), t.width - 2 * kMarkInset);
    const double h = std::min(uniformIn(rng, kMarkMinH, kMarkMaxH), t.height - 2 * kMarkInset);
    if (w <= 0 || h <= 0) return;  // board too small for marks
    const double x = uniformIn(rng, kMarkInset, t.width - kMarkInset - w);
    const double y = uniformIn(rng, kMarkInset, t.height - kMarkInset - h);
    scene->board_marks.push_back({Eigen::Vector2d(x, y), Eigen::Vector2d(x + w, y + h)});
  }
}

// Contrast with the surroundings (walls 0.4..0.75): dark or bright, a few tinted; LiDAR
// intensity anywhere from dull to as bright as the board.
void randomLook(std::mt19937& rng, const SceneSpec& scene, Panel* panel) {
  const bool dark = uniformIn(rng, 0, 1) < 0.5;
  panel->grey = dark ? uniformIn(rng, 0.05, 0.25) : uniformIn(rng, 0.8, 0.95);
  if (uniformIn(rng, 0, 1) < 0.3)
    panel->tint = Eigen::Vector3d(uniformIn(rng, 0.6, 1.2), uniformIn(rng, 0.6, 1.2), uniformIn(rng, 0.6, 1.2));
  panel->intensity = static_cast<float>(uniformIn(rng, 0.1, 1.0) * std::max(1.0f, scene.board_intensity));
}

// Posters, screens, cabinets and doors on the walls (facades outdoors) and free-standing panels
// away from where the board is held (beyond the farthest pose or outside the motion's cone), so
// they never hide it; the pose sampler checks the lines of sight anyway.
void addRandomPanels(const Scenario& s, int n, std::mt19937& rng, SceneSpec* scene) {
  if (n <= 0 || !(scene->room || scene->outdoor)) return;
  const Target& t = scene->target;
  const double big = std::max(t.width, t.height), small = std::min(t.width, t.height);
  const double half_x = scene->outdoor ? std::min(scene->facade_distance_m, kFacadeClutterReach) : scene->room_half_size_m;
  const double half_y = scene->outdoor ? scene->street_half_width_m : scene->room_half_size_m;
  const double top = scene->outdoor ? scene->floor_z_m + 6.0 : scene->ceiling_z_m;
  const Eigen::Vector3d rig = s.world_T_rig.translation();
  const Eigen::Vector3d rig_x = s.world_T_rig.linear().col(0);
  for (int i = 0; i < n; ++i) {
    Panel panel;
    randomLook(rng, *scene, &panel);
    const bool free_standing = uniformIn(rng, 0, 1) < kFreeStandingFraction;
    const bool door = !free_standing && uniformIn(rng, 0, 1) < kDoorFraction;
    panel.width_m = door ? kDoorWidth : big * uniformIn(rng, kPosterSizeMin, kPosterSizeMax);
    panel.height_m = door ? kDoorHeight : small * uniformIn(rng, kPosterSizeMin, kPosterSizeMax);
    if (!door && uniformIn(rng, 0, 1) < 0.5) std::swap(panel.width_m, panel.height_m);
    if (!free_standing) {
      // Walls: 0 x-, 1 x+, 2 y-, 3 y+ (outdoors only the side facades along the street).
      // Half of them on the wall the rig faces, so the cameras see clutter around the board too.
      int ahead = std::abs(rig_x.x()) >= std::abs(rig_x.y()) ? (rig_x.x() > 0 ? 1 : 0) : (rig_x.y() > 0 ? 3 : 2);
      if (scene->outdoor && ahead < 2) ahead = 2 + static_cast<int>(uniformIn(rng, 0, 2) >= 1);
      const int any = scene->outdoor ? 2 + static_cast<int>(uniformIn(rng, 0, 2) >= 1) : std::min(3, static_cast<int>(uniformIn(rng, 0, 4)));
      const int wall = uniformIn(rng, 0, 1) < 0.5 ? ahead : any;
      const double standoff = door ? -0.05 : uniformIn(rng, kPosterStandoffMin, kPosterStandoffMax);  // doors recessed
      const double along_half = (wall < 2 ? half_y : half_x) - 0.5 * panel.width_m - 0.2;
      if (along_half <= 0) continue;
      const double along = uniformIn(rng, -along_half, along_half);
      const double z_lo = scene->floor_z_m + 0.5 * panel.height_m + (door ? 0.0 : 0.5);
      const double z_hi = std::max(z_lo, top - 0.5 * panel.height_m - 0.1);
      const double z = door ? scene->floor_z_m + 0.5 * panel.height_m + 0.005 : uniformIn(rng, z_lo, z_hi);
      Eigen::Vector3d inward = Eigen::Vector3d::Zero();
      inward[wall / 2] = (wall % 2) ? -1.0 : 1.0;
      Eigen::Vector3d centre = Eigen::Vector3d::Zero();
      centre[wall / 2] = -inward[wall / 2] * (wall < 2 ? half_x : half_y) + inward[wall / 2] * standoff;
      centre[1 - wall / 2] = along;
      centre.z() = z;
      Eigen::Matrix3d R;
      R.col(2) = -inward;  // normal away from the room's inside, like the board's away from the rig
      R.col(1) = -Eigen::Vector3d::UnitZ();
      R.col(0) = R.col(1).cross(R.col(2));
      panel.world_T_panel = makeTransform(R, centre);
    } else {
      bool placed = false;
      for (int attempt = 0; attempt < kClutterAttempts && !placed; ++attempt) {
        const Eigen::Vector3d c(uniformIn(rng, -half_x + 1.0, half_x - 1.0), uniformIn(rng, -half_y + 1.0, half_y - 1.0), 0.0);
        Eigen::Vector3d d = c - rig;
        d.z() = 0;
        const double r = d.norm();
        const double az = std::acos(std::clamp(d.normalized().dot(rig_x), -1.0, 1.0)) / kRadPerDeg;
        const bool in_cone = az < s.motion.max_azimuth_deg + kClutterConeMarginDeg && r < s.motion.max_distance_m + kClutterClearance;
        if (r < kClutterClearance || in_cone) continue;
        const double lift = uniformIn(rng, 0.0, 0.8);
        const double yaw = uniformIn(rng, -kPi, kPi);
        const double roll = uniformIn(rng, 0, 1) < kDiamondFraction ? uniformIn(rng, 30, 60) * kRadPerDeg : 0.0;
        const Eigen::Matrix3d R = fromRollPitchYaw(Eigen::Vector3d(roll, 0.0, yaw)) * facingRig();
        const double half_height = 0.5 * (std::abs(std::cos(roll)) * panel.height_m + std::abs(std::sin(roll)) * panel.width_m);
        panel.world_T_panel = makeTransform(R, Eigen::Vector3d(c.x(), c.y(), scene->floor_z_m + lift + half_height));
        placed = true;
      }
      if (!placed) continue;
    }
    scene->panels.push_back(panel);
  }
}

}  // namespace

std::string MotionSpec::validate() const {
  if (poses < 1) return "poses must be >= 1";
  if (!(min_distance_m > 0) || !(max_distance_m >= min_distance_m)) return "need 0 < min_distance_m <= max_distance_m";
  if (!(max_azimuth_deg >= 0) || max_azimuth_deg > 80) return "max_azimuth_deg must be in [0, 80]";
  if (!(max_elevation_deg >= 0) || max_elevation_deg > 60) return "max_elevation_deg must be in [0, 60]";
  if (!(min_roll_deg >= 0) || !(max_roll_deg >= min_roll_deg) || max_roll_deg > 90)
    return "need 0 <= min_roll_deg <= max_roll_deg <= 90";
  if (!(max_tilt_deg >= 0) || max_tilt_deg > 60) return "max_tilt_deg must be in [0, 60]";
  if (!(min_edge_slope_deg >= 0) || min_edge_slope_deg > 45) return "min_edge_slope_deg must be in [0, 45]";
  if (!(hold_s > 0)) return "hold_s must be > 0";
  if (!(move_s >= 0)) return "move_s must be >= 0";
  if (still_frames_per_hold < 0) return "still_frames_per_hold must be >= 0 (0 = all)";
  if (frames_per_move < -1) return "frames_per_move must be >= -1 (-1 = all)";
  if (!(image_margin_px >= 0)) return "image_margin_px must be >= 0";
  return {};
}

std::string Scenario::validate() const {
  if (cameras.empty() && lidars.empty()) return "the rig has no sensors";
  const std::string scene_reason = scene.validate();
  if (!scene_reason.empty()) return "scene: " + scene_reason;
  const std::string motion_reason = motion.validate();
  if (!motion_reason.empty()) return "motion: " + motion_reason;
  std::set<std::string> names, frames;
  for (const auto& c : cameras) {
    if (!names.insert(c.name).second) return "sensor name '" + c.name + "' used twice";
    if (!frames.insert(c.frame_id).second) return "frame_id '" + c.frame_id + "' used twice";
    if (!(c.rate_hz > 0)) return "camera '" + c.name + "': rate_hz must be > 0";
    const std::string why = c.render.validate();
    if (!why.empty()) return "camera '" + c.name + "': " + why;
  }
  for (const auto& l : lidars) {
    if (!names.insert(l.name).second) return "sensor name '" + l.name + "' used twice";
    if (!frames.insert(l.frame_id).second) return "frame_id '" + l.frame_id + "' used twice";
    const std::string why = l.spec.validate();
    if (!why.empty()) return why;
  }
  return {};
}

Expected<Scenario> parseScenario(const std::string& yaml_text, const std::string& base_dir) {
  try {
    const YAML::Node root = YAML::Load(yaml_text);
    if (!root.IsMap()) return Expected<Scenario>::failure("scenario must be a YAML map");
    rejectUnknownKeys(root, {"name", "seed", "target", "scene", "rig_pose", "cameras", "lidars", "motion"}, "scenario");
    Scenario s;
    readOptional(root, "name", "scenario", "string", &s.name);
    readOptional(root, "seed", "scenario", "non-negative integer", &s.seed);
    s.target_path = readValue<std::string>(root, "target", "scenario", "path");
    const auto target = loadTarget(joinPath(base_dir, s.target_path));
    if (!target) return Expected<Scenario>::failure("scenario.target: " + target.error());
    s.scene.target = *target;
    SceneRandom random;
    readScene(root["scene"], &s.scene, &random);
    if (root["rig_pose"]) {
      YAML::Node wrapper;
      wrapper["pose"] = root["rig_pose"];
      s.world_T_rig = readPose(wrapper, "scenario.rig", false);
    }
    if (root["cameras"]) {
      if (!root["cameras"].IsSequence()) return Expected<Scenario>::failure("'cameras' must be a list");
      for (size_t i = 0; i < root["cameras"].size(); ++i)
        s.cameras.push_back(readCamera(root["cameras"][i], "cameras[" + std::to_string(i) + "]"));
    }
    if (root["lidars"]) {
      if (!root["lidars"].IsSequence()) return Expected<Scenario>::failure("'lidars' must be a list");
      for (size_t i = 0; i < root["lidars"].size(); ++i)
        s.lidars.push_back(readLidar(root["lidars"][i], "lidars[" + std::to_string(i) + "]"));
    }
    s.motion = readMotion(root["motion"]);
    if (random.posters > 0 || random.board_marks > 0) {
      std::seed_seq seq{random.have_seed ? random.seed : s.seed, 0xC1u};
      std::mt19937 rng(seq);
      addRandomMarks(random.board_marks, rng, &s.scene);
      addRandomPanels(s, random.posters, rng, &s.scene);
    }
    const std::string why = s.validate();
    if (!why.empty()) return Expected<Scenario>::failure(why);
    return s;
  } catch (const ScenarioError& e) {
    return Expected<Scenario>::failure(e.message);
  } catch (const YAML::Exception& e) {
    return Expected<Scenario>::failure(std::string("YAML error: ") + e.what());
  }
}

Expected<Scenario> loadScenario(const std::string& path) {
  std::ifstream in(path);
  if (!in) return Expected<Scenario>::failure("cannot read scenario file '" + path + "'");
  std::stringstream text;
  text << in.rdbuf();
  const size_t slash = path.find_last_of('/');
  const std::string base_dir = slash == std::string::npos ? "." : path.substr(0, slash);
  auto s = parseScenario(text.str(), base_dir);
  if (!s) return Expected<Scenario>::failure(path + ": " + s.error());
  return s;
}

Eigen::Isometry3d worldTCamera(const Scenario& scenario, int camera) {
  return scenario.world_T_rig * scenario.cameras[static_cast<size_t>(camera)].rig_T_sensor;
}

Eigen::Isometry3d worldTLidar(const Scenario& scenario, int lidar) {
  return scenario.world_T_rig * scenario.lidars[static_cast<size_t>(lidar)].rig_T_sensor;
}

namespace {

// Whether a board pose suits every sensor (see makeTimeline).
std::string poseProblem(const Scenario& s, const std::vector<CameraModel>& models,
                        const Eigen::Isometry3d& world_T_board) {
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
    for (size_t k = 0; k < s.cameras.size(); ++k) eyes.push_back(worldTCamera(s, static_cast<int>(k)).translation());
    for (size_t k = 0; k < s.lidars.size(); ++k) eyes.push_back(worldTLidar(s, static_cast<int>(k)).translation());
    std::vector<Eigen::Vector3d> marks(world.begin(), world.end());
    marks.push_back(world_T_board * target.center());
    for (const Panel& panel : s.scene.panels) {
      const Eigen::Isometry3d panel_T_world = panel.world_T_panel.inverse();
      auto crosses = [&](const Eigen::Vector3d& a, const Eigen::Vector3d& b) {  // segment a-b through the panel
        const Eigen::Vector3d pa = panel_T_world * a, pb = panel_T_world * b;
        if ((pa.z() > 0) == (pb.z() > 0)) return false;
        const Eigen::Vector3d q = pa + (pb - pa) * (pa.z() / (pa.z() - pb.z()));
        return std::abs(q.x()) <= 0.5 * panel.width_m && std::abs(q.y()) <= 0.5 * panel.height_m;
      };
      for (int e = 0; e < 4; ++e)
        if (crosses(world[e], world[(e + 1) % 4]) || crosses(world[e], world[(e + 2) % 4])) return "board cuts a panel";
      for (const auto& eye : eyes)
        for (const auto& m : marks)
          if (crosses(eye, m)) return "panel hides the board";
    }
  }
  for (size_t k = 0; k < s.cameras.size(); ++k) {
    const Eigen::Isometry3d board_T_camera = world_T_board.inverse() * worldTCamera(s, static_cast<int>(k));
    if (!(board_T_camera.translation().z() < 0)) return "camera sees the back";
    const Eigen::Isometry3d camera_T_world = worldTCamera(s, static_cast<int>(k)).inverse();
    for (const auto& p : world)
      if (!models[k].isVisible(camera_T_world * p, -s.motion.image_margin_px)) return "corner outside an image";
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
      if (q.norm() < spec.min_range_m || q.norm() > spec.max_range_m) return "board out of LiDAR range";
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
  const MotionSpec& m = s.motion;
  const Target& target = s.scene.target;
  std::mt19937 rng(s.seed);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  auto uniform = [&](double lo, double hi) { return lo + (hi - lo) * unit(rng); };

  Timeline timeline;
  for (int i = 0; i < m.poses; ++i) {
    std::map<std::string, int> rejections;
    bool placed = false;
    for (int attempt = 0; attempt < kMaxPoseAttempts && !placed; ++attempt) {
      const double d = uniform(m.min_distance_m, m.max_distance_m);
      const double az = uniform(-m.max_azimuth_deg, m.max_azimuth_deg) * kRadPerDeg;
      const double el = uniform(-m.max_elevation_deg, m.max_elevation_deg) * kRadPerDeg;
      const Eigen::Vector3d centre = d * Eigen::Vector3d(std::cos(el) * std::cos(az), std::cos(el) * std::sin(az),
                                                         std::sin(el));
      // Facing the rig origin: z away from the rig, y down, x right as seen from the rig.
      const Eigen::Vector3d z = centre.normalized();
      const Eigen::Vector3d y = -(Eigen::Vector3d::UnitZ() - Eigen::Vector3d::UnitZ().dot(z) * z).normalized();
      Eigen::Matrix3d facing;
      facing.col(0) = y.cross(z);
      facing.col(1) = y;
      facing.col(2) = z;
      const double roll = (unit(rng) < 0.5 ? -1 : 1) * uniform(m.min_roll_deg, m.max_roll_deg) * kRadPerDeg;
      const double tilt_x = uniform(-m.max_tilt_deg, m.max_tilt_deg) * kRadPerDeg;
      const double tilt_y = uniform(-m.max_tilt_deg, m.max_tilt_deg) * kRadPerDeg;
      const Eigen::Matrix3d R = facing * Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitZ()).toRotationMatrix() *
                                Eigen::AngleAxisd(tilt_x, Eigen::Vector3d::UnitX()).toRotationMatrix() *
                                Eigen::AngleAxisd(tilt_y, Eigen::Vector3d::UnitY()).toRotationMatrix();
      const Eigen::Isometry3d rig_T_board = makeTransform(R, centre - R * target.center());
      const Eigen::Isometry3d world_T_board = s.world_T_rig * rig_T_board;
      const std::string problem = poseProblem(s, models, world_T_board);
      if (problem.empty()) {
        timeline.world_T_board_poses.push_back(world_T_board);
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
      return Expected<Timeline>::failure("cannot place board pose " + std::to_string(i) + " after " +
                                         std::to_string(kMaxPoseAttempts) + " tries (mostly: " + most +
                                         "); check that the sensors' fields of view overlap at the motion's distances");
    }
  }

  const double period = m.hold_s + m.move_s;
  timeline.duration_s = m.poses * m.hold_s + (m.poses - 1) * m.move_s;
  auto boardAt = [&](double t, int* pose, double* hold_end) {
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
  };

  auto addSensor = [&](bool is_camera, int index, double rate, double offset) {
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
      f.world_T_board = boardAt(t, &f.pose, &hold_end);
      f.still = f.pose >= 0 && (t + exposure <= hold_end + 1e-9 || f.pose == m.poses - 1);
      if (!f.still) f.pose = -1;
      frames.push_back(f);
    }
    // Thin: the last N still frames of each hold, N evenly spread frames of each move.
    std::vector<Frame> kept;
    size_t i = 0;
    while (i < frames.size()) {
      size_t j = i;
      const bool still = frames[i].still;
      const int pose = frames[i].pose;
      while (j < frames.size() && frames[j].still == still && frames[j].pose == pose) ++j;
      const size_t n = j - i;
      if (still) {
        const size_t keep = m.still_frames_per_hold > 0 ? std::min(n, static_cast<size_t>(m.still_frames_per_hold)) : n;
        for (size_t q = j - keep; q < j; ++q) kept.push_back(frames[q]);
      } else if (m.frames_per_move < 0 || static_cast<size_t>(m.frames_per_move) >= n) {
        for (size_t q = i; q < j; ++q) kept.push_back(frames[q]);
      } else {
        for (int q = 0; q < m.frames_per_move; ++q)
          kept.push_back(frames[i + static_cast<size_t>((q + 0.5) * n / m.frames_per_move)]);
      }
      i = j;
    }
    timeline.frames.insert(timeline.frames.end(), kept.begin(), kept.end());
  };
  for (size_t k = 0; k < s.cameras.size(); ++k)
    addSensor(true, static_cast<int>(k), s.cameras[k].rate_hz, s.cameras[k].stamp_offset_s);
  for (size_t k = 0; k < s.lidars.size(); ++k)
    addSensor(false, static_cast<int>(k), s.lidars[k].spec.rate_hz, s.lidars[k].stamp_offset_s);
  std::stable_sort(timeline.frames.begin(), timeline.frames.end(),
                   [](const Frame& a, const Frame& b) { return a.stamp < b.stamp; });
  return timeline;
}

ResultFile groundTruth(const Scenario& s) {
  ResultFile r;
  r.method = "ground_truth";
  r.views_used = s.motion.poses;
  r.notes.push_back("simulated ground truth of scenario '" + s.name + "' (seed " + std::to_string(s.seed) + ")");
  if (!s.cameras.empty() && !s.lidars.empty()) {
    r.camera_frame = s.cameras[0].frame_id;
    r.lidar_frame = s.lidars[0].frame_id;
    r.camera_T_lidar = worldTCamera(s, 0).inverse() * worldTLidar(s, 0);
  }
  // Reference: the first LiDAR (a frame that exists in TF), else the first camera.
  const Eigen::Isometry3d world_T_reference = s.lidars.empty() ? worldTCamera(s, 0) : worldTLidar(s, 0);
  r.reference_frame = s.lidars.empty() ? s.cameras[0].frame_id : s.lidars[0].frame_id;
  for (size_t k = 0; k < s.lidars.size(); ++k)
    r.sensors.push_back({s.lidars[k].frame_id, "lidar", world_T_reference.inverse() * worldTLidar(s, static_cast<int>(k))});
  for (size_t k = 0; k < s.cameras.size(); ++k)
    r.sensors.push_back(
        {s.cameras[k].frame_id, "camera", world_T_reference.inverse() * worldTCamera(s, static_cast<int>(k))});
  for (size_t c = 0; c < s.cameras.size(); ++c) {
    for (size_t l = 0; l < s.lidars.size(); ++l) {
      PairEntry pair;
      pair.camera_frame = s.cameras[c].frame_id;
      pair.lidar_frame = s.lidars[l].frame_id;
      pair.camera_T_lidar = worldTCamera(s, static_cast<int>(c)).inverse() * worldTLidar(s, static_cast<int>(l));
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
  std::seed_seq seq{seed, static_cast<unsigned int>(frame_index), static_cast<unsigned int>(frame_index >> 32)};
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
    radiance = renderCameraRadiance(models_[k], worldTCamera(*scenario_, frame.sensor), scenario_->scene,
                                    frame.world_T_board, camera.render);
    cached.pose = frame.still ? frame.pose : -2;
    cached.radiance = frame.still ? radiance : cv::Mat();
  }
  std::mt19937 rng = frameRng(scenario_->seed, frame_index);
  return finishCameraImage(radiance, models_[k], camera.render, rng);
}

LidarCloud FrameGenerator::cloud(const Frame& frame, size_t frame_index, std::vector<ReturnOrigin>* origins) {
  const LidarSensor& lidar = scenario_->lidars[static_cast<size_t>(frame.sensor)];
  std::mt19937 rng = frameRng(scenario_->seed, frame_index);
  LidarCloud cloud = simulateLidarScan(lidar.spec, worldTLidar(*scenario_, frame.sensor), scenario_->scene,
                                       frame.world_T_board, rng, origins);
  cloud.frame_id = lidar.frame_id;
  cloud.stamp = frame.stamp;
  return cloud;
}

}  // namespace sim
}  // namespace board_calib
