// Board features each detector produces and the solvers consume: the core mirror of the
// board_calib/LidarBoard and board_calib/CameraBoard messages.
//
// Edge naming (types.h EdgeIndex): UL, UR, LR, LL as the sensor sees the board held as a
// diamond. Corner j is the intersection of edge j and edge (j+1)%4: 0 top, 1 right, 2 bottom,
// 3 left. Planes follow types.h: normal away from the sensor, offset > 0.
#pragma once

#include <board_calib/core/types.h>

namespace board_calib {

template <typename V>
std::array<V, kNumEdges> zeroEdges() {
  std::array<V, kNumEdges> a;
  a.fill(V::Zero());
  return a;
}

struct LidarBoardFeatures {
  std::string frame_id;
  double stamp = 0.0;  ///< s
  bool found = false;
  std::string reason;                          ///< why not found, or doubts about a found board
  Plane plane;                                 ///< LiDAR frame
  double plane_rms_m = 0.0;                    ///< RMS distance of inliers to the plane
  Points3 board_points;                        ///< inliers on the board, LiDAR frame, m
  std::array<Points3, kNumEdges> edge_points;  ///< per-scan-line extremes assigned to each edge
  std::array<bool, kNumEdges> edge_valid{};    ///< enough edge points and a consistent line fit
  // Eigen leaves fixed-size members uninitialised: a producer that skips them must not hand on
  // whatever the memory held (the stillness judge reads the corners).
  std::array<Eigen::Vector3d, kNumEdges> edge_line_point = zeroEdges<Eigen::Vector3d>();
  std::array<Eigen::Vector3d, kNumEdges> edge_line_direction = zeroEdges<Eigen::Vector3d>();
  /// Edge-line intersections (valid if both edges are).
  std::array<Eigen::Vector3d, kNumEdges> corners = zeroEdges<Eigen::Vector3d>();
  Eigen::Vector2d measured_size_m = Eigen::Vector2d::Zero();  ///< side lengths from the corners

  bool allEdgesValid() const {
    return edge_valid[0] && edge_valid[1] && edge_valid[2] && edge_valid[3];
  }
};

/// One pattern point (checkerboard corner or AprilTag corner) seen in the image.
struct PatternObservation {
  int id = 0;                   ///< checkerboard: corner index; AprilTag: tag_id * 4 + corner
  Eigen::Vector3d board_point;  ///< board frame, m
  Eigen::Vector2d pixel;        ///< undistorted pixel
};

struct CameraBoardFeatures {
  std::string frame_id;
  double stamp = 0.0;  ///< s
  bool found = false;
  std::string reason;
  Eigen::Matrix3d K =
      Eigen::Matrix3d::Identity();        ///< intrinsics of the undistorted pixel coordinates
  int image_width = 0, image_height = 0;  ///< px
  Eigen::Isometry3d camera_T_board = Eigen::Isometry3d::Identity();
  Plane plane;  ///< camera frame
  /// Lines a*u + b*v + c = 0 in undistorted pixels, a^2 + b^2 = 1, (a, b) the outward normal
  /// (the board interior gives < 0).
  std::array<Eigen::Vector3d, kNumEdges> edge_lines = zeroEdges<Eigen::Vector3d>();
  std::array<bool, kNumEdges> edge_valid{};
  /// Undistorted px, may lie outside the image.
  std::array<Eigen::Vector2d, kNumEdges> corners_px = zeroEdges<Eigen::Vector2d>();
  std::vector<PatternObservation> pattern;
  double reprojection_rms_px = 0.0;

  bool allEdgesValid() const {
    return edge_valid[0] && edge_valid[1] && edge_valid[2] && edge_valid[3];
  }
};

/// Largest image side features may carry (the image conversions refuse larger ones).
constexpr int kMaxFeatureImageSidePx = 1 << 16;

/// Why found features cannot be used: a non-finite or inconsistent value, as a corrupted or
/// hostile message carries (the detectors never publish one). Empty when usable or not found.
std::string malformedFeatures(const LidarBoardFeatures& f);
std::string malformedFeatures(const CameraBoardFeatures& f);

/// One board pose seen by one camera and one LiDAR.
struct View {
  int id = 0;
  LidarBoardFeatures lidar;
  CameraBoardFeatures camera;
};

}  // namespace board_calib
