// Simulator with ground truth: renders camera images and ray-casts spinning LiDARs observing a
// calibration board in a simple room with a person-like occluder. ROS-free; the
// simulate_bag tool wraps it into bags.
#pragma once

#include <board_calib/core/camera_model.h>
#include <board_calib/core/lidar_detection/lidar_cloud.h>
#include <board_calib/core/target.h>

#include <opencv2/core.hpp>

#include <cstdint>
#include <random>
#include <string>
#include <vector>

namespace board_calib {
namespace sim {

/// A spinning multi-beam LiDAR.
struct LidarSpec {
  std::string name;                    ///< preset name, e.g. "VLP-32C"
  std::vector<double> elevations_deg;  ///< beam elevation per ring; ring i = elevations_deg[i]
  std::vector<double>
      azimuth_offsets_deg;  ///< optional per-ring azimuth offset (Ouster stagger), deg
  double horizontal_resolution_deg = 0.2;  ///< azimuth step between columns, deg
  double range_noise_m = 0.01;             ///< 1 sigma range noise, m
  double min_range_m = 0.3;                ///< m
  double max_range_m = 100.0;              ///< m
  double dropout_probability = 0.0;        ///< chance a return is lost, 0..1
  double beam_divergence_deg = 0.15;       ///< footprint for mixed returns at board edges, deg
  bool organized = true;                   ///< rings x columns (NaN for no return) vs. a flat list
  bool with_ring = true;                   ///< emit the ring field
  double mixed_return_max_gap_m =
      1.5;                       ///< footprints straddling surfaces closer than this average
                                 ///< their ranges (mixed pixel); farther: strongest return, m
  double intensity_noise = 2.0;  ///< 1 sigma intensity noise, intensity units
  double rate_hz = 10.0;         ///< revolutions per second (used by the scenario timeline), Hz
  std::string validate() const;
  /// Columns of one revolution (round(360 / horizontal_resolution_deg)).
  int columns() const;
  /// Azimuth (rad, counter-clockwise from +x, in (-pi, pi]) of column `col` for ring `ring`.
  /// Column 0 looks backwards (-x) and columns advance clockwise seen from above, as the
  /// sensors spin.
  double azimuthRad(int ring, int col) const;
};

/// Presets: "VLP-16", "VLP-32C", "OS1-64".
Expected<LidarSpec> lidarPreset(const std::string& name);

/// A flat rectangle in the scene: a poster, door, screen or free-standing panel, i.e.
/// board-like clutter for both detectors. Two-sided; seen by cameras and LiDARs.
struct Panel {
  Eigen::Isometry3d world_T_panel =
      Eigen::Isometry3d::Identity();  ///< origin at the centre, x along the width, y along the
                                      ///< height, z the normal
  double width_m = 1.0;               ///< m, along panel x
  double height_m = 1.0;              ///< m, along panel y
  double grey = 0.2;                  ///< camera albedo, 0..1
  Eigen::Vector3d tint = Eigen::Vector3d::Ones();  ///< per-channel albedo factor (b, g, r)
  float intensity = 40;                            ///< LiDAR intensity
  std::string validate() const;
};

/// A mark printed on the board face (text, logo, sticker): an axis-aligned rectangle in board
/// coordinates, drawn dark (camera) and with the black print's LiDAR reflectivity.
struct BoardMark {
  Eigen::Vector2d min = Eigen::Vector2d::Zero();  ///< m, board frame (x right, y down)
  Eigen::Vector2d max = Eigen::Vector2d::Zero();  ///< m
};

/// The world: a board, a room (or a street) around the rig, clutter and a person holding the board.
struct SceneSpec {
  Target target;
  bool room = true;  ///< floor, walls and ceiling (textured for cameras); ignored when outdoor
  double room_half_size_m = 10;  ///< walls at +-this distance from the world origin, m
  double floor_z_m = -1.2;       ///< floor (or ground) height in the world frame (world z up), m
  double ceiling_z_m = 2.8;      ///< ceiling height in the world frame, m
  bool outdoor = false;  ///< a street: ground plane, facades far away on all sides, sky, no ceiling
  double street_half_width_m = 12.0;  ///< outdoor: facades at world y = +-this, m
  double facade_distance_m = 40.0;    ///< outdoor: facades at world x = +-this (street ends), m
  double ground_grey = 0.55;    ///< outdoor: pavement albedo, 0..1 (the board's is board_grey)
  bool occluder = true;         ///< person-like box below and behind the board
  float board_intensity = 200;  ///< LiDAR intensity of the board (its white parts)
  float background_intensity = 40;
  double board_grey = 0.86;  ///< camera albedo of the board face (white print), 0..1
  Eigen::Vector3d board_tint =
      Eigen::Vector3d::Ones();  ///< per-channel factor of the board albedo (b, g, r)
  double board_texture =
      0.0;  ///< relative albedo variation of a fine grain on the face (cardboard, wood), 0..0.5
  std::vector<BoardMark> board_marks;  ///< printed marks on the face
  std::vector<Panel> panels;           ///< board-like clutter
  std::string validate() const;
};

struct RenderOptions {
  int supersampling = 4;       ///< samples per pixel per axis (anti-aliased edges)
  double noise_sigma = 2.0;    ///< Gaussian pixel noise, grey levels
  double vignetting = 0.15;    ///< relative darkening at the image corners, 0..1
  double blur_sigma_px = 0.0;  ///< optional Gaussian blur, px
  bool mono = false;           ///< a mono camera: one grey channel (mono8), its noise added to it
  std::string validate() const;
};

/// What each LiDAR return hit (ground truth for detector tests), parallel to LidarCloud::points.
enum class ReturnOrigin : std::uint8_t {
  kNone = 0,        ///< no return (NaN point; organized output only)
  kBoard = 1,       ///< the whole beam footprint on the board
  kBackground = 2,  ///< room or occluder only
  kMixed = 3,       ///< footprint straddles the board's edge and something else
};

/// Ray-casts one full revolution. Points are in the LiDAR frame. world_T_board places the
/// board (board frame as in target.h). `origins` (optional) receives what each point hit.
LidarCloud simulateLidarScan(const LidarSpec& spec, const Eigen::Isometry3d& world_T_lidar,
                             const SceneSpec& scene, const Eigen::Isometry3d& world_T_board,
                             std::mt19937& rng, std::vector<ReturnOrigin>* origins);

/// Ray-casts one full revolution. Points are in the LiDAR frame. world_T_board places the
/// board (board frame as in target.h).
LidarCloud simulateLidarScan(const LidarSpec& spec, const Eigen::Isometry3d& world_T_lidar,
                             const SceneSpec& scene, const Eigen::Isometry3d& world_T_board,
                             std::mt19937& rng);

/// Renders a raw (distorted) bgr8 image of the scene.
cv::Mat renderCameraImage(const CameraModel& camera, const Eigen::Isometry3d& world_T_camera,
                          const SceneSpec& scene, const Eigen::Isometry3d& world_T_board,
                          const RenderOptions& options, std::mt19937& rng);

/// The expensive, deterministic part of renderCameraImage: anti-aliased linear colour (CV_32FC3,
/// BGR, 0..1) before blur, vignetting, quantisation and noise. Reusable while the board is still.
/// Empty when the options, scene or camera are invalid.
cv::Mat renderCameraRadiance(const CameraModel& camera, const Eigen::Isometry3d& world_T_camera,
                             const SceneSpec& scene, const Eigen::Isometry3d& world_T_board,
                             const RenderOptions& options);
/// Blur, vignetting, Gaussian noise and 8-bit quantisation of a radiance image -> bgr8.
cv::Mat finishCameraImage(const cv::Mat& radiance, const CameraModel& camera,
                          const RenderOptions& options, std::mt19937& rng);

}  // namespace sim
}  // namespace board_calib
