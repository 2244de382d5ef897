// SPDX-License-Identifier: BSD-3-Clause
// Synthetic multi-sensor rigs at known ground truth for the MSG graph tests and benchmark:
// cameras see AprilTag-grid corners (projected, pixel noise) and get their board pose from a
// PnP refinement of those noisy corners (so plane and corners are consistent, as from a
// detector); spinning LiDARs are ray-cast ring by ring against the board rectangle (range noise
// along the ray), the plane is a PCA fit of the hits and the edge points are the per-ring
// extremes (up to one horizontal step inside the true edge, as on a real LiDAR).
// Edges are named by the physical board edge (outer corner k to k+1) for every sensor.
#pragma once

#include <board_calib/core/msg_graph/msg_graph.h>
#include <board_calib/core/rig/rig_config.h>
#include <board_calib/core/target.h>

#include <random>

namespace board_calib {
namespace sim {

struct RigSensor {
  std::string frame;
  multi_sensor::SensorKind kind = multi_sensor::SensorKind::kCamera;
  Eigen::Isometry3d reference_T_sensor = Eigen::Isometry3d::Identity();  ///< ground truth
  // Camera (pinhole, undistorted pixels).
  int image_width = 1280, image_height = 960;       ///< px
  double fx = 1000, fy = 1000, cx = 640, cy = 480;  ///< px
  double pixel_noise_px = 0.3;                      ///< 1 sigma per corner coordinate, px
  // LiDAR (spinning; rings evenly spread between the two elevations).
  int rings = 32;
  double min_elevation_deg = -25.0, max_elevation_deg = 15.0;  ///< deg
  double horizontal_resolution_deg = 0.2;                      ///< deg
  double range_noise_m = 0.01;                                 ///< 1 sigma along the ray, m
  /// 1 sigma of a fixed per-ring range offset (laser-to-laser calibration error, drawn once
  /// per scene): a systematic error that tilts the fitted plane differently per board pose.
  double ring_bias_m = 0.002;
  double max_range_m = 50.0;   ///< m
  int max_board_points = 400;  ///< uniform subsample of the kept board points; 0 keeps all
  /// Multiplies every noise of this sensor (3 for the "noisy sensor" experiments).
  double noise_scale = 1.0;
};

/// Ground-truth sensors of the reference test rig, in the frame of the left camera
/// (optical frame): a stereo pair (12 cm baseline), a VLP-32C-like and an OS1-64-like LiDAR.
std::vector<RigSensor> defaultRig();
/// A VLP-16-like LiDAR beside the rig, to add as a further (e.g. noisy) sensor.
RigSensor extraLidar16(const std::string& frame, double noise_scale);

struct RigSceneOptions {
  int num_poses = 40;
  Target target;  ///< defaults to a 1 m AprilTag grid (4 x 4 tags of 0.2 m)
  double min_distance_m = 2.0, max_distance_m = 5.0;  ///< board centre from the reference sensor
  double max_tilt_deg = 35.0;                         ///< board normal away from the viewing ray
  double diamond_jitter_deg = 15.0;                   ///< in-plane rotation around 45 deg
  double max_off_axis_deg = 15.0;  ///< board centre direction off the reference optical axis
  int min_lidar_rings = 4;         ///< rings that must cross the board for a LiDAR to see it
  int min_lidar_points = 60;
  int max_attempts = 5000;  ///< board pose draws before giving up

  RigSceneOptions();
  std::string validate() const;
};

struct RigScene {
  multi_sensor::MsgProblem problem;  ///< reference sensor 0, sigmas left at the defaults (<= 0)
  std::vector<RigSensor> sensors;
  std::vector<Eigen::Isometry3d> reference_T_board;  ///< per board pose
};

/// Board poses every sensor sees completely (cameras: all corners inside the image; LiDARs:
/// enough rings and points). Fails with a reason when the options are invalid or the sensors
/// share too little field of view.
Expected<RigScene> generateRigScene(const std::vector<RigSensor>& sensors,
                                    const RigSceneOptions& options, std::mt19937& rng);

/// `sensors` seeing `num_poses` board poses (default scene options) drawn from `seed`.
Expected<RigScene> rigScene(const std::vector<RigSensor>& sensors, int num_poses, unsigned seed);
/// The reference rig (defaultRig) with `num_poses` board poses drawn from `seed`: the fixture
/// of the rig session, report and calibration tests.
Expected<RigScene> defaultRigScene(int num_poses, unsigned seed);

/// The rig file of a scene: every sensor named by its frame (topics derived from it, as a rig
/// file gives them), the first sensor the reference.
RigConfig rigConfigOf(const RigScene& scene);

}  // namespace sim
}  // namespace board_calib
