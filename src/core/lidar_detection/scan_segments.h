// Sparse-board candidates from scan-line segments (private to the module). Far away a board is
// cut by a few scan lines spaced wider than any voxel: planes are grown from runs of returns
// along each scan line that stand in front of their surroundings, linked across adjacent lines.
// Also the sampling-aware board checks and the rectangle fit of the per-line extremes.
#pragma once

#include <board_calib/core/lidar_detection/lidar_cloud.h>

#include "geometry_2d.h"

#include <string>
#include <vector>

namespace board_calib {
namespace lidar_detail {

/// Scan line of every valid point: ring, organized row, or elevation clustering of the whole
/// cloud (a spinning LiDAR's beams have fixed elevations). Lines are numbered bottom-up by
/// elevation. `source` receives "ring", "row" or "elevation".
std::vector<int> scanLinesOf(const LidarCloud& cloud, const std::vector<int>& cloud_index,
                             const std::vector<Eigen::Vector3d>& points, double elevation_gap_rad,
                             std::string* source);

/// Elevation gap (rad) from each line (numbered bottom-up) to its nearer neighbour line.
std::vector<double> lineGaps(const std::vector<Eigen::Vector3d>& points,
                             const std::vector<int>& line);

struct SegmentOptions {
  double max_length_m = 2.0;    ///< longest segment chord that can lie on the board, m
  double max_rms_m = 0.03;      ///< straightness of a segment and flatness of a region, m
  double plane_band_m = 0.05;   ///< a segment joins a region within this of its plane, m
  double range_noise_m = 0.02;  ///< 1 sigma, m: range jumps below 4 sigma never split a run
  int min_lines = 3;            ///< scan lines a candidate needs
};

/// A planar candidate made of scan-line segments, with its sampling.
struct SegmentRegion {
  std::vector<int> points;       ///< indices into the valid points
  int lines = 0;                 ///< scan lines with a segment in the region
  double column_step_rad = 0.0;  ///< median azimuth step between neighbouring returns on a line
  double line_step_rad = 0.0;    ///< median elevation step between the region's lines
};

std::vector<SegmentRegion> segmentRegions(const std::vector<Eigen::Vector3d>& points,
                                          const std::vector<int>& line,
                                          const SegmentOptions& options);

/// The declared rectangle (width x height) fitted to the per-line extremes in a plane frame
/// (u right, v up): every board point inside it (within `inside_tol_m`), every extreme on its
/// boundary once moved out by its expected inset (along the scan direction u).
struct RectangleFit {
  bool ok = false;
  double angle = 0.0;  ///< rad, rotation of the width axis from u
  Eigen::Vector2d centre = Eigen::Vector2d::Zero();
  double rms_m = 0.0;                      ///< RMS boundary residual of the extremes, m
  double worst_outside_m = 0.0;            ///< largest distance of a board point outside, m
  std::array<Eigen::Vector2d, 4> corners;  ///< counter-clockwise
};
RectangleFit fitRectangle(const Points2& board, const Points2& extremes,
                          const std::vector<double>& insets, double width, double height,
                          double inside_tol_m);

}  // namespace lidar_detail
}  // namespace board_calib
