// Rig session health (see rig_session.h): which sensors take part in the captured poses and,
// for those that do not, why in words (for diagnostics, the panel and the report).
#include <board_calib/core/common/format.h>
#include <board_calib/core/rig/rig_session.h>

#include <algorithm>
#include <cmath>
#include <limits>

namespace board_calib {
namespace multi_sensor {
std::vector<int> RigSession::posesPerSensor() const {
  std::vector<int> n(sensors_.size(), 0);
  for (const auto& p : poses_) {
    for (const auto& c : p.observation.cameras) ++n[c.first];
    for (const auto& l : p.observation.lidars) ++n[l.first];
  }
  return n;
}

std::string RigSession::whyNoPose(size_t k) const {
  // A sensor with the board in this many frames but in no pose is not a matter of bad luck.
  constexpr int kFoundButUnused = 5;
  const RigSensorCounts& c = counts_[k];
  if (c.messages == 0)
    return names_[k] + ": no board features received (is its detector running and publishing?)";
  if (c.found == 0)
    return names_[k] + ": never saw the board in " + std::to_string(c.messages) + " messages" +
           (c.last_reason.empty() ? "" : " (last: " + c.last_reason + ")");
  if (c.found < kFoundButUnused || poses_.empty()) return "";
  if (c.lost_at_capture > 0)
    return names_[k] + ": saw the board in " + std::to_string(c.found) + " of " +
           std::to_string(c.messages) + " frames but lost it around every still moment (left " +
           "out of " + std::to_string(c.lost_at_capture) +
           " captured pose(s) for it): is the board at the edge of its view?";
  // Offset of its newest stamp to the newest stamp of any other sensor.
  double other = -std::numeric_limits<double>::infinity();
  for (size_t j = 0; j < counts_.size(); ++j)
    if (j != k && counts_[j].messages > 0) other = std::max(other, counts_[j].newest_stamp);
  std::string offset;
  if (std::isfinite(other) && std::isfinite(c.newest_stamp))
    offset =
        ", its newest stamp is " + formatFixed(c.newest_stamp - other, 3) + " s from the others'";
  return names_[k] + ": saw the board in " + std::to_string(c.found) +
         " frames but is in none of the " + std::to_string(poses_.size()) +
         " poses: its stamps may be offset from the other sensors" + offset +
         " (stamp_tolerance_s " + formatFixed(options_.stamp_tolerance_s, 3) + " s)";
}

std::string RigSession::whySilent(size_t k) const {
  // Silent for longer than the wait for a late stream and than a few of its own intervals: it
  // stopped (a driver died, its topic's recording ended) while the others went on.
  const double silent = silentFor(k);
  if (counts_[k].messages == 0 ||
      !(silent > std::max(options_.history_s, 3.0 * streams_[k].clock.typicalInterval())))
    return "";
  return names_[k] + ": no message for the last " + formatFixed(silent, 1) +
         " s of the other sensors' stream (its driver, topic or recording stopped?): board "
         "poses after that lack it";
}

std::vector<std::string> RigSession::problems() const {
  std::vector<std::string> out;
  const std::vector<int> in_poses = posesPerSensor();
  for (size_t k = 0; k < sensors_.size(); ++k) {
    if (std::string why = whySilent(k); !why.empty()) out.push_back(std::move(why));
    if (in_poses[k] == 0)
      if (std::string why = whyNoPose(k); !why.empty()) out.push_back(std::move(why));
  }
  return out;
}

std::vector<RigSensorHealth> RigSession::health() const {
  std::vector<RigSensorHealth> out(sensors_.size());
  for (size_t k = 0; k < sensors_.size(); ++k) {
    out[k].name = names_[k];
    out[k].frame = sensors_[k].frame;
    out[k].counts = counts_[k];
  }
  for (const auto& p : poses_) {
    for (const auto& c : p.observation.cameras) out[c.first].pose_ids.push_back(p.observation.id);
    for (const auto& l : p.observation.lidars) out[l.first].pose_ids.push_back(p.observation.id);
  }
  for (size_t k = 0; k < out.size(); ++k) {
    if (!out[k].pose_ids.empty()) continue;
    out[k].why_no_pose = whyNoPose(k);
    if (out[k].why_no_pose.empty())
      out[k].why_no_pose =
          names_[k] + ": saw the board in " + std::to_string(counts_[k].found) +
          " frames, none of them in a captured pose yet (hold the board still where it and "
          "another sensor see it)";
  }
  return out;
}
}  // namespace multi_sensor
}  // namespace board_calib
