// Rig description for MSG-Cal (docs/MSG.md): which cameras and LiDARs take part, their topics,
// their noise, the reference sensor and optional known extrinsics (e.g. a factory stereo
// calibration, used as an independent check). ROS-free; the loader returns reasons naming the key.
#pragma once

#include <board_calib/core/msg_graph/msg_graph.h>
#include <board_calib/core/types.h>

#include <Eigen/Geometry>

#include <string>
#include <vector>

namespace board_calib {

struct RigCamera {
  std::string name;  ///< sensor name (used in `reference`, `known_extrinsics`)
  std::string image_topic;
  std::string camera_info_topic;
  std::string
      features_topic;  ///< board features for the calibrator nodelet (default NAME/camera_board)
  double pixel_sigma_px = 0.0;    ///< px, noise.pixel_sigma_px (<= 0: graph default)
  double normal_sigma_deg = 0.0;  ///< deg, noise.normal_sigma_deg (<= 0: graph default)
  double offset_sigma_m = 0.0;    ///< m, noise.offset_sigma_m (<= 0: graph default)
};

struct RigLidar {
  std::string name;
  std::string cloud_topic;
  std::string
      features_topic;  ///< board features for the calibrator nodelet (default NAME/lidar_board)
  double normal_sigma_deg = 0.0;  ///< deg, noise.normal_sigma_deg (<= 0: graph default)
  double offset_sigma_m = 0.0;    ///< m, noise.offset_sigma_m (<= 0: graph default)
  double edge_sigma_m = 0.0;      ///< m, noise.edge_sigma_m (<= 0: graph default)
};

/// A transform known independently of the calibration (p_a = a_T_b * p_b).
struct KnownExtrinsic {
  std::string a, b;
  Eigen::Isometry3d a_T_b = Eigen::Isometry3d::Identity();
};

struct RigConfig {
  std::string target_path;  ///< absolute or relative to the working directory (resolved)
  std::string reference;    ///< sensor name whose pose is the identity
  std::vector<RigCamera> cameras;
  std::vector<RigLidar> lidars;
  std::vector<KnownExtrinsic> known_extrinsics;
  double stamp_tolerance_s =
      0.05;  ///< s, features of one board pose lie within this of its first stamp

  /// Empty when usable; otherwise the reason (duplicate names, unknown reference...).
  std::string validate() const;
  /// Sensor index in the order cameras then LiDARs (the MsgProblem order); -1 when unknown.
  int sensorIndex(const std::string& name) const;
  /// Sensors in MsgProblem order (frames are the sensor names until the bag tells the frame_id).
  std::vector<multi_sensor::SensorSpec> sensorSpecs() const;
  /// Sensor names in the same order.
  std::vector<std::string> sensorNames() const;
};

/// Parses a rig YAML; relative `target` paths are resolved against `base_dir` (empty: as is).
Expected<RigConfig> parseRigConfig(const std::string& yaml_text, const std::string& base_dir = "");
/// Loads a rig file; `target` is relative to the rig file's folder.
Expected<RigConfig> loadRigConfig(const std::string& path);

}  // namespace board_calib
