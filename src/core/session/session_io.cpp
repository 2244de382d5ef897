// Session file: YAML with the target, the gating options and every kept view's features.
// Features (not images) are stored, so a session is small and a solve is reproducible.
#include <board_calib/core/file_io.h>
#include <board_calib/core/session/session.h>
#include <board_calib/core/transform.h>

#include <board_calib/core/session/feature_yaml.h>

#include <yaml-cpp/yaml.h>

#include <limits>
#include <set>

namespace board_calib {
namespace {

constexpr int kSessionFormatVersion = 1;

}  // namespace

using feature_yaml::emitCamera;
using feature_yaml::emitLidar;
using feature_yaml::readCamera;
using feature_yaml::readLidar;

Status PairSession::save(const std::string& path) const {
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
  const Status written = writeFileAtomic(path, std::string(out.c_str()) + "\n");
  if (!written) return Status::failure("session file: " + written.reason);
  return written;
}

Status PairSession::load(const std::string& path) {
  try {
    const auto text = readTextFile(path, "session file");
    if (!text) return Status::failure(text.error());
    const YAML::Node root = YAML::Load(*text);
    if (!root.IsMap() || !root["board_calib_session"])
      return Status::failure("'" + path + "' is not a board_calib session file");
    if (root["board_calib_session"].as<int>() != kSessionFormatVersion)
      return Status::failure("'" + path + "' has an unsupported session format version");
    auto target = parseTarget(root["target"].as<std::string>());
    if (!target) return Status::failure("session '" + path + "': target: " + target.error());
    std::vector<SessionView> views;
    std::set<int> ids;
    int next_id = 0;
    const YAML::Node view_list = root["views"];
    if (view_list && !view_list.IsSequence())
      return Status::failure("session '" + path + "': 'views' must be a list");
    for (const auto& v : view_list) {
      SessionView sv;
      sv.view.id = v["id"].as<int>();
      if (sv.view.id < 0 || sv.view.id == std::numeric_limits<int>::max() ||
          !ids.insert(sv.view.id).second)
        return Status::failure("session '" + path + "': view id " + std::to_string(sv.view.id) +
                               " is negative, out of range or appears twice");
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
  } catch (const std::exception& e) {
    return Status::failure("session '" + path + "' cannot be read: " + e.what());
  }
}

}  // namespace board_calib
