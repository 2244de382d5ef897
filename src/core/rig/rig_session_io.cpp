// Rig session file: the rig's sensors (name, kind, frame) and every captured pose's features.
#include <board_calib/core/rig/rig_session.h>

#include <board_calib/core/session/feature_yaml.h>

#include <board_calib/core/file_io.h>

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <limits>
#include <set>

namespace board_calib {
namespace multi_sensor {
namespace {

constexpr int kRigSessionFormatVersion = 1;

}  // namespace

Status RigSession::save(const std::string& path) const {
  YAML::Emitter out;
  out.SetDoublePrecision(12);  // sub-micrometre round trip
  out << YAML::BeginMap;
  out << YAML::Key << "board_calib_rig_session" << YAML::Value << kRigSessionFormatVersion;
  out << YAML::Key << "sensors" << YAML::Value << YAML::BeginSeq;
  for (size_t k = 0; k < sensors_.size(); ++k)
    out << YAML::Flow << YAML::BeginMap << YAML::Key << "name" << YAML::Value << names_[k]
        << YAML::Key << "kind" << YAML::Value << sensorKindName(sensors_[k].kind) << YAML::Key
        << "frame" << YAML::Value << sensors_[k].frame << YAML::EndMap;
  out << YAML::EndSeq;
  out << YAML::Key << "poses" << YAML::Value << YAML::BeginSeq;
  for (const auto& p : poses_) {
    out << YAML::BeginMap;
    out << YAML::Key << "id" << YAML::Value << p.observation.id;
    out << YAML::Key << "why" << YAML::Value << p.why;
    out << YAML::Key << "cameras" << YAML::Value << YAML::BeginSeq;
    for (const auto& [sensor, f] : p.observation.cameras) {
      out << YAML::BeginMap << YAML::Key << "sensor" << YAML::Value << sensor << YAML::Key
          << "features" << YAML::Value;
      feature_yaml::emitCamera(out, f);
      out << YAML::EndMap;
    }
    out << YAML::EndSeq;
    out << YAML::Key << "lidars" << YAML::Value << YAML::BeginSeq;
    for (const auto& [sensor, f] : p.observation.lidars) {
      out << YAML::BeginMap << YAML::Key << "sensor" << YAML::Value << sensor << YAML::Key
          << "features" << YAML::Value;
      feature_yaml::emitLidar(out, f);
      out << YAML::EndMap;
    }
    out << YAML::EndSeq << YAML::EndMap;
  }
  out << YAML::EndSeq << YAML::EndMap;
  const Status written = writeFileAtomic(path, std::string(out.c_str()) + "\n");
  if (!written) return Status::failure("rig session file: " + written.reason);
  return written;
}

Status RigSession::load(const std::string& path) {
  try {
    const auto text = readTextFile(path, "rig session file");
    if (!text) return Status::failure(text.error());
    const YAML::Node root = YAML::Load(*text);
    if (!root.IsMap() || !root["board_calib_rig_session"])
      return Status::failure("'" + path + "' is not a board_calib rig session file");
    if (root["board_calib_rig_session"].as<int>() != kRigSessionFormatVersion)
      return Status::failure("'" + path + "' has an unsupported rig session format version");
    const YAML::Node sensors = root["sensors"];
    if (!sensors || !sensors.IsSequence() || sensors.size() != sensors_.size())
      return Status::failure("rig session '" + path + "' lists " +
                             std::to_string(sensors ? sensors.size() : 0) +
                             " sensors; this rig has " + std::to_string(sensors_.size()));
    std::vector<std::string> frames;
    for (size_t k = 0; k < sensors_.size(); ++k) {
      const std::string kind = sensors[k]["kind"].as<std::string>("");
      if (kind != sensorKindName(sensors_[k].kind))
        return Status::failure("rig session '" + path + "': sensor " + std::to_string(k) +
                               " is a " + kind + " there but a " +
                               sensorKindName(sensors_[k].kind) + " (" + names_[k] +
                               ") in this rig");
      frames.push_back(sensors[k]["frame"].as<std::string>(""));
    }
    std::vector<RigSessionPose> poses;
    std::set<int> ids;
    int next_id = 0;
    const int num_sensors = static_cast<int>(sensors_.size());
    for (const auto& p : root["poses"]) {
      RigSessionPose pose;
      pose.observation.id = p["id"].as<int>();
      if (pose.observation.id < 0 || pose.observation.id == std::numeric_limits<int>::max() ||
          !ids.insert(pose.observation.id).second)
        return Status::failure("rig session '" + path + "': pose id " +
                               std::to_string(pose.observation.id) +
                               " is negative, out of range or appears twice");
      pose.why = p["why"].as<std::string>("");
      for (const auto& c : p["cameras"]) {
        const int k = c["sensor"].as<int>();
        if (k < 0 || k >= num_sensors || sensors_[k].kind != SensorKind::kCamera)
          return Status::failure(
              "rig session '" + path + "': pose " + std::to_string(pose.observation.id) +
              " has camera features for sensor " + std::to_string(k) + ", not a camera");
        pose.observation.cameras[k] = feature_yaml::readCamera(c["features"]);
      }
      for (const auto& l : p["lidars"]) {
        const int k = l["sensor"].as<int>();
        if (k < 0 || k >= num_sensors || sensors_[k].kind != SensorKind::kLidar)
          return Status::failure(
              "rig session '" + path + "': pose " + std::to_string(pose.observation.id) +
              " has LiDAR features for sensor " + std::to_string(k) + ", not a LiDAR");
        pose.observation.lidars[k] = feature_yaml::readLidar(l["features"]);
      }
      next_id = std::max(next_id, pose.observation.id + 1);
      poses.push_back(std::move(pose));
    }
    reset();
    for (size_t k = 0; k < sensors_.size(); ++k)
      if (!frames[k].empty()) sensors_[k].frame = frames[k];
    poses_ = std::move(poses);
    next_id_ = next_id;
    return Status::success();
  } catch (const feature_yaml::FeatureYamlError& e) {
    return Status::failure("rig session '" + path + "': " + e.message);
  } catch (const YAML::BadFile&) {
    return Status::failure("cannot read rig session file '" + path + "'");
  } catch (const YAML::Exception& e) {
    return Status::failure("rig session '" + path + "' is malformed: " + e.what());
  } catch (const std::exception& e) {
    return Status::failure("rig session '" + path + "' cannot be read: " + e.what());
  }
}

}  // namespace multi_sensor
}  // namespace board_calib
