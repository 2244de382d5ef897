// ROS-free LiDAR cloud: what the detectors and the simulator exchange. Built from a
// sensor_msgs/PointCloud2 by the conversions unit, or by the simulator.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace board_calib {

struct LidarPoint {
  float x = 0, y = 0, z = 0;  ///< m, LiDAR frame; NaN (or all zero) for no return
  float intensity = 0;
  int ring = -1;  ///< scan line (beam) index, -1 when the cloud has no ring field
};

struct LidarCloud {
  std::string frame_id;
  double stamp = 0.0;  ///< s
  int width = 0;       ///< organized: columns; unorganized: number of points
  int height = 1;      ///< organized: rings (> 1); unorganized: 1
  bool has_ring = false;
  bool has_intensity = false;
  std::vector<LidarPoint> points;  ///< row-major (row = ring for organized spinning LiDARs)

  bool organized() const { return height > 1; }
  size_t size() const { return points.size(); }
};

}  // namespace board_calib
