// Groups per-sensor feature streams by stamp into board poses (see pose_grouping.h).
#include <board_calib/core/msg_graph/pose_grouping.h>

#include <algorithm>
#include <cmath>

namespace board_calib {
namespace multi_sensor {

namespace {

struct Event {
  double stamp = 0.0;
  int sensor = 0;
  bool camera = false;
  size_t index = 0;
};

}  // namespace

std::string GroupingOptions::validate() const {
  if (!(stamp_tolerance_s >= 0) || !std::isfinite(stamp_tolerance_s))
    return "stamp_tolerance_s must be >= 0";
  if (min_sensors < 2) return "min_sensors must be >= 2 (a board pose links sensors)";
  return "";
}

Expected<GroupingReport> groupByStamp(
    const std::vector<SensorSpec>& sensors,
    const std::map<int, std::vector<CameraBoardFeatures>>& cameras,
    const std::map<int, std::vector<LidarBoardFeatures>>& lidars, const GroupingOptions& options) {
  using Result = Expected<GroupingReport>;
  const std::string invalid = options.validate();
  if (!invalid.empty()) return Result::failure("invalid grouping options: " + invalid);
  const int n = static_cast<int>(sensors.size());
  std::vector<Event> events;
  for (const auto& [s, stream] : cameras) {
    if (s < 0 || s >= n)
      return Result::failure("camera stream keyed to unknown sensor " + std::to_string(s));
    if (sensors[s].kind != SensorKind::kCamera)
      return Result::failure("sensor '" + sensors[s].frame +
                             "' is a LiDAR but has a camera stream");
    for (size_t i = 0; i < stream.size(); ++i)
      if (stream[i].found && std::isfinite(stream[i].stamp))
        events.push_back({stream[i].stamp, s, true, i});
  }
  for (const auto& [s, stream] : lidars) {
    if (s < 0 || s >= n)
      return Result::failure("LiDAR stream keyed to unknown sensor " + std::to_string(s));
    if (sensors[s].kind != SensorKind::kLidar)
      return Result::failure("sensor '" + sensors[s].frame +
                             "' is a camera but has a LiDAR stream");
    for (size_t i = 0; i < stream.size(); ++i)
      if (stream[i].found && std::isfinite(stream[i].stamp))
        events.push_back({stream[i].stamp, s, false, i});
  }
  std::stable_sort(events.begin(), events.end(),
                   [](const Event& a, const Event& b) { return a.stamp < b.stamp; });
  GroupingReport report;
  report.features_in = static_cast<int>(events.size());
  size_t begin = 0;
  while (begin < events.size()) {
    const double anchor = events[begin].stamp;
    size_t end = begin;
    while (end < events.size() && events[end].stamp - anchor <= options.stamp_tolerance_s) ++end;
    // Per sensor, the feature closest to the anchor.
    std::map<int, const Event*> best;
    for (size_t i = begin; i < end; ++i) {
      const Event& e = events[i];
      auto it = best.find(e.sensor);
      if (it == best.end()) {
        best[e.sensor] = &e;
      } else {
        ++report.duplicates_dropped;
        if (std::abs(e.stamp - anchor) < std::abs(it->second->stamp - anchor)) it->second = &e;
      }
    }
    if (static_cast<int>(best.size()) >= options.min_sensors) {
      BoardPoseObservation pose;
      pose.id = static_cast<int>(report.poses.size());
      for (const auto& [s, e] : best) {
        if (e->camera)
          pose.cameras[s] = cameras.at(s)[e->index];
        else
          pose.lidars[s] = lidars.at(s)[e->index];
      }
      report.features_used += static_cast<int>(best.size());
      report.poses.push_back(std::move(pose));
    } else {
      ++report.groups_dropped;
    }
    begin = end;
  }
  return report;
}

}  // namespace multi_sensor
}  // namespace board_calib
