// Board points and plane gaps shared by the pairwise solver and the MSG graph.
#include <board_calib/core/common/board_geometry.h>

namespace board_calib {

Eigen::Vector3d boardPoint(const LidarBoardFeatures& f) {
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  int count = 0;
  for (const auto& p : f.board_points)
    if (p.allFinite()) {
      sum += p;
      ++count;
    }
  const Eigen::Vector3d c =
      count > 0 ? Eigen::Vector3d(sum / count) : Eigen::Vector3d(f.plane.offset * f.plane.normal);
  return c - f.plane.signedDistance(c) * f.plane.normal;
}

Eigen::Vector3d boardPoint(const CameraBoardFeatures& f) {
  Eigen::Vector3d c = f.camera_T_board.translation();
  if (!f.pattern.empty()) {
    // PnP on the pattern: its position is best determined at the points' centroid.
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    for (const auto& o : f.pattern) sum += f.camera_T_board * o.board_point;
    c = sum / static_cast<double>(f.pattern.size());
  } else {
    // PnP on the four outer corners: their centroid on the plane (rays through the image corners).
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    int count = 0;
    const Eigen::Matrix3d K_inv = f.K.inverse();
    for (const auto& px : f.corners_px) {
      const Eigen::Vector3d ray = K_inv * px.homogeneous();
      const double along = f.plane.normal.dot(ray);
      if (!ray.allFinite() || !(along > 0.0)) continue;
      sum += ray * (f.plane.offset / along);
      ++count;
    }
    if (count == kNumEdges) c = sum / count;
  }
  if (!c.allFinite()) c = f.plane.offset * f.plane.normal;
  return c - f.plane.signedDistance(c) * f.plane.normal;
}

double planeGapM(const Plane& in_a, const Eigen::Vector3d& point_a, const Plane& in_b,
                 const Eigen::Vector3d& point_b, const Eigen::Isometry3d& a_T_b) {
  const Eigen::Vector3d rnb = a_T_b.linear() * in_b.normal;
  const Eigen::Vector3d p = 0.5 * (point_a + a_T_b * point_b);
  return (in_a.normal.dot(p) - in_a.offset) - (rnb.dot(p - a_T_b.translation()) - in_b.offset);
}

}  // namespace board_calib
