// SPDX-License-Identifier: BSD-3-Clause
// Synthetic board features at known ground truth, for solver tests and benchmarks (no images,
// no full clouds): a spinning LiDAR's rings are ray-cast against the board rectangle, the edge
// points are the per-scan-line extremes (so they lie up to one horizontal step inside the true
// edge, as on a real LiDAR), the image lines are the projected board edges with pixel noise, and
// the camera board plane is the PnP of the corners those noisy lines meet at.
#pragma once

#include <board_calib/core/features.h>

#include <random>

namespace board_calib {
namespace sim {

struct SyntheticFeatureOptions {
  int num_views = 30;
  double board_width_m = 1.0;   ///< true board size, m
  double board_height_m = 1.0;  ///< m
  /// The camera plane and pose are computed as PnP with a board of this factor times the true
  /// size would give (pose translation scales with it): < 1 mimics a board declared too small.
  double declared_size_factor = 1.0;

  // LiDAR (spinning, rings evenly spread over the vertical field of view).
  int lidar_rings = 64;
  double lidar_vertical_fov_deg = 45.0;          ///< deg, symmetric about the horizon
  double lidar_horizontal_resolution_deg = 0.2;  ///< deg
  double lidar_range_noise_m = 0.02;             ///< 1 sigma along the ray, m
  /// Keep at most this many board points per view (uniform subsample); 0 keeps all.
  int max_board_points = 500;

  // Camera (pinhole, undistorted pixels).
  int image_width = 1600, image_height = 1200;      ///< px
  double fx = 1200, fy = 1200, cx = 800, cy = 600;  ///< px
  double line_noise_px = 0.3;  ///< 1 sigma of the line at its two end corners, px
  /// Camera plane and pose from a PnP on the four noisy image corners (the intersections of the
  /// noisy lines), as the plain-board detector does: the plane error grows with the distance
  /// (about Z^2 for both tilt and offset) and is consistent with the lines. With 0.3 px lines
  /// over 2-5 m: 0.33 deg normal and 3.6 mm offset RMS. false: the true plane with the
  /// independent, distance-free noise below (0.2 deg, 3 mm; the earlier model).
  bool camera_plane_from_pnp = true;
  double camera_plane_normal_noise_deg =
      0.2;  ///< without PnP: 1 sigma tilt of the camera plane normal, deg
  double camera_plane_offset_noise_m =
      0.003;  ///< without PnP: 1 sigma of the camera plane offset, m

  // Board poses (camera frame).
  double min_distance_m = 2.0, max_distance_m = 5.0;  ///< m, board centre from the camera
  double max_tilt_deg = 35.0;        ///< board normal away from the viewing ray, deg
  double diamond_jitter_deg = 15.0;  ///< in-plane rotation around 45 deg, deg
  /// Fraction of the image half-size the board centre may be off the optical axis.
  double max_off_axis_fraction = 0.6;

  std::string validate() const;
};

/// A plausible ground truth camera_T_lidar: the LiDAR (x forward, z up) beside a camera
/// (optical frame: z forward, y down), with a random extra rotation and offset.
Eigen::Isometry3d randomCameraTLidar(std::mt19937& rng, double max_extra_rotation_deg = 10.0,
                                     double max_offset_m = 0.3);

struct SyntheticScene {
  std::vector<View> views;
  std::vector<Eigen::Isometry3d> camera_T_board;  ///< true board poses (true size), per view
  Eigen::Isometry3d camera_T_lidar = Eigen::Isometry3d::Identity();
};

/// Generates options.num_views views of the board seen by both sensors with camera_T_lidar as
/// the ground truth. Fails with a reason if the options are invalid or too few poses fit both
/// fields of view.
Expected<SyntheticScene> generateSyntheticViews(const SyntheticFeatureOptions& options,
                                                const Eigen::Isometry3d& camera_T_lidar,
                                                std::mt19937& rng);

/// A LiDAR range offset: every return `delta_m` further along its ray (board points, edge
/// points, edge lines' points, corners), the plane refitted through the moved points.
void lengthenRanges(LidarBoardFeatures* lidar, double delta_m);

}  // namespace sim
}  // namespace board_calib
