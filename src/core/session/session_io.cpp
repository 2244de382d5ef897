// Session file: YAML with the target, the gating options and every kept view's features.
// Features (not images) are stored, so a session is small and a solve is reproducible.
#include <board_calib/core/session.h>
#include <board_calib/core/transform.h>

#include "feature_yaml.h"

#include <yaml-cpp/yaml.h>

#include <fstream>

namespace board_calib {
namespace {

constexpr int kSessionFormatVersion = 1;

}  // namespace

using feature_yaml::emitCamera;
using feature_yaml::emitLidar;
using feature_yaml::readCamera;
using feature_yaml::readLidar;

Status CalibrationSession::save(const std::string& path) const {
  YAML::Emitter out;
  out.SetDoublePrecision(12);  // sub-micrometre round trip
  out << YAML::BeginMap;
  out << YAML::Key << "board_calib_session" << YAML::Value << kSessionFormatVersion;
  out << YAML::Key << "target" << YAML::Value << YAML::Literal << targetToYaml(target_);
  out << YAML::Key << "views" << YAML::Value << YAML::BeginSeq;
  for (const auto& v : views_) {
    out << YAML::BeginMap;
    out << YAML::Key << "id" << YAML::Value << v.view.id;
    out << YAML::Key << "why" << YAML::Value << v.why;
    out << YAML::Key << "lidar" << YAML::Value;
    emitLidar(out, v.view.lidar);
    out << YAML::Key << "camera" << YAML::Value;
    emitCamera(out, v.view.camera);
    out << YAML::EndMap;
  }
  out << YAML::EndSeq << YAML::EndMap;
  std::ofstream f(path);
  if (!f) return Status::failure("cannot write session file '" + path + "'");
  f << out.c_str() << "\n";
  if (!f) return Status::failure("error while writing session file '" + path + "'");
  return Status::success();
}

Status CalibrationSession::load(const std::string& path) {
  try {
    const YAML::Node root = YAML::LoadFile(path);
    if (!root.IsMap() || !root["board_calib_session"])
      return Status::failure("'" + path + "' is not a board_calib session file");
    if (root["board_calib_session"].as<int>() != kSessionFormatVersion)
      return Status::failure("'" + path + "' has an unsupported session format version");
    auto target = parseTarget(root["target"].as<std::string>());
    if (!target) return Status::failure("session '" + path + "': target: " + target.error());
    std::vector<SessionView> views;
    int next_id = 0;
    for (const auto& v : root["views"]) {
      SessionView sv;
      sv.view.id = v["id"].as<int>();
      sv.why = v["why"].as<std::string>("");
      sv.view.lidar = readLidar(v["lidar"]);
      sv.view.camera = readCamera(v["camera"]);
      next_id = std::max(next_id, sv.view.id + 1);
      views.push_back(std::move(sv));
    }
    reset();
    target_ = *target;
    views_ = std::move(views);
    next_id_ = next_id;
    return Status::success();
  } catch (const feature_yaml::FeatureYamlError& e) {
    return Status::failure("session '" + path + "': " + e.message);
  } catch (const YAML::BadFile&) {
    return Status::failure("cannot read session file '" + path + "'");
  } catch (const YAML::Exception& e) {
    return Status::failure("session '" + path + "' is malformed: " + e.what());
  }
}

}  // namespace board_calib
