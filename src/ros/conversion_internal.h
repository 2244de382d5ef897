// SPDX-License-Identifier: BSD-3-Clause
// What the cloud, camera_info and image conversions share (private to src/ros): the size
// limits enforced before allocating, and the host byte order.
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstring>

namespace board_calib {
namespace conversion_internal {

// Limits far above any real sensor; they keep every later int index and allocation sane.
constexpr uint64_t kMaxCloudPoints = uint64_t(1)
                                     << 24;  ///< 16.7 M points (a 128-beam LiDAR sends ~0.3 M)
constexpr double kMaxRingIndex = 65535;      ///< ring fields are at most uint16 in practice
constexpr uint64_t kMaxImageSidePx = uint64_t(1)
                                     << 16;  ///< px per side; OpenCV and the detectors use int
constexpr uint64_t kMaxImageBytes =
    (uint64_t(1) << 31) - 1;                 ///< cv_bridge/OpenCV size their buffers with int
constexpr size_t kMaxDistortionCoeffs = 14;  ///< OpenCV's largest model

inline bool hostIsBigEndian() {
  const uint16_t probe = 1;
  uint8_t first = 0;
  std::memcpy(&first, &probe, 1);
  return first == 0;
}

}  // namespace conversion_internal
}  // namespace board_calib
