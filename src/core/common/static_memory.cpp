#include <board_calib/core/common/static_memory.h>

namespace board_calib {

std::string StaticMemoryOptions::validate() const {
  if (!(place_radius_m > 0.0)) return "place_radius_m must be > 0";
  if (!(max_normal_angle_deg > 0.0 && max_normal_angle_deg <= 90.0))
    return "max_normal_angle_deg must be in (0, 90]";
  if (!(static_after_s > 0.0)) return "static_after_s must be > 0";
  if (!(min_seen_fraction >= 0.0 && min_seen_fraction <= 1.0))
    return "min_seen_fraction must be in [0, 1]";
  if (!(forget_after_s > 0.0)) return "forget_after_s must be > 0";
  return {};
}

PlaceSightings PlaceSightings::start(double stamp, long frame) {
  PlaceSightings p;
  p.first_s = p.last_s = stamp;
  p.first_frame = p.last_frame = frame;
  p.seen = 1;
  return p;
}

bool PlaceSightings::see(double stamp, long frame) {
  if (last_frame == frame) return false;
  last_s = stamp;
  last_frame = frame;
  ++seen;
  return true;
}

bool PlaceSightings::isStatic(const StaticMemoryOptions& o, long frame) const {
  const long frames_since = frame - first_frame + 1;
  return last_s - first_s >= o.static_after_s &&
         seen >= o.min_seen_fraction * static_cast<double>(frames_since);
}

}  // namespace board_calib
