// Stateful LiDAR board detector: board-like planes that stay put over the session are background.
#include "detector_internal.h"

#include <algorithm>
#include <cmath>

namespace board_calib {

using lidar_detail::failure;
using lidar_detail::kRadPerDeg;

LidarBoardTracker::LidarBoardTracker(Target target, LidarBoardDetectorOptions detector,
                                     StaticMemoryOptions memory)
    : target_(std::move(target)), detector_(std::move(detector)), memory_(memory) {}

void LidarBoardTracker::reset() {
  places_.clear();
  frames_ = 0;
  last_stamp_ = -1e300;
}

bool LidarBoardTracker::isStatic(const Place& p) const {
  return p.sightings.isStatic(memory_, frames_);
}

int LidarBoardTracker::numStaticPlaces() const {
  int n = 0;
  for (const auto& p : places_) n += isStatic(p);
  return n;
}

int LidarBoardTracker::match(const LidarBoardCandidate& c) const {
  const double min_cos = std::cos(memory_.max_normal_angle_deg * kRadPerDeg);
  int best = -1;
  double best_d = memory_.place_radius_m;
  for (size_t k = 0; k < places_.size(); ++k) {
    const double d = (places_[k].centroid - c.centroid).norm();
    if (d <= best_d && std::abs(places_[k].normal.dot(c.plane.normal)) >= min_cos) {
      best_d = d;
      best = static_cast<int>(k);
    }
  }
  return best;
}

LidarBoardDetection LidarBoardTracker::detect(const LidarCloud& cloud,
                                              const BackgroundModel* background) {
  if (!memory_.validate().empty()) {
    LidarBoardDetection det = detectLidarBoard(cloud, target_, detector_, background);
    if (det.features.found) return det;
    return failure(std::move(det), LidarDetectionCode::kInvalidOptions,
                   "invalid static memory options: " + memory_.validate());
  }
  if (cloud.stamp < last_stamp_) reset();  // a replay started over
  last_stamp_ = cloud.stamp;
  ++frames_;
  lidar_detail::History history;
  history.strict_ambiguity = memory_.strict_ambiguity;
  history.is_static = [this](const LidarBoardCandidate& c) {
    const int k = match(c);
    return k >= 0 && isStatic(places_[static_cast<size_t>(k)]);
  };
  LidarBoardDetection det =
      lidar_detail::detectImpl(cloud, target_, detector_, background, &history);
  // Remember every board-like candidate of this cloud (accepted, or dropped as static).
  for (const auto& c : det.candidates) {
    if (c.score < 0 && c.rejected_because.rfind("static", 0) != 0) continue;
    const int k = match(c);
    if (k < 0) {
      places_.push_back({c.centroid, c.plane.normal, PlaceSightings::start(cloud.stamp, frames_)});
    } else {
      // Two candidates of this cloud at one place count once.
      places_[static_cast<size_t>(k)].sightings.see(cloud.stamp, frames_);
    }
  }
  places_.erase(
      std::remove_if(places_.begin(), places_.end(),
                     [&](const Place& p) { return p.sightings.forgotten(memory_, cloud.stamp); }),
      places_.end());
  return det;
}

}  // namespace board_calib
