// YAML form of the board features (LiDAR and camera), shared by the pair session and the rig
// session files. For the session modules' .cpp files only (it includes yaml-cpp: no public header
// may include it); readers throw FeatureYamlError naming the bad key.
#pragma once

#include <board_calib/core/features.h>

#include <yaml-cpp/yaml.h>

#include <string>

namespace board_calib {
namespace feature_yaml {

struct FeatureYamlError {
  std::string message;
};

void emitLidar(YAML::Emitter& out, const LidarBoardFeatures& f);
void emitCamera(YAML::Emitter& out, const CameraBoardFeatures& f);
LidarBoardFeatures readLidar(const YAML::Node& n);
CameraBoardFeatures readCamera(const YAML::Node& n);

}  // namespace feature_yaml
}  // namespace board_calib
