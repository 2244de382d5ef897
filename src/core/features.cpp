// Sanity of features that arrive from outside the process (topics, other producers): every
// consumer (capture, solvers, verdict) assumes finite values, unit normals and a camera matrix.
#include <board_calib/core/features.h>

#include <cmath>
#include <string>

namespace board_calib {
namespace {

// The detectors write unit vectors and rotations to double precision; a message built by hand
// in another language may round them, so a little slack.
constexpr double kUnitTolerance = 1e-3;
// Farther than any LiDAR reaches or any board is held: a corrupted coordinate.
constexpr double kMaxCoordinateM = 1e4;

bool unit(const Eigen::Vector3d& v) {
  return v.allFinite() && std::abs(v.norm() - 1.0) <= kUnitTolerance;
}

bool inReach(const Eigen::Vector3d& p) { return p.allFinite() && p.norm() <= kMaxCoordinateM; }

std::string firstOutOfReach(const Points3& points, const std::string& what) {
  for (const auto& p : points)
    if (!inReach(p)) return what + " holds a non-finite or absurd point";
  return {};
}

}  // namespace

std::string malformedFeatures(const LidarBoardFeatures& f) {
  if (!f.found) return {};
  if (!unit(f.plane.normal) || !std::isfinite(f.plane.offset))
    return "board plane normal not a finite unit vector or offset not finite";
  if (!(f.plane_rms_m >= 0.0) || !std::isfinite(f.plane_rms_m)) return "plane RMS not finite";
  if (f.board_points.empty()) return "a found board without board points";
  if (auto why = firstOutOfReach(f.board_points, "board points"); !why.empty()) return why;
  for (int j = 0; j < kNumEdges; ++j) {
    if (auto why = firstOutOfReach(f.edge_points[j], "edge points"); !why.empty()) return why;
    if (f.edge_valid[j] && (!inReach(f.edge_line_point[j]) || !unit(f.edge_line_direction[j])))
      return "a valid edge line with a non-finite point or a direction not of unit length";
  }
  // The stillness judge takes the board's centre from the corners of four valid edges: each must
  // lie on both its lines (corner j joins edge j and edge j + 1), to within 1 % of its range.
  if (f.allEdgesValid())
    for (int j = 0; j < kNumEdges; ++j) {
      const Eigen::Vector3d& c = f.corners[j];
      if (!inReach(c)) return "a corner between two valid edges is not finite or out of reach";
      for (int k : {j, (j + 1) % kNumEdges}) {
        const Eigen::Vector3d off = c - f.edge_line_point[k];
        const double distance =
            (off - off.dot(f.edge_line_direction[k]) * f.edge_line_direction[k]).norm();
        if (distance > 0.01 * c.norm() + 0.01)
          return "corner " + std::to_string(j) + " lies " + std::to_string(distance) +
                 " m off its edge line " + std::to_string(k);
      }
    }
  if (!f.measured_size_m.allFinite() || f.measured_size_m.minCoeff() < 0.0)
    return "measured board size not finite";
  return {};
}

std::string malformedFeatures(const CameraBoardFeatures& f) {
  if (!f.found) return {};
  const Eigen::Matrix3d& K = f.K;
  if (!K.allFinite() || !(K(0, 0) > 0.0) || !(K(1, 1) > 0.0) ||
      !K.row(2).isApprox(Eigen::RowVector3d(0.0, 0.0, 1.0), kUnitTolerance))
    return "camera matrix K not finite, focal lengths not positive or last row not 0 0 1";
  if (f.image_width < 1 || f.image_height < 1 || f.image_width > kMaxFeatureImageSidePx ||
      f.image_height > kMaxFeatureImageSidePx)
    return "image size " + std::to_string(f.image_width) + "x" + std::to_string(f.image_height) +
           " out of range";
  const Eigen::Matrix3d R = f.camera_T_board.linear();
  if (!f.camera_T_board.matrix().allFinite() || !inReach(f.camera_T_board.translation()) ||
      !(R.transpose() * R).isIdentity(kUnitTolerance) || !(R.determinant() > 0.0))
    return "board pose not finite or not a rotation";
  if (!unit(f.plane.normal) || !std::isfinite(f.plane.offset))
    return "board plane normal not a finite unit vector or offset not finite";
  for (int j = 0; j < kNumEdges; ++j) {
    if (!f.edge_valid[j]) continue;
    const Eigen::Vector3d& l = f.edge_lines[j];
    if (!l.allFinite() || std::abs(l.head<2>().norm() - 1.0) > kUnitTolerance)
      return "a valid edge line not finite or not normalised (a^2 + b^2 = 1)";
    if (f.edge_valid[(j + 1) % kNumEdges] && !f.corners_px[j].allFinite())
      return "a corner between valid edges not finite";
  }
  for (const auto& p : f.pattern)
    if (!p.board_point.allFinite() || !p.pixel.allFinite()) return "a pattern point not finite";
  if (!(f.reprojection_rms_px >= 0.0) || !std::isfinite(f.reprojection_rms_px))
    return "reprojection RMS not finite";
  return {};
}

}  // namespace board_calib
