// SPDX-License-Identifier: BSD-3-Clause
// Scenario files: strict YAML reading (errors name the key), validation, seeded clutter.
#include <board_calib/core/common/format.h>
#include <board_calib/core/sim/scenario.h>

#include <board_calib/core/transform.h>
#include "scenario_internal.h"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <random>
#include <set>
#include <sstream>
#include <type_traits>

namespace board_calib {
namespace sim {
namespace {

// ---------------------------------------------------------------------------------------------
// YAML helpers: strict keys, errors that name the key.
// ---------------------------------------------------------------------------------------------
struct ScenarioError {
  std::string message;
};

void rejectUnknownKeys(const YAML::Node& node, const std::set<std::string>& allowed,
                       const std::string& where) {
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
T readValue(const YAML::Node& node, const std::string& key, const std::string& where,
            const char* type_name) {
  const YAML::Node value = node[key];
  if (!value) throw ScenarioError{"missing key '" + where + "." + key + "'"};
  if (!value.IsScalar())
    throw ScenarioError{"key '" + where + "." + key + "' must be a " + type_name};
  T out;
  try {
    out = value.as<T>();
  } catch (const YAML::Exception&) {
    throw ScenarioError{"key '" + where + "." + key + "' must be a " + type_name + ", got '" +
                        value.Scalar() + "'"};
  }
  if constexpr (std::is_floating_point_v<T>)
    if (!std::isfinite(out))
      throw ScenarioError{"key '" + where + "." + key + "' must be a finite number, got '" +
                          value.Scalar() + "'"};
  return out;
}

template <typename T>
void readOptional(const YAML::Node& node, const std::string& key, const std::string& where,
                  const char* type_name, T* out) {
  if (node[key]) *out = readValue<T>(node, key, where, type_name);
}

std::vector<double> readNumbers(const YAML::Node& node, const std::string& key,
                                const std::string& where) {
  const YAML::Node value = node[key];
  if (!value || !value.IsSequence())
    throw ScenarioError{"key '" + where + "." + key + "' must be a list of numbers"};
  std::vector<double> out;
  for (size_t i = 0; i < value.size(); ++i) {
    try {
      out.push_back(value[i].as<double>());
    } catch (const YAML::Exception&) {
      throw ScenarioError{"key '" + where + "." + key + "' must be a list of numbers"};
    }
    if (!std::isfinite(out.back()))
      throw ScenarioError{"key '" + where + "." + key + "' must be a list of finite numbers"};
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
  if (!node)
    return camera ? makeTransform(bodyROptical(), Eigen::Vector3d::Zero())
                  : Eigen::Isometry3d::Identity();
  const std::string at = where + ".pose";
  rejectUnknownKeys(node, {"translation", "rpy_deg", "rotation_xyzw"}, at);
  Eigen::Vector3d t = Eigen::Vector3d::Zero();
  if (node["translation"]) {
    const auto v = readNumbers(node, "translation", at);
    if (v.size() != 3)
      throw ScenarioError{"key '" + at + ".translation' must be [x, y, z] in metres"};
    t = Eigen::Vector3d(v[0], v[1], v[2]);
  }
  if (node["rpy_deg"] && node["rotation_xyzw"])
    throw ScenarioError{"'" + at + "': give either rpy_deg or rotation_xyzw, not both"};
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
  if (node["rotation_xyzw"]) {
    const auto q = readNumbers(node, "rotation_xyzw", at);
    if (q.size() != 4 || Eigen::Vector4d(q[0], q[1], q[2], q[3]).norm() < 1e-9)
      throw ScenarioError{"key '" + at +
                          ".rotation_xyzw' must be a non-zero quaternion [qx, qy, qz, qw]"};
    return makeTransform(t, Eigen::Vector4d(q[0], q[1], q[2], q[3]));
  }
  if (node["rpy_deg"]) {
    const auto rpy = readNumbers(node, "rpy_deg", at);
    if (rpy.size() != 3)
      throw ScenarioError{"key '" + at + ".rpy_deg' must be [roll, pitch, yaw] in degrees"};
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
  rejectUnknownKeys(node, {"supersampling", "noise_sigma", "vignetting", "blur_sigma_px", "mono"},
                    at);
  readOptional(node, "supersampling", at, "integer", &r.supersampling);
  readOptional(node, "noise_sigma", at, "number", &r.noise_sigma);
  readOptional(node, "vignetting", at, "number", &r.vignetting);
  readOptional(node, "blur_sigma_px", at, "number", &r.blur_sigma_px);
  readOptional(node, "mono", at, "bool", &r.mono);
  const std::string why = r.validate();
  if (!why.empty()) throw ScenarioError{"'" + at + "': " + why};
  return r;
}

// The simulator renders by inverting the lens model at every pixel: a distortion that folds back
// before the image's border (a radial polynomial peaking inside it) has no inverse there, and the
// image would be a meaningless fan of rays. Checked on the border, where the fold shows first.
std::string lensFoldsInsideTheImage(const CameraModel& model, int width, int height) {
  const double w = width - 1.0, h = height - 1.0;
  for (const Eigen::Vector2d raw :
       {Eigen::Vector2d(0, 0), Eigen::Vector2d(w, 0), Eigen::Vector2d(0, h), Eigen::Vector2d(w, h),
        Eigen::Vector2d(w / 2, 0), Eigen::Vector2d(w / 2, h), Eigen::Vector2d(0, h / 2),
        Eigen::Vector2d(w, h / 2)}) {
    const Eigen::Vector2d back = model.distortPixel(model.undistortPixel(raw));
    if (!back.allFinite() || (back - raw).norm() > 0.5)
      return "its distortion has no inverse at image pixel (" + formatFixed(raw.x(), 0) + ", " +
             formatFixed(raw.y(), 0) +
             ") (the lens model folds back inside the image): check fx, fy and D together";
  }
  return {};
}

CameraSensor readCamera(const YAML::Node& node, const std::string& where) {
  rejectUnknownKeys(node,
                    {"name", "frame_id", "width", "height", "fx", "fy", "cx", "cy",
                     "distortion_model", "D", "rate_hz", "stamp_offset_s", "pose", "render"},
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
  if (const std::string folds = lensFoldsInsideTheImage(*check, in.width, in.height);
      !folds.empty())
    throw ScenarioError{"'" + where + "': " + folds};
  readOptional(node, "rate_hz", where, "number", &c.rate_hz);
  readOptional(node, "stamp_offset_s", where, "number", &c.stamp_offset_s);
  c.rig_T_sensor = readPose(node, where, true);
  c.render = readRender(node, where);
  return c;
}

LidarSensor readLidar(const YAML::Node& node, const std::string& where) {
  rejectUnknownKeys(
      node,
      {"name", "frame_id", "preset", "rate_hz", "stamp_offset_s", "pose", "range_noise_m",
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
    if (!node["elevations_deg"])
      throw ScenarioError{"'" + where + "' needs a preset or elevations_deg"};
  }
  auto& s = l.spec;
  if (node["elevations_deg"]) s.elevations_deg = readNumbers(node, "elevations_deg", where);
  if (node["azimuth_offsets_deg"])
    s.azimuth_offsets_deg = readNumbers(node, "azimuth_offsets_deg", where);
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
  rejectUnknownKeys(
      node,
      {"poses", "min_distance_m", "max_distance_m", "max_azimuth_deg", "max_elevation_deg",
       "min_roll_deg", "max_roll_deg", "max_tilt_deg", "min_edge_slope_deg", "min_board_height_m",
       "hold_s", "move_s", "still_frames_per_hold", "frames_per_move", "image_margin_px"},
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

Eigen::Vector3d readColour(const YAML::Node& node, const std::string& key,
                           const std::string& where) {
  const auto v = readNumbers(node, key, where);
  if (v.size() != 3)
    throw ScenarioError{"key '" + where + "." + key + "' must be [r, g, b] factors"};
  return {v[2], v[1], v[0]};  // stored b, g, r as the renderer's colours
}

Panel readPanel(const YAML::Node& node, const std::string& where) {
  rejectUnknownKeys(node, {"center", "rpy_deg", "width", "height", "grey", "tint", "intensity"},
                    where);
  Panel panel;
  const auto c = readNumbers(node, "center", where);
  if (c.size() != 3) throw ScenarioError{"key '" + where + ".center' must be [x, y, z] in metres"};
  Eigen::Vector3d rpy = Eigen::Vector3d::Zero();
  if (node["rpy_deg"]) {
    const auto v = readNumbers(node, "rpy_deg", where);
    if (v.size() != 3)
      throw ScenarioError{"key '" + where + ".rpy_deg' must be [roll, pitch, yaw] in degrees"};
    rpy = Eigen::Vector3d(v[0], v[1], v[2]);
  }
  panel.world_T_panel = makeTransform(fromRollPitchYaw(rpy * kRadPerDeg) * internal::facingRig(),
                                      Eigen::Vector3d(c[0], c[1], c[2]));
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
  rejectUnknownKeys(node,
                    {"room", "room_half_size_m", "floor_z_m", "ceiling_z_m", "occluder",
                     "board_intensity", "background_intensity", "outdoor", "street_half_width_m",
                     "facade_distance_m", "ground_grey", "board_grey", "board_tint",
                     "board_texture", "board_marks", "posters", "panels", "clutter_seed"},
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
      random->board_marks =
          readValue<int>(node, "board_marks", at, "integer or a list of {min, max}");
      if (random->board_marks < 0) throw ScenarioError{"key 'scene.board_marks' must be >= 0"};
    } else if (marks.IsSequence()) {
      for (size_t i = 0; i < marks.size(); ++i) {
        const std::string where = at + ".board_marks[" + std::to_string(i) + "]";
        rejectUnknownKeys(marks[i], {"min", "max"}, where);
        const auto lo = readNumbers(marks[i], "min", where),
                   hi = readNumbers(marks[i], "max", where);
        if (lo.size() != 2 || hi.size() != 2)
          throw ScenarioError{"'" + where + "': min and max must be [x, y] in metres"};
        scene->board_marks.push_back(
            {Eigen::Vector2d(lo[0], lo[1]), Eigen::Vector2d(hi[0], hi[1])});
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
      scene->panels.push_back(
          readPanel(node["panels"][i], at + ".panels[" + std::to_string(i) + "]"));
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

}  // namespace

constexpr int kMaxPoses = 10000;
constexpr double kMaxPhaseS = 3600.0;
constexpr double kMaxRateHz = 1000.0;
constexpr double kMaxImagePixels = 250e6;

std::string MotionSpec::validate() const {
  if (poses < 1) return "poses must be >= 1";
  if (!(min_distance_m > 0) || !(max_distance_m >= min_distance_m))
    return "need 0 < min_distance_m <= max_distance_m";
  if (!(max_azimuth_deg >= 0) || max_azimuth_deg > 80) return "max_azimuth_deg must be in [0, 80]";
  if (!(max_elevation_deg >= 0) || max_elevation_deg > 60)
    return "max_elevation_deg must be in [0, 60]";
  if (!(min_roll_deg >= 0) || !(max_roll_deg >= min_roll_deg) || max_roll_deg > 90)
    return "need 0 <= min_roll_deg <= max_roll_deg <= 90";
  if (!(max_tilt_deg >= 0) || max_tilt_deg > 60) return "max_tilt_deg must be in [0, 60]";
  if (!(min_edge_slope_deg >= 0) || min_edge_slope_deg > 45)
    return "min_edge_slope_deg must be in [0, 45]";
  // Bounds on what a session is: beyond them the recording would not fit in memory or on disk.
  if (poses > kMaxPoses) return "poses must be <= " + std::to_string(kMaxPoses);
  if (!(hold_s > 0) || hold_s > kMaxPhaseS) return "hold_s must be in (0, 3600] s";
  if (!(move_s >= 0) || move_s > kMaxPhaseS) return "move_s must be in [0, 3600] s";
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
    if (!(c.rate_hz > 0) || c.rate_hz > kMaxRateHz)
      return "camera '" + c.name + "': rate_hz must be in (0, 1000]";
    if (static_cast<double>(c.intrinsics.width) * c.intrinsics.height > kMaxImagePixels)
      return "camera '" + c.name + "': " + std::to_string(c.intrinsics.width) + " x " +
             std::to_string(c.intrinsics.height) + " px is beyond 250 megapixels";
    const std::string why = c.render.validate();
    if (!why.empty()) return "camera '" + c.name + "': " + why;
  }
  for (const auto& l : lidars) {
    if (!names.insert(l.name).second) return "sensor name '" + l.name + "' used twice";
    if (!frames.insert(l.frame_id).second) return "frame_id '" + l.frame_id + "' used twice";
    const std::string why = l.spec.validate();
    if (!why.empty()) return why;
    if (l.spec.rate_hz > kMaxRateHz) return "LiDAR '" + l.name + "': rate_hz must be <= 1000";
  }
  return {};
}

Expected<Scenario> parseScenario(const std::string& yaml_text, const std::string& base_dir) {
  try {
    const YAML::Node root = YAML::Load(yaml_text);
    if (!root.IsMap()) return Expected<Scenario>::failure("scenario must be a YAML map");
    rejectUnknownKeys(
        root, {"name", "seed", "target", "scene", "rig_pose", "cameras", "lidars", "motion"},
        "scenario");
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
      if (!root["cameras"].IsSequence())
        return Expected<Scenario>::failure("'cameras' must be a list");
      for (size_t i = 0; i < root["cameras"].size(); ++i)
        s.cameras.push_back(readCamera(root["cameras"][i], "cameras[" + std::to_string(i) + "]"));
    }
    if (root["lidars"]) {
      if (!root["lidars"].IsSequence())
        return Expected<Scenario>::failure("'lidars' must be a list");
      for (size_t i = 0; i < root["lidars"].size(); ++i)
        s.lidars.push_back(readLidar(root["lidars"][i], "lidars[" + std::to_string(i) + "]"));
    }
    s.motion = readMotion(root["motion"]);
    if (random.posters > 0 || random.board_marks > 0) {
      std::seed_seq seq{random.have_seed ? random.seed : s.seed, 0xC1u};
      std::mt19937 rng(seq);
      internal::addRandomMarks(random.board_marks, rng, &s.scene);
      internal::addRandomPanels(s, random.posters, rng, &s.scene);
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

}  // namespace sim
}  // namespace board_calib
