// The one association of LiDAR board edges with image edge lines, by projection with an
// extrinsic: used by the PBPC solver, the MSG graph's line terms, the MLRE figures and the
// projected-edges overlay, so the solver and the overlay score the same pairs.
#pragma once

#include <board_calib/core/features.h>
#include <board_calib/core/types.h>

#include <array>

namespace board_calib {

/// Detectors name edges on their own (the LiDAR from the scan geometry, the image from the
/// pattern or the outline), so the names can disagree; the projection decides.
struct EdgeAssociation {
  /// Per image edge j, the LiDAR edge paired with it: always a permutation of 0..3.
  std::array<int, kNumEdges> lidar_edge{{0, 1, 2, 3}};
  /// Per image edge j: both edges usable and at least one point of lidar_edge[j] in front of
  /// the camera, so the pair can be scored.
  std::array<bool, kNumEdges> scored{};
  /// Per image edge j: mean perpendicular distance (undistorted px) of lidar_edge[j]'s points to
  /// line j; infinite when not scored.
  std::array<double, kNumEdges> mean_px{};
  int matched = 0;          ///< scored pairs
  bool relabelled = false;  ///< differs from the detectors' naming (the identity)
};

/// Mean perpendicular distance (undistorted px, with the intrinsic matrix K of the undistorted
/// image: image.K, or the camera model's) of `lidar_points` projected with camera_T_lidar to
/// image edge line j; `count` receives the points in front of the camera; infinite when none is.
double edgeLineDistancePx(const Eigen::Matrix3d& K, const CameraBoardFeatures& image,
                          int image_edge, const Points3& lidar_points,
                          const Eigen::Isometry3d& camera_T_lidar, int* count);
inline double edgeLineDistancePx(const CameraBoardFeatures& image, int image_edge,
                                 const Points3& lidar_points,
                                 const Eigen::Isometry3d& camera_T_lidar, int* count) {
  return edgeLineDistancePx(image.K, image, image_edge, lidar_points, camera_T_lidar, count);
}

/// Best one-to-one pairing over the 24 permutations: most scored pairs first, then the least
/// summed mean distance. The detectors' naming is kept unless the best scores more pairs or
/// halves the summed distance, so a near-tie (a board seen almost edge-on, a rough extrinsic)
/// does not swap labels back and forth between solver iterations. A LiDAR edge counts when
/// it is valid and has >= min_lidar_points points; an image edge when its line is valid.
EdgeAssociation associateEdges(const Eigen::Matrix3d& K, const CameraBoardFeatures& image,
                               const LidarBoardFeatures& lidar,
                               const Eigen::Isometry3d& camera_T_lidar, int min_lidar_points = 2);
inline EdgeAssociation associateEdges(const CameraBoardFeatures& image,
                                      const LidarBoardFeatures& lidar,
                                      const Eigen::Isometry3d& camera_T_lidar,
                                      int min_lidar_points = 2) {
  return associateEdges(image.K, image, lidar, camera_T_lidar, min_lidar_points);
}

}  // namespace board_calib
