#include <board_calib/core/common/format.h>
#include <board_calib/core/file_io.h>
#include <board_calib/core/rig/rig_config.h>

#include <yaml-cpp/yaml.h>

#include <cmath>
#include <fstream>
#include <set>
#include <sstream>

namespace board_calib {
namespace {

// Thrown inside the parser only; turned into an Expected failure at the API boundary.
struct RigError {
  std::string why;
};

[[noreturn]] void bad(const std::string& why) { throw RigError{why}; }

std::string requireString(const YAML::Node& node, const std::string& key,
                          const std::string& where) {
  const YAML::Node v = node[key];
  if (!v) bad(where + ": missing key '" + key + "'");
  if (!v.IsScalar()) bad(where + "." + key + ": expected a string");
  const std::string s = v.as<std::string>();
  if (s.empty()) bad(where + "." + key + ": must not be empty");
  return s;
}

double optionalNumber(const YAML::Node& node, const std::string& key, const std::string& where,
                      double fallback) {
  const YAML::Node v = node[key];
  if (!v) return fallback;
  double x = 0.0;
  if (!v.IsScalar() || !YAML::convert<double>::decode(v, x) || !std::isfinite(x))
    bad(where + "." + key + ": expected a number");
  return x;
}

std::vector<double> numberList(const YAML::Node& node, const std::string& key,
                               const std::string& where, size_t n) {
  const YAML::Node v = node[key];
  if (!v) bad(where + ": missing key '" + key + "'");
  if (!v.IsSequence() || v.size() != n)
    bad(where + "." + key + ": expected a list of " + std::to_string(n) + " numbers");
  std::vector<double> out;
  for (const auto& e : v) {
    double x = 0.0;
    if (!e.IsScalar() || !YAML::convert<double>::decode(e, x) || !std::isfinite(x))
      bad(where + "." + key + ": expected a list of " + std::to_string(n) + " numbers");
    out.push_back(x);
  }
  return out;
}

void checkKeys(const YAML::Node& node, const std::set<std::string>& allowed,
               const std::string& where) {
  for (const auto& kv : node) {
    const std::string k = kv.first.as<std::string>();
    if (!allowed.count(k)) bad(where + ": unknown key '" + k + "'");
  }
}

// Noise sigmas must be >= 0 (0 = graph default); negative values are a typo, not a default.
// Beyond `max` a sigma says the sensor measures nothing (the graph would quietly ignore it).
double noiseValue(const YAML::Node& noise, const std::string& key, const std::string& where,
                  double max, const char* unit) {
  const double x = optionalNumber(noise, key, where, 0.0);
  if (x < 0.0) bad(where + "." + key + ": must be >= 0");
  if (x > max)
    bad(where + "." + key + ": must be <= " + formatFixed(max, 0) + " " + unit +
        " (a sigma this large says the sensor measures nothing)");
  return x;
}

constexpr double kMaxPixelSigmaPx = 100.0;
constexpr double kMaxNormalSigmaDeg = 45.0;
constexpr double kMaxLengthSigmaM = 1.0;
constexpr double kMaxKnownTranslationM = 100.0;  // between two sensors of one rig

// A sensor's optional `noise` map, checked against its keys (a null node when absent).
YAML::Node noiseNode(const YAML::Node& sensor, const std::set<std::string>& keys,
                     const std::string& where) {
  const YAML::Node n = sensor["noise"];
  if (!n) return n;
  if (!n.IsMap()) bad(where + ".noise: expected a map");
  checkKeys(n, keys, where + ".noise");
  return n;
}

RigCamera parseCamera(const YAML::Node& c, const std::string& where) {
  RigCamera cam;
  cam.name = requireString(c, "name", where);
  cam.image_topic = requireString(c, "image_topic", where);
  cam.camera_info_topic = requireString(c, "camera_info_topic", where);
  cam.features_topic =
      c["features_topic"] ? requireString(c, "features_topic", where) : cam.name + "/camera_board";
  if (const YAML::Node n =
          noiseNode(c, {"pixel_sigma_px", "normal_sigma_deg", "offset_sigma_m"}, where)) {
    const std::string nw = where + ".noise";
    cam.pixel_sigma_px = noiseValue(n, "pixel_sigma_px", nw, kMaxPixelSigmaPx, "px");
    cam.normal_sigma_deg = noiseValue(n, "normal_sigma_deg", nw, kMaxNormalSigmaDeg, "deg");
    cam.offset_sigma_m = noiseValue(n, "offset_sigma_m", nw, kMaxLengthSigmaM, "m");
  }
  return cam;
}

RigLidar parseLidar(const YAML::Node& l, const std::string& where) {
  RigLidar lid;
  lid.name = requireString(l, "name", where);
  lid.cloud_topic = requireString(l, "cloud_topic", where);
  lid.features_topic =
      l["features_topic"] ? requireString(l, "features_topic", where) : lid.name + "/lidar_board";
  if (const YAML::Node n =
          noiseNode(l, {"normal_sigma_deg", "offset_sigma_m", "edge_sigma_m"}, where)) {
    const std::string nw = where + ".noise";
    lid.normal_sigma_deg = noiseValue(n, "normal_sigma_deg", nw, kMaxNormalSigmaDeg, "deg");
    lid.offset_sigma_m = noiseValue(n, "offset_sigma_m", nw, kMaxLengthSigmaM, "m");
    lid.edge_sigma_m = noiseValue(n, "edge_sigma_m", nw, kMaxLengthSigmaM, "m");
  }
  return lid;
}

KnownExtrinsic parseKnownExtrinsic(const YAML::Node& k, const std::string& where) {
  KnownExtrinsic e;
  e.a = requireString(k, "a", where);
  e.b = requireString(k, "b", where);
  const YAML::Node t = k["a_T_b"];
  if (!t || !t.IsMap())
    bad(where + ": missing key 'a_T_b' (a map with translation and rotation_xyzw)");
  checkKeys(t, {"translation", "rotation_xyzw"}, where + ".a_T_b");
  const auto tr = numberList(t, "translation", where + ".a_T_b", 3);
  const auto q = numberList(t, "rotation_xyzw", where + ".a_T_b", 4);
  Eigen::Quaterniond quat(q[3], q[0], q[1], q[2]);
  if (std::abs(quat.norm() - 1.0) > 1e-3)
    bad(where + ".a_T_b.rotation_xyzw: not a unit quaternion (norm " + std::to_string(quat.norm()) +
        ")");
  quat.normalize();
  e.a_T_b.linear() = quat.toRotationMatrix();
  e.a_T_b.translation() = Eigen::Vector3d(tr[0], tr[1], tr[2]);
  if (e.a_T_b.translation().norm() > kMaxKnownTranslationM)
    bad(where + ".a_T_b.translation: " + formatFixed(e.a_T_b.translation().norm(), 1) +
        " m between two sensors of one rig (more than " + formatFixed(kMaxKnownTranslationM, 0) +
        " m: a unit or sign error?)");
  return e;
}

RigConfig parse(const YAML::Node& root, const std::string& base_dir) {
  if (!root.IsMap()) bad("rig file: expected a map at the top level");
  checkKeys(root,
            {"target", "reference", "cameras", "lidars", "known_extrinsics", "stamp_tolerance_s"},
            "rig");
  RigConfig rig;
  rig.target_path = requireString(root, "target", "rig");
  if (!base_dir.empty() && rig.target_path[0] != '/')
    rig.target_path = base_dir + "/" + rig.target_path;
  rig.reference = requireString(root, "reference", "rig");
  rig.stamp_tolerance_s = optionalNumber(root, "stamp_tolerance_s", "rig", rig.stamp_tolerance_s);

  if (const YAML::Node cams = root["cameras"]) {
    if (!cams.IsSequence()) bad("rig.cameras: expected a list");
    for (size_t i = 0; i < cams.size(); ++i) {
      const std::string where = "cameras[" + std::to_string(i) + "]";
      const YAML::Node c = cams[i];
      if (!c.IsMap()) bad(where + ": expected a map");
      checkKeys(c, {"name", "image_topic", "camera_info_topic", "features_topic", "noise"}, where);
      rig.cameras.push_back(parseCamera(c, where));
    }
  }
  if (const YAML::Node lids = root["lidars"]) {
    if (!lids.IsSequence()) bad("rig.lidars: expected a list");
    for (size_t i = 0; i < lids.size(); ++i) {
      const std::string where = "lidars[" + std::to_string(i) + "]";
      const YAML::Node l = lids[i];
      if (!l.IsMap()) bad(where + ": expected a map");
      checkKeys(l, {"name", "cloud_topic", "features_topic", "noise"}, where);
      rig.lidars.push_back(parseLidar(l, where));
    }
  }
  if (const YAML::Node known = root["known_extrinsics"]) {
    if (!known.IsSequence()) bad("rig.known_extrinsics: expected a list");
    for (size_t i = 0; i < known.size(); ++i) {
      const std::string where = "known_extrinsics[" + std::to_string(i) + "]";
      const YAML::Node k = known[i];
      if (!k.IsMap()) bad(where + ": expected a map");
      checkKeys(k, {"a", "b", "a_T_b"}, where);
      rig.known_extrinsics.push_back(parseKnownExtrinsic(k, where));
    }
  }
  if (const std::string why = rig.validate(); !why.empty()) bad(why);
  return rig;
}

}  // namespace

std::string RigConfig::validate() const {
  if (target_path.empty()) return "rig: 'target' is empty";
  if (cameras.size() + lidars.size() < 2)
    return "rig: needs at least two sensors in 'cameras' and 'lidars'";
  // Frames further apart than a second belong to different holds of the board.
  if (!(stamp_tolerance_s > 0.0) || stamp_tolerance_s > 1.0)
    return "rig.stamp_tolerance_s: must be in (0, 1] s";
  std::set<std::string> names, topics;
  auto addName = [&](const std::string& n) { return names.insert(n).second; };
  auto addTopic = [&](const std::string& t) { return topics.insert(t).second; };
  for (const auto& c : cameras) {
    if (!addName(c.name)) return "rig: duplicate sensor name '" + c.name + "'";
    if (!addTopic(c.image_topic)) return "rig: topic '" + c.image_topic + "' used twice";
    if (!addTopic(c.camera_info_topic))
      return "rig: topic '" + c.camera_info_topic + "' used twice";
    if (!addTopic(c.features_topic)) return "rig: topic '" + c.features_topic + "' used twice";
  }
  for (const auto& l : lidars) {
    if (!addName(l.name)) return "rig: duplicate sensor name '" + l.name + "'";
    if (!addTopic(l.cloud_topic)) return "rig: topic '" + l.cloud_topic + "' used twice";
    if (!addTopic(l.features_topic)) return "rig: topic '" + l.features_topic + "' used twice";
  }
  if (!names.count(reference))
    return "rig.reference: '" + reference + "' is not a sensor of the rig";
  for (size_t i = 0; i < known_extrinsics.size(); ++i) {
    const auto& k = known_extrinsics[i];
    const std::string where = "known_extrinsics[" + std::to_string(i) + "]";
    if (!names.count(k.a)) return where + ".a: '" + k.a + "' is not a sensor of the rig";
    if (!names.count(k.b)) return where + ".b: '" + k.b + "' is not a sensor of the rig";
    if (k.a == k.b) return where + ": a and b are the same sensor";
  }
  return "";
}

std::vector<std::string> RigConfig::sensorNames() const {
  std::vector<std::string> names;
  for (const auto& c : cameras) names.push_back(c.name);
  for (const auto& l : lidars) names.push_back(l.name);
  return names;
}

int RigConfig::sensorIndex(const std::string& name) const {
  for (size_t i = 0; i < cameras.size(); ++i)
    if (cameras[i].name == name) return static_cast<int>(i);
  for (size_t i = 0; i < lidars.size(); ++i)
    if (lidars[i].name == name) return static_cast<int>(cameras.size() + i);
  return -1;
}

std::vector<multi_sensor::SensorSpec> RigConfig::sensorSpecs() const {
  std::vector<multi_sensor::SensorSpec> out;
  for (const auto& c : cameras) {
    multi_sensor::SensorSpec s;
    s.frame = c.name;
    s.kind = multi_sensor::SensorKind::kCamera;
    s.pixel_sigma_px = c.pixel_sigma_px;
    s.normal_sigma_deg = c.normal_sigma_deg;
    s.offset_sigma_m = c.offset_sigma_m;
    out.push_back(s);
  }
  for (const auto& l : lidars) {
    multi_sensor::SensorSpec s;
    s.frame = l.name;
    s.kind = multi_sensor::SensorKind::kLidar;
    s.normal_sigma_deg = l.normal_sigma_deg;
    s.offset_sigma_m = l.offset_sigma_m;
    s.edge_sigma_m = l.edge_sigma_m;
    out.push_back(s);
  }
  return out;
}

Expected<RigConfig> parseRigConfig(const std::string& yaml_text, const std::string& base_dir) {
  try {
    return parse(YAML::Load(yaml_text), base_dir);
  } catch (const RigError& e) {
    return Expected<RigConfig>::failure(e.why);
  } catch (const YAML::Exception& e) {
    return Expected<RigConfig>::failure(std::string("rig file: invalid YAML: ") + e.what());
  } catch (const std::exception& e) {
    return Expected<RigConfig>::failure(std::string("rig file: cannot parse: ") + e.what());
  }
}

Expected<RigConfig> loadRigConfig(const std::string& path) {
  const auto text = readTextFile(path, "rig file");
  if (!text) return Expected<RigConfig>::failure(text.error());
  const size_t slash = path.find_last_of('/');
  const std::string base =
      slash == std::string::npos ? "." : path.substr(0, slash == 0 ? 1 : slash);
  auto rig = parseRigConfig(*text, base);
  if (!rig) return Expected<RigConfig>::failure(path + ": " + rig.error());
  return rig;
}

}  // namespace board_calib
