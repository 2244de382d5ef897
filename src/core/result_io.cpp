#include <board_calib/core/file_io.h>
#include <board_calib/core/result_io.h>
#include <board_calib/core/transform.h>

#include <yaml-cpp/yaml.h>

#include <cmath>
#include <sstream>

namespace board_calib {
namespace {

void emitSeq(YAML::Emitter& out, const double* v, int n) {
  out << YAML::Flow << YAML::BeginSeq;
  for (int i = 0; i < n; ++i) out << v[i];
  out << YAML::EndSeq;
}

void emitTransform(YAML::Emitter& out, const Eigen::Isometry3d& T) {
  out << YAML::BeginMap;
  const Eigen::Vector3d t = T.translation();
  const Eigen::Vector4d q = quaternionXyzw(T);
  const auto m = rowMajor(T);
  out << YAML::Key << "translation" << YAML::Value;
  emitSeq(out, t.data(), 3);
  out << YAML::Key << "rotation_xyzw" << YAML::Value;
  emitSeq(out, q.data(), 4);
  out << YAML::Key << "matrix" << YAML::Value;
  emitSeq(out, m.data(), 16);
  out << YAML::EndMap;
}

struct ParseError {
  std::string message;
};

std::vector<double> readNumbers(const YAML::Node& node, const std::string& key, size_t n) {
  if (!node || !node.IsSequence() || node.size() != n)
    throw ParseError{"'" + key + "' must be a list of " + std::to_string(n) + " numbers"};
  std::vector<double> out;
  for (const auto& v : node) out.push_back(v.as<double>());
  return out;
}

Eigen::Isometry3d readTransform(const YAML::Node& node, const std::string& key) {
  if (!node || !node.IsMap()) throw ParseError{"missing mapping '" + key + "'"};
  if (node["translation"] && node["rotation_xyzw"]) {
    const auto t = readNumbers(node["translation"], key + ".translation", 3);
    const auto q = readNumbers(node["rotation_xyzw"], key + ".rotation_xyzw", 4);
    for (double v : t)
      if (!std::isfinite(v)) throw ParseError{"'" + key + ".translation' is not finite"};
    for (double v : q)
      if (!std::isfinite(v)) throw ParseError{"'" + key + ".rotation_xyzw' is not finite"};
    const Eigen::Vector4d qv(q[0], q[1], q[2], q[3]);
    if (!(qv.norm() > 1e-9)) throw ParseError{"'" + key + ".rotation_xyzw' is not a rotation"};
    return makeTransform(Eigen::Vector3d(t[0], t[1], t[2]), qv);
  }
  if (node["matrix"]) {
    auto T = fromRowMajor(readNumbers(node["matrix"], key + ".matrix", 16));
    if (!T) throw ParseError{"'" + key + ".matrix': " + T.error()};
    return *T;
  }
  throw ParseError{"'" + key + "' needs translation + rotation_xyzw or matrix"};
}

std::string readString(const YAML::Node& node, const std::string& key) {
  if (!node[key]) throw ParseError{"missing key '" + key + "'"};
  return node[key].as<std::string>();
}

// `stddev: {translation_m: [...], rotation_deg: [...]}` (single-pair block and each pair).
void emitStddev(YAML::Emitter& out, const PoseStddev& sd) {
  out << YAML::Key << "stddev" << YAML::Value << YAML::BeginMap;
  out << YAML::Key << "translation_m" << YAML::Value;
  emitSeq(out, sd.translation_m.data(), 3);
  out << YAML::Key << "rotation_deg" << YAML::Value;
  emitSeq(out, sd.rotation_deg.data(), 3);
  out << YAML::EndMap;
}

PoseStddev readStddev(const YAML::Node& node, const std::string& name) {
  PoseStddev sd;
  const auto t = readNumbers(node["translation_m"], name + ".translation_m", 3);
  const auto a = readNumbers(node["rotation_deg"], name + ".rotation_deg", 3);
  sd.translation_m = {t[0], t[1], t[2]};
  sd.rotation_deg = {a[0], a[1], a[2]};
  return sd;
}

}  // namespace

std::string resultToYaml(const ResultFile& r) {
  YAML::Emitter out;
  out.SetDoublePrecision(9);
  out << YAML::BeginMap;
  out << YAML::Key << "method" << YAML::Value << r.method;
  out << YAML::Key << "camera_frame" << YAML::Value << r.camera_frame;
  out << YAML::Key << "lidar_frame" << YAML::Value << r.lidar_frame;
  out << YAML::Key << "camera_T_lidar" << YAML::Value;
  emitTransform(out, r.camera_T_lidar);
  out << YAML::Key << "lidar_T_camera" << YAML::Value;
  emitTransform(out, r.camera_T_lidar.inverse());
  out << YAML::Key << "views_used" << YAML::Value << r.views_used;
  if (!r.verdict.empty()) {
    out << YAML::Key << "verdict" << YAML::Value << r.verdict;
    out << YAML::Key << "verdict_reason" << YAML::Value << r.verdict_reason;
    out << YAML::Key << "views_to_check" << YAML::Value << YAML::Flow << r.views_to_check;
  }
  if (r.mlre_px) out << YAML::Key << "mlre_px" << YAML::Value << *r.mlre_px;
  if (r.stddev) emitStddev(out, *r.stddev);
  if (!r.quality.empty()) {
    out << YAML::Key << "quality" << YAML::Value << YAML::BeginMap;
    for (const auto& kv : r.quality) out << YAML::Key << kv.first << YAML::Value << kv.second;
    out << YAML::EndMap;
  }
  if (!r.notes.empty()) {
    out << YAML::Key << "notes" << YAML::Value << YAML::BeginSeq;
    for (const auto& n : r.notes) out << n;
    out << YAML::EndSeq;
  }
  if (!r.sensors.empty()) {
    out << YAML::Key << "reference_frame" << YAML::Value << r.reference_frame;
    out << YAML::Key << "sensors" << YAML::Value << YAML::BeginSeq;
    for (const auto& s : r.sensors) {
      out << YAML::BeginMap << YAML::Key << "frame" << YAML::Value << s.frame << YAML::Key << "kind"
          << YAML::Value << s.kind << YAML::Key << "reference_T_sensor" << YAML::Value;
      emitTransform(out, s.reference_T_sensor);
      out << YAML::EndMap;
    }
    out << YAML::EndSeq;
  }
  if (!r.pairs.empty()) {
    out << YAML::Key << "pairs" << YAML::Value << YAML::BeginSeq;
    for (const auto& p : r.pairs) {
      out << YAML::BeginMap << YAML::Key << "camera_frame" << YAML::Value << p.camera_frame
          << YAML::Key << "lidar_frame" << YAML::Value << p.lidar_frame << YAML::Key
          << "camera_T_lidar" << YAML::Value;
      emitTransform(out, p.camera_T_lidar);
      out << YAML::Key << "lidar_T_camera" << YAML::Value;
      emitTransform(out, p.camera_T_lidar.inverse());
      if (p.mlre_px) out << YAML::Key << "mlre_px" << YAML::Value << *p.mlre_px;
      if (p.stddev) emitStddev(out, *p.stddev);
      if (!p.verdict.empty()) {
        out << YAML::Key << "verdict" << YAML::Value << p.verdict;
        out << YAML::Key << "verdict_reason" << YAML::Value << p.verdict_reason;
        out << YAML::Key << "views_to_check" << YAML::Value << YAML::Flow << p.views_to_check;
      }
      out << YAML::EndMap;
    }
    out << YAML::EndSeq;
  }
  out << YAML::EndMap;
  return std::string(out.c_str()) + "\n";
}

Status writeResultFile(const std::string& path, const ResultFile& r) {
  const Status written = writeFileAtomic(path, resultToYaml(r));
  if (!written) return Status::failure("result file: " + written.reason);
  return written;
}

std::string failedResultPath(const std::string& path) {
  const std::string ext = ".yaml";
  if (path.size() > ext.size() && path.compare(path.size() - ext.size(), ext.size(), ext) == 0)
    return path.substr(0, path.size() - ext.size()) + ".failed.yaml";
  return path + ".failed.yaml";
}

Expected<ResultFile> parseResult(const std::string& text) {
  try {
    const YAML::Node root = YAML::Load(text);
    if (!root.IsMap()) throw ParseError{"result file must be a YAML mapping"};
    ResultFile r;
    r.method = readString(root, "method");
    r.camera_frame = readString(root, "camera_frame");
    r.lidar_frame = readString(root, "lidar_frame");
    r.camera_T_lidar = readTransform(root["camera_T_lidar"], "camera_T_lidar");
    if (root["views_used"]) r.views_used = root["views_used"].as<int>();
    if (root["mlre_px"]) r.mlre_px = root["mlre_px"].as<double>();
    if (root["verdict"]) r.verdict = root["verdict"].as<std::string>();
    if (root["verdict_reason"]) r.verdict_reason = root["verdict_reason"].as<std::string>();
    if (const YAML::Node v = root["views_to_check"])
      for (const auto& id : v) r.views_to_check.push_back(id.as<int>());
    if (const YAML::Node s = root["stddev"]) r.stddev = readStddev(s, "stddev");
    if (const YAML::Node q = root["quality"])
      for (const auto& kv : q) r.quality[kv.first.as<std::string>()] = kv.second.as<double>();
    if (const YAML::Node n = root["notes"])
      for (const auto& v : n) r.notes.push_back(v.as<std::string>());
    if (root["reference_frame"]) r.reference_frame = root["reference_frame"].as<std::string>();
    if (const YAML::Node s = root["sensors"]) {
      for (const auto& e : s) {
        SensorPoseEntry entry;
        entry.frame = readString(e, "frame");
        if (e["kind"]) entry.kind = e["kind"].as<std::string>();
        entry.reference_T_sensor =
            readTransform(e["reference_T_sensor"], "sensors[].reference_T_sensor");
        r.sensors.push_back(entry);
      }
    }
    if (const YAML::Node p = root["pairs"]) {
      for (const auto& e : p) {
        PairEntry entry;
        entry.camera_frame = readString(e, "camera_frame");
        entry.lidar_frame = readString(e, "lidar_frame");
        entry.camera_T_lidar = readTransform(e["camera_T_lidar"], "pairs[].camera_T_lidar");
        if (e["mlre_px"]) entry.mlre_px = e["mlre_px"].as<double>();
        if (const YAML::Node s = e["stddev"]) entry.stddev = readStddev(s, "pairs[].stddev");
        if (e["verdict"]) entry.verdict = e["verdict"].as<std::string>();
        if (e["verdict_reason"]) entry.verdict_reason = e["verdict_reason"].as<std::string>();
        if (const YAML::Node v = e["views_to_check"])
          for (const auto& id : v) entry.views_to_check.push_back(id.as<int>());
        r.pairs.push_back(entry);
      }
    }
    return r;
  } catch (const ParseError& e) {
    return Expected<ResultFile>::failure(e.message);
  } catch (const YAML::Exception& e) {
    return Expected<ResultFile>::failure(std::string("invalid result YAML: ") + e.what());
  } catch (const std::exception& e) {
    return Expected<ResultFile>::failure(std::string("cannot parse the result: ") + e.what());
  }
}

Expected<ResultFile> loadResultFile(const std::string& path) {
  const auto text = readTextFile(path, "result file");
  if (!text) return Expected<ResultFile>::failure(text.error());
  auto r = parseResult(*text);
  if (!r) return Expected<ResultFile>::failure("result file '" + path + "': " + r.error());
  return r;
}

}  // namespace board_calib
