// SPDX-License-Identifier: BSD-3-Clause
// LiDAR scans: each beam is a small bundle of sub-rays across its divergence footprint, which
// yields mixed returns where the footprint straddles the board's edge.
#include <board_calib/core/sim/simulator.h>

#include "scene.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace board_calib {
namespace sim {
namespace {

using internal::Hit;
using internal::kDegToRad;
using internal::kPi;
using internal::Scene;

// Sub-rays across the beam footprint: centre plus a ring of six at half the divergence.
constexpr int kFootprintRays = 7;

struct Footprint {
  double da[kFootprintRays] = {0}, de[kFootprintRays] = {0};  // rad, azimuth / elevation offsets
};

Footprint footprintOf(const LidarSpec& spec) {
  Footprint f;
  const double footprint_radius = 0.5 * spec.beam_divergence_deg * kDegToRad;
  for (int k = 1; k < kFootprintRays; ++k) {
    const double phi = 2 * kPi * (k - 1) / (kFootprintRays - 1);
    f.da[k] = footprint_radius * std::cos(phi);
    f.de[k] = footprint_radius * std::sin(phi);
  }
  return f;
}

Eigen::Vector3d beamDirection(double az, double el) {
  const double ce = std::cos(el);
  return Eigen::Vector3d(ce * std::cos(az), ce * std::sin(az), std::sin(el));
}

// One return from the footprint's hits (some valid): range and intensity before noise. Energy
// per sub-ray ~ reflectivity / r^2, clustered into board / not board.
ReturnOrigin mixReturn(const LidarSpec& spec, const Scene& world, const Hit* hits, int n_valid,
                       int n_board, double* range, double* intensity) {
  double e_board = 0, r_board = 0, i_board = 0, e_other = 0, r_other = 0, i_other = 0;
  for (int k = 0; k < kFootprintRays; ++k) {
    if (!hits[k].valid()) continue;
    const double refl = std::max(1.0, world.reflectivity(hits[k]));
    const double energy = refl / std::max(hits[k].t * hits[k].t, 1e-6);
    if (hits[k].board()) {
      e_board += energy;
      r_board += energy * hits[k].t;
      i_board += refl;
    } else {
      e_other += energy;
      r_other += energy * hits[k].t;
      i_other += refl;
    }
  }
  if (n_board == n_valid) {
    *range = r_board / e_board;
    *intensity = i_board / n_board;
    return ReturnOrigin::kBoard;
  }
  if (n_board == 0) {
    *range = r_other / e_other;
    *intensity = i_other / (n_valid - n_board);
    return ReturnOrigin::kBackground;
  }
  const double rb = r_board / e_board, ro = r_other / e_other;
  if (std::abs(rb - ro) <= spec.mixed_return_max_gap_m) {
    *range = (r_board + r_other) / (e_board + e_other);  // the receiver blends both echoes
  } else {
    *range = e_board >= e_other ? rb : ro;  // separate echoes: the strongest one wins
  }
  *intensity = (i_board + i_other) / n_valid;
  return ReturnOrigin::kMixed;
}

// The scan's random draws; one set per scan (the normal distribution keeps a spare draw).
struct BeamNoise {
  std::mt19937& rng;
  std::normal_distribution<double> range{0.0, 1.0};
  std::uniform_real_distribution<double> uniform{0.0, 1.0};
};

// One beam (ring, azimuth): the point in the LiDAR frame (NaN when nothing returns) and where
// its return came from.
ReturnOrigin castBeam(const LidarSpec& spec, const Scene& world,
                      const Eigen::Isometry3d& world_T_lidar, const Footprint& footprint, double az,
                      double el, BeamNoise& noise, LidarPoint* point) {
  Hit hits[kFootprintRays];
  int n_board = 0, n_valid = 0;
  for (int k = 0; k < kFootprintRays; ++k) {
    const Eigen::Vector3d d_lidar =
        beamDirection(az + footprint.da[k] / std::max(std::cos(el), 1e-6), el + footprint.de[k]);
    hits[k] = world.cast(world_T_lidar.translation(), world_T_lidar.linear() * d_lidar);
    if (hits[k].valid()) {
      ++n_valid;
      if (hits[k].board()) ++n_board;
    }
  }
  const bool dropped =
      spec.dropout_probability > 0 && noise.uniform(noise.rng) < spec.dropout_probability;
  if (n_valid == 0 || dropped) return ReturnOrigin::kNone;
  double range = 0, intensity = 0;
  const ReturnOrigin what = mixReturn(spec, world, hits, n_valid, n_board, &range, &intensity);
  range += spec.range_noise_m * noise.range(noise.rng);
  intensity += spec.intensity_noise * noise.range(noise.rng);
  if (range < spec.min_range_m || range > spec.max_range_m) return ReturnOrigin::kNone;
  const Eigen::Vector3d p = range * beamDirection(az, el);
  point->x = static_cast<float>(p.x());
  point->y = static_cast<float>(p.y());
  point->z = static_cast<float>(p.z());
  point->intensity = static_cast<float>(std::clamp(intensity, 0.0, 255.0));
  return what;
}

}  // namespace

LidarCloud simulateLidarScan(const LidarSpec& spec, const Eigen::Isometry3d& world_T_lidar,
                             const SceneSpec& scene, const Eigen::Isometry3d& world_T_board,
                             std::mt19937& rng) {
  return simulateLidarScan(spec, world_T_lidar, scene, world_T_board, rng, nullptr);
}

LidarCloud simulateLidarScan(const LidarSpec& spec, const Eigen::Isometry3d& world_T_lidar,
                             const SceneSpec& scene, const Eigen::Isometry3d& world_T_board,
                             std::mt19937& rng, std::vector<ReturnOrigin>* origins) {
  LidarCloud cloud;
  cloud.has_intensity = true;
  cloud.has_ring = spec.with_ring;
  if (origins) origins->clear();
  if (!spec.validate().empty() || !scene.validate().empty())
    return cloud;  // empty cloud: nothing sensible to cast

  const Scene world(scene, world_T_board);
  const int rings = static_cast<int>(spec.elevations_deg.size());
  const int cols = spec.columns();
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const Footprint footprint = footprintOf(spec);
  BeamNoise noise{rng};
  if (spec.organized) {
    cloud.width = cols;
    cloud.height = rings;
    cloud.points.resize(static_cast<size_t>(rings) * cols);
  }
  for (int ring = 0; ring < rings; ++ring) {
    const double el = spec.elevations_deg[static_cast<size_t>(ring)] * kDegToRad;
    for (int col = 0; col < cols; ++col) {
      LidarPoint point;
      point.x = point.y = point.z = nan;
      point.ring = spec.with_ring ? ring : -1;
      const ReturnOrigin what = castBeam(spec, world, world_T_lidar, footprint,
                                         spec.azimuthRad(ring, col), el, noise, &point);
      if (spec.organized) {
        cloud.points[static_cast<size_t>(ring) * cols + col] = point;
        if (origins) origins->push_back(what);
      } else if (what != ReturnOrigin::kNone) {
        cloud.points.push_back(point);
        if (origins) origins->push_back(what);
      }
    }
  }
  if (!spec.organized) {
    cloud.width = static_cast<int>(cloud.points.size());
    cloud.height = 1;
  }
  return cloud;
}

}  // namespace sim
}  // namespace board_calib
