// The result file (a contract: tools outside this package read it): writer and reader.
#pragma once

#include <board_calib/core/types.h>

#include <map>
#include <string>
#include <vector>

namespace board_calib {

struct PoseStddev {
  Eigen::Vector3d translation_m = Eigen::Vector3d::Zero();
  Eigen::Vector3d rotation_deg = Eigen::Vector3d::Zero();  ///< about x (roll), y (pitch), z (yaw)
};

/// One sensor's pose in the reference frame (multi-sensor results).
struct SensorPoseEntry {
  std::string frame;
  std::string kind;  ///< "camera" or "lidar"
  Eigen::Isometry3d reference_T_sensor = Eigen::Isometry3d::Identity();
};

/// One camera<->LiDAR pair, as in the single-pair block.
struct PairEntry {
  std::string camera_frame;
  std::string lidar_frame;
  Eigen::Isometry3d camera_T_lidar = Eigen::Isometry3d::Identity();
  std::optional<double> mlre_px;
  std::optional<PoseStddev> stddev;  ///< 1 sigma of camera_T_lidar, as the single-pair `stddev`
  std::string verdict;               ///< good | doubtful | failed (empty: not judged)
  std::string verdict_reason;        ///< one line
  std::vector<int> views_to_check;   ///< board pose ids
};

struct ResultFile {
  std::string method;
  std::string camera_frame;
  std::string lidar_frame;
  Eigen::Isometry3d camera_T_lidar = Eigen::Isometry3d::Identity();  ///< p_camera = T * p_lidar
  int views_used = 0;
  std::string verdict;         ///< good | doubtful | failed (empty: not judged, e.g. ground truth)
  std::string verdict_reason;  ///< one line
  std::vector<int> views_to_check;
  std::optional<double> mlre_px;
  std::optional<PoseStddev> stddev;
  /// Further named figures (plane_rms_mm, final_cost, ...), written under `quality:`.
  std::map<std::string, double> quality;
  /// Human-readable findings (inconsistencies, weak directions), written under `notes:`.
  std::vector<std::string> notes;
  std::string reference_frame;  ///< multi-sensor: the fixed frame of `sensors`
  std::vector<SensorPoseEntry> sensors;
  std::vector<PairEntry> pairs;
};

std::string resultToYaml(const ResultFile& result);
Status writeResultFile(const std::string& path, const ResultFile& result);
/// Where a failed result goes for inspection: "x.yaml" -> "x.failed.yaml" (never the good file's
/// name).
std::string failedResultPath(const std::string& path);
Expected<ResultFile> parseResult(const std::string& yaml_text);
Expected<ResultFile> loadResultFile(const std::string& path);

}  // namespace board_calib
