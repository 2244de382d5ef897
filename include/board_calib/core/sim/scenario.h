// Scenario of a simulated calibration recording: a rig of cameras and LiDARs, a board waved
// in front of it (held still, then moved), sensor rates and stamp offsets, noise and a seed.
// The core turns it into a time-ordered list of frames with ground truth; the simulate_bag tool
// only serialises them. File format: docs/SIMULATOR.md.
#pragma once

#include <board_calib/core/result_io.h>
#include <board_calib/core/sim/simulator.h>

#include <map>
#include <memory>
#include <string>
#include <vector>

namespace board_calib {
namespace sim {

struct CameraSensor {
  std::string name;      ///< topic namespace: /<name>/image_raw, /<name>/camera_info
  std::string frame_id;  ///< optical frame (z forward, x right, y down)
  CameraIntrinsics intrinsics;
  Eigen::Isometry3d rig_T_sensor =
      Eigen::Isometry3d::Identity();  ///< optical frame in the rig frame
  double rate_hz = 10.0;              ///< Hz
  double stamp_offset_s = 0.0;        ///< s, phase of the first frame after the recording starts
  RenderOptions render;
};

struct LidarSensor {
  std::string name;      ///< topic namespace: /<name>/points
  std::string frame_id;  ///< x forward, y left, z up
  LidarSpec spec;        ///< spec.rate_hz is the revolution rate
  Eigen::Isometry3d rig_T_sensor = Eigen::Isometry3d::Identity();
  double stamp_offset_s = 0.0;  ///< s
};

/// How the person waves the board: N poses in front of the rig (rig +x forward, +z up).
struct MotionSpec {
  int poses = 20;
  double min_distance_m = 1.5;     ///< m, board centre from the rig origin
  double max_distance_m = 6.0;     ///< m
  double max_azimuth_deg = 20.0;   ///< deg, board centre direction left/right of rig +x
  double max_elevation_deg = 8.0;  ///< deg, board centre direction above/below the rig's horizon
  double min_roll_deg = 30.0;      ///< deg, diamond-like roll about the viewing axis (magnitude)
  double max_roll_deg = 60.0;      ///< deg
  double max_tilt_deg = 25.0;      ///< deg, extra yaw / pitch of the board away from facing the rig
  double min_edge_slope_deg =
      15.0;  ///< deg, min angle between any board edge and every LiDAR's scan plane
  double min_board_height_m = 0.2;  ///< m, lowest board corner above the floor
  double hold_s = 1.5;              ///< s, the board is still this long at each pose
  double move_s = 1.0;              ///< s, smooth move between poses
  int still_frames_per_hold =
      0;                     ///< per sensor: keep only the last N frames of each hold (0 = all)
  int frames_per_move = -1;  ///< per sensor: keep N evenly spread frames of each move (-1 = all)
  double image_margin_px = 20.0;  ///< px, board corners stay this far inside every image
  std::string validate() const;
};

struct Scenario {
  std::string name;
  std::string target_path;  ///< as written in the file (resolved relative to the scenario file)
  SceneSpec scene;          ///< scene.target loaded from target_path
  Eigen::Isometry3d world_T_rig = Eigen::Isometry3d::Identity();  ///< rig placement in the room
  std::vector<CameraSensor> cameras;
  std::vector<LidarSensor> lidars;
  MotionSpec motion;
  unsigned int seed = 1;
  std::string validate() const;
};

/// Parses a scenario from YAML text; `base_dir` resolves a relative target path. Errors name
/// the offending key.
Expected<Scenario> parseScenario(const std::string& yaml_text, const std::string& base_dir);
/// Loads a scenario file (target path relative to the file's folder, or absolute).
Expected<Scenario> loadScenario(const std::string& path);

/// One sensor message to produce.
struct Frame {
  double stamp = 0.0;  ///< s since the recording start
  bool is_camera = false;
  int sensor = 0;      ///< index into Scenario::cameras or Scenario::lidars
  int pose = -1;       ///< index of the held pose, -1 while the board moves
  bool still = false;  ///< the board does not move during this frame
  Eigen::Isometry3d world_T_board = Eigen::Isometry3d::Identity();
};

struct Timeline {
  std::vector<Eigen::Isometry3d> world_T_board_poses;  ///< the held poses
  std::vector<Frame> frames;                           ///< sorted by stamp
  double duration_s = 0.0;
};

/// Draws the board poses (seeded) so the board is fully seen by every camera, cut by every
/// LiDAR with no edge near-parallel to its scan lines, and clear of the floor; then lays out
/// the frames of every sensor at its rate. Fails with a reason when no such pose exists.
Expected<Timeline> makeTimeline(const Scenario& scenario);

/// World pose of a sensor.
Eigen::Isometry3d worldTCamera(const Scenario& scenario, int camera);
Eigen::Isometry3d worldTLidar(const Scenario& scenario, int lidar);

/// Ground truth in the result-file format: the first camera / first LiDAR as the main pair,
/// `sensors:` in the rig frame and `pairs:` for every camera<->LiDAR pair.
ResultFile groundTruth(const Scenario& scenario);

/// Produces frame data (keeps a pointer: the scenario must outlive it), reusing the noise-free
/// render of a camera while the board is still. Frame noise is seeded from the scenario seed and
/// the frame index, so any frame can be regenerated on its own.
class FrameGenerator {
 public:
  /// Fails when a camera's intrinsics are invalid.
  static Expected<FrameGenerator> create(const Scenario& scenario);
  cv::Mat image(const Frame& frame, size_t frame_index);
  LidarCloud cloud(const Frame& frame, size_t frame_index,
                   std::vector<ReturnOrigin>* origins = nullptr);
  const CameraModel& cameraModel(int camera) const { return models_[static_cast<size_t>(camera)]; }

 private:
  explicit FrameGenerator(const Scenario& scenario) : scenario_(&scenario) {}
  const Scenario* scenario_;
  std::vector<CameraModel> models_;
  struct Cached {
    int pose = -2;
    cv::Mat radiance;
  };
  std::vector<Cached> cache_;  // per camera: the radiance of its current still pose
};

}  // namespace sim
}  // namespace board_calib
