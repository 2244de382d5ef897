// SPDX-License-Identifier: BSD-3-Clause
// Simulator options: validation and the LiDAR presets.
#include <board_calib/core/sim/simulator.h>

#include "scene.h"

#include <algorithm>
#include <cmath>

namespace board_calib {
namespace sim {

using internal::kDegToRad;

std::string LidarSpec::validate() const {
  if (elevations_deg.empty()) return "LiDAR '" + name + "': elevations_deg is empty";
  for (double e : elevations_deg)
    if (!std::isfinite(e) || e <= -90 || e >= 90)
      return "LiDAR '" + name + "': elevation out of (-90, 90) deg";
  if (!azimuth_offsets_deg.empty() && azimuth_offsets_deg.size() != elevations_deg.size())
    return "LiDAR '" + name + "': azimuth_offsets_deg must be empty or have one entry per ring";
  if (!(horizontal_resolution_deg > 0.01) || horizontal_resolution_deg > 10)
    return "LiDAR '" + name + "': horizontal_resolution_deg must be in (0.01, 10]";
  if (!(range_noise_m >= 0)) return "LiDAR '" + name + "': range_noise_m must be >= 0";
  if (!(min_range_m >= 0) || !(max_range_m > min_range_m))
    return "LiDAR '" + name + "': need 0 <= min_range_m < max_range_m";
  if (!(dropout_probability >= 0) || dropout_probability > 1)
    return "LiDAR '" + name + "': dropout_probability must be in [0, 1]";
  if (!(beam_divergence_deg >= 0) || beam_divergence_deg > 5)
    return "LiDAR '" + name + "': beam_divergence_deg must be in [0, 5]";
  if (!(mixed_return_max_gap_m >= 0))
    return "LiDAR '" + name + "': mixed_return_max_gap_m must be >= 0";
  if (!(intensity_noise >= 0)) return "LiDAR '" + name + "': intensity_noise must be >= 0";
  if (!(rate_hz > 0)) return "LiDAR '" + name + "': rate_hz must be > 0";
  return {};
}

int LidarSpec::columns() const {
  return std::max(1, static_cast<int>(std::lround(360.0 / horizontal_resolution_deg)));
}

double LidarSpec::azimuthRad(int ring, int col) const {
  double az_deg = 180.0 - col * (360.0 / columns());
  if (!azimuth_offsets_deg.empty() && ring >= 0 &&
      ring < static_cast<int>(azimuth_offsets_deg.size()))
    az_deg += azimuth_offsets_deg[static_cast<size_t>(ring)];
  az_deg = std::remainder(az_deg, 360.0);
  return az_deg * kDegToRad;
}

std::string SceneSpec::validate() const {
  const std::string target_reason = target.validate();
  if (!target_reason.empty()) return "target: " + target_reason;
  if (room) {
    if (!(room_half_size_m > 0)) return "room_half_size_m must be > 0";
    if (!(ceiling_z_m > floor_z_m)) return "ceiling_z_m must be above floor_z_m";
  }
  if (outdoor) {
    if (!(street_half_width_m > 0)) return "street_half_width_m must be > 0";
    if (!(facade_distance_m > 0)) return "facade_distance_m must be > 0";
    if (!(ground_grey >= 0 && ground_grey <= 1)) return "ground_grey must be in [0, 1]";
  }
  if (!std::isfinite(board_intensity) || !std::isfinite(background_intensity) ||
      board_intensity < 0 || background_intensity < 0)
    return "intensities must be finite and >= 0";
  if (!(board_grey >= 0 && board_grey <= 1)) return "board_grey must be in [0, 1]";
  if (!board_tint.allFinite() || (board_tint.array() < 0).any())
    return "board_tint must be finite and >= 0";
  if (!(board_texture >= 0 && board_texture <= 0.5)) return "board_texture must be in [0, 0.5]";
  for (const auto& mark : board_marks)
    if (!mark.min.allFinite() || !mark.max.allFinite() ||
        !(mark.min.array() < mark.max.array()).all())
      return "board mark: min must be < max";
  if (panels.size() > 1000) return "at most 1000 panels";
  for (size_t k = 0; k < panels.size(); ++k) {
    const std::string why = panels[k].validate();
    if (!why.empty()) return "panel " + std::to_string(k) + ": " + why;
  }
  return {};
}

std::string Panel::validate() const {
  if (!(width_m > 0) || !(height_m > 0)) return "width_m and height_m must be > 0";
  if (!(grey >= 0 && grey <= 1)) return "grey must be in [0, 1]";
  if (!tint.allFinite() || (tint.array() < 0).any()) return "tint must be finite and >= 0";
  if (!std::isfinite(intensity) || intensity < 0) return "intensity must be finite and >= 0";
  if (!world_T_panel.matrix().allFinite()) return "pose must be finite";
  return {};
}

std::string RenderOptions::validate() const {
  if (supersampling < 1 || supersampling > 16) return "supersampling must be in [1, 16]";
  if (!(noise_sigma >= 0)) return "noise_sigma must be >= 0";
  if (!(vignetting >= 0) || vignetting > 1) return "vignetting must be in [0, 1]";
  if (!(blur_sigma_px >= 0)) return "blur_sigma_px must be >= 0";
  return {};
}

Expected<LidarSpec> lidarPreset(const std::string& name) {
  LidarSpec spec;
  spec.name = name;
  if (name == "VLP-16") {
    // Velodyne's ROS driver numbers rings bottom-up (ring 0 = -15 deg), 2 deg apart.
    for (int i = 0; i < 16; ++i) spec.elevations_deg.push_back(-15.0 + 2.0 * i);
    spec.horizontal_resolution_deg = 0.2;  // 600 rpm
    spec.range_noise_m = 0.015;
    spec.max_range_m = 100.0;
    spec.beam_divergence_deg = 0.17;
  } else if (name == "VLP-32C") {
    // Datasheet elevations, ascending (ring 0 = lowest beam, as the ROS driver numbers them).
    spec.elevations_deg = {-25.0,  -15.639, -11.31, -8.843, -7.254, -6.148, -5.333, -4.667,
                           -4.0,   -3.667,  -3.333, -3.0,   -2.667, -2.333, -2.0,   -1.667,
                           -1.333, -1.0,    -0.667, -0.333, 0.0,    0.333,  0.667,  1.0,
                           1.333,  1.667,   2.333,  3.333,  4.667,  7.0,    10.333, 15.0};
    spec.horizontal_resolution_deg = 0.2;
    spec.range_noise_m = 0.01;
    spec.max_range_m = 200.0;
    spec.beam_divergence_deg = 0.17;
  } else if (name == "OS1-64") {
    // Ouster numbers rings top-down (ring 0 = +16.6 deg), uniform over 33.2 deg; beams are
    // staggered in azimuth by a 4-periodic pattern.
    constexpr int kRings = 64;
    constexpr double kTop = 16.6, kFov = 33.2;
    const double stagger[4] = {3.164, 1.055, -1.055, -3.164};
    for (int i = 0; i < kRings; ++i) {
      spec.elevations_deg.push_back(kTop - kFov * i / (kRings - 1));
      spec.azimuth_offsets_deg.push_back(stagger[i % 4]);
    }
    spec.horizontal_resolution_deg = 360.0 / 1024;
    spec.range_noise_m = 0.02;
    spec.min_range_m = 0.8;
    spec.max_range_m = 120.0;
    spec.beam_divergence_deg = 0.13;
  } else {
    return Expected<LidarSpec>::failure("unknown LiDAR preset '" + name +
                                        "' (known: VLP-16, VLP-32C, OS1-64)");
  }
  return spec;
}

}  // namespace sim
}  // namespace board_calib
