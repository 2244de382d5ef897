// Where a sensor's board plane is best determined, and the gap between two sensors' planes
// there: shared by the pairwise plane-to-plane solver and the MSG graph.
#pragma once

#include <board_calib/core/features.h>
#include <board_calib/core/types.h>

namespace board_calib {

/// A point of the board on the sensor's own plane where that plane is best determined: the
/// LiDAR board points' centroid; the camera's PnP data centre (pattern points, else the four
/// image corners back-projected, else the board origin), each projected onto the plane.
Eigen::Vector3d boardPoint(const LidarBoardFeatures& features);
Eigen::Vector3d boardPoint(const CameraBoardFeatures& features);

/// Gap (m) between plane a and plane b mapped with a_T_b, at the midpoint of the two board
/// points (point_a in a, point_b in b): the MSG offset residual.
double planeGapM(const Plane& in_a, const Eigen::Vector3d& point_a, const Plane& in_b,
                 const Eigen::Vector3d& point_b, const Eigen::Isometry3d& a_T_b);

}  // namespace board_calib
