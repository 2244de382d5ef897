// Live multi-sensor session (see rig_session.h).
#include <board_calib/core/rig_session.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <iomanip>
#include <limits>
#include <sstream>

namespace board_calib {
namespace msg {
namespace {

constexpr double kDegPerRad = 180.0 / M_PI;
// A stamp this far behind the newest one means the source restarted (a bag looped).
constexpr double kTimeJumpBackS = 2.0;
constexpr size_t kMaxFeaturesPerStream = 100;

double angleDeg(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return std::acos(std::clamp(a.normalized().dot(b.normalized()), -1.0, 1.0)) * kDegPerRad;
}

std::string fixed(double v, int digits) {
  std::ostringstream os;
  os << std::fixed << std::setprecision(digits) << v;
  return os.str();
}

SessionEvent event(SessionEvent::Kind kind, std::string message, int id = -1) {
  SessionEvent e;
  e.kind = kind;
  e.message = std::move(message);
  e.view_id = id;
  return e;
}

// Accepted beats rejected beats waiting, and a later event beats an earlier one of its kind.
SessionEvent stronger(SessionEvent a, SessionEvent b) {
  auto rank = [](SessionEvent::Kind k) {
    return k == SessionEvent::Kind::kAccepted ? 2 : k == SessionEvent::Kind::kRejected ? 1 : 0;
  };
  return rank(b.kind) >= rank(a.kind) ? b : a;
}

template <typename F>
const F* closestWithin(const std::vector<F>& features, double stamp, double tolerance) {
  const F* best = nullptr;
  for (const auto& f : features)
    if (std::abs(f.stamp - stamp) <= tolerance && (!best || std::abs(f.stamp - stamp) < std::abs(best->stamp - stamp)))
      best = &f;
  return best;
}

}  // namespace

std::string RigSessionOptions::validate() const {
  if (!(stamp_tolerance_s > 0.0)) return "stamp_tolerance_s must be > 0";
  if (still_frames_required < 1) return "still_frames_required must be >= 1";
  if (!(still_max_translation_m > 0.0) || !(still_max_rotation_deg > 0.0))
    return "still_max_translation_m and still_max_rotation_deg must be > 0";
  if (!(still_max_gap_s > 0.0)) return "still_max_gap_s must be > 0";
  if (min_pose_rotation_deg < 0.0 || min_pose_translation_m < 0.0) return "min_pose_* must be >= 0";
  if (min_sensors < 2) return "min_sensors must be >= 2 (a pose links sensors)";
  if (max_poses < 1) return "max_poses must be >= 1";
  if (history_s < 2.0 * stamp_tolerance_s) return "history_s must be at least twice stamp_tolerance_s";
  return "";
}

RigSessionOptions rigSessionOptionsFor(const RigConfig& rig) {
  RigSessionOptions o;
  o.stamp_tolerance_s = rig.stamp_tolerance_s;
  o.history_s = std::max(o.history_s, 2.0 * o.stamp_tolerance_s);
  return o;
}

RigSession::RigSession(std::vector<std::string> names, std::vector<SensorSpec> sensors, RigSessionOptions options)
    : names_(std::move(names)), sensors_(std::move(sensors)), options_(options) {
  names_.resize(sensors_.size());
  for (size_t i = 0; i < names_.size(); ++i)
    if (names_[i].empty()) names_[i] = sensors_[i].frame;
  streams_.resize(sensors_.size());
  counts_.resize(sensors_.size());
}

SessionEvent RigSession::addCamera(int sensor, const CameraBoardFeatures& f) {
  if (sensor < 0 || sensor >= static_cast<int>(sensors_.size()) || sensors_[sensor].kind != SensorKind::kCamera)
    return event(SessionEvent::Kind::kRejected, "camera features given for sensor " + std::to_string(sensor) +
                                                    ", which is not a camera of this rig");
  return add(sensor, f.stamp, summarize(f), f.frame_id, f.reason, [&](Stream& st) {
    if (st.cameras.empty() || f.stamp >= st.cameras.back().stamp) st.cameras.push_back(f);
  });
}

SessionEvent RigSession::addLidar(int sensor, const LidarBoardFeatures& f) {
  if (sensor < 0 || sensor >= static_cast<int>(sensors_.size()) || sensors_[sensor].kind != SensorKind::kLidar)
    return event(SessionEvent::Kind::kRejected, "LiDAR features given for sensor " + std::to_string(sensor) +
                                                    ", which is not a LiDAR of this rig");
  return add(sensor, f.stamp, summarize(f), f.frame_id, f.reason, [&](Stream& st) {
    if (st.lidars.empty() || f.stamp >= st.lidars.back().stamp) st.lidars.push_back(f);
  });
}

SessionEvent RigSession::add(int sensor, double stamp, const std::optional<Summary>& summary,
                             const std::string& frame, const std::string& reason,
                             const std::function<void(Stream&)>& keep) {
  const bool found = summary.has_value();  // the board seen, with a usable summary
  SessionEvent result = event(SessionEvent::Kind::kWaiting, "waiting for the board to be held still");
  if (!std::isfinite(stamp)) return event(SessionEvent::Kind::kRejected, names_[sensor] + ": non-finite stamp");
  RigSensorCounts& count = counts_[sensor];
  if (count.messages > 0 && stamp < count.newest_stamp - kTimeJumpBackS) {
    // This sensor's time went back: the source restarted (a bag looped). Keep the poses, forget
    // the streams (their stamps no longer compare). Judged per sensor, so a sensor whose clock
    // is offset from the others' does not look like a restart.
    result = stronger(result, flush());
    for (auto& st : streams_) st = Stream{};
    for (auto& c : counts_) c.newest_stamp = -std::numeric_limits<double>::infinity();
  }
  ++count.messages;
  count.board_now = found;
  if (!found) count.last_reason = reason;
  count.newest_stamp = std::max(count.newest_stamp, stamp);
  Stream& st = streams_[sensor];
  if (found) keep(st);
  if (pending_ && readyToAssemble(*pending_)) {
    const Pending p = *pending_;
    pending_.reset();
    result = stronger(result, assemble(p));
  }

  if (!found) {
    st.still_count = 0;
    st.triggered_this_still = false;
    st.last.reset();
    prune();
    return result;
  }
  ++count.found;
  if (!frame.empty()) sensors_[sensor].frame = frame;

  const bool consecutive = st.last && stamp - st.last_stamp <= options_.still_max_gap_s && stamp >= st.last_stamp;
  const bool still = consecutive && (summary->centre - st.last->centre).norm() <= options_.still_max_translation_m &&
                     angleDeg(summary->normal, st.last->normal) <= options_.still_max_rotation_deg;
  st.still_count = still ? st.still_count + 1 : 1;
  if (!still) st.triggered_this_still = false;
  st.last = summary;
  st.last_stamp = stamp;

  if (options_.auto_capture && !pending_ && !st.triggered_this_still &&
      st.still_count >= options_.still_frames_required) {
    st.triggered_this_still = true;
    int seen_pose = -1;
    if (seenBefore(sensor, *summary, &seen_pose)) {
      result = stronger(result, event(SessionEvent::Kind::kWaiting,
                                      names_[sensor] + " already saw this board pose (pose " +
                                          std::to_string(seen_pose) + "): move or tilt the board"));
    } else {
      pending_ = Pending{sensor, stamp,
                         "auto: " + names_[sensor] + " saw the board still for " + std::to_string(st.still_count) +
                             " frames"};
      if (readyToAssemble(*pending_)) {
        const Pending p = *pending_;
        pending_.reset();
        result = stronger(result, assemble(p));
      }
    }
  }
  prune();
  return result;
}

bool RigSession::readyToAssemble(const Pending& p) const {
  // Every stream that can still contribute has moved past the window. A stream far from the
  // trigger stamp (silent for a while, or offset clock) cannot and is not waited for; the
  // trigger's own stream moving on by history_s ends any wait.
  if (counts_[p.sensor].newest_stamp > p.stamp + options_.history_s) return true;
  for (size_t k = 0; k < counts_.size(); ++k) {
    const double newest = counts_[k].newest_stamp;
    if (counts_[k].messages == 0 || !std::isfinite(newest) || std::abs(newest - p.stamp) > options_.history_s) continue;
    if (newest <= p.stamp + options_.stamp_tolerance_s) return false;
  }
  return true;
}

bool RigSession::seenBefore(int sensor, const Summary& s, int* pose_id) const {
  for (const auto& p : poses_) {
    const auto seen = summaryOf(sensor, p.observation);
    if (!seen) continue;
    if (angleDeg(seen->normal, s.normal) < options_.min_pose_rotation_deg &&
        (seen->centre - s.centre).norm() < options_.min_pose_translation_m) {
      *pose_id = p.observation.id;
      return true;
    }
  }
  return false;
}

std::optional<RigSession::Summary> RigSession::summarize(const CameraBoardFeatures& f) {
  if (!f.found) return std::nullopt;
  return Summary{f.camera_T_board.translation(), f.plane.normal};
}

std::optional<RigSession::Summary> RigSession::summarize(const LidarBoardFeatures& f) {
  if (!f.found || f.board_points.empty()) return std::nullopt;
  Eigen::Vector3d c = Eigen::Vector3d::Zero();
  for (const auto& p : f.board_points) c += p;
  return Summary{c / static_cast<double>(f.board_points.size()), f.plane.normal};
}

std::optional<RigSession::Summary> RigSession::summaryOf(int sensor, const BoardPoseObservation& o) const {
  if (auto it = o.cameras.find(sensor); it != o.cameras.end()) return summarize(it->second);
  if (auto it = o.lidars.find(sensor); it != o.lidars.end()) return summarize(it->second);
  return std::nullopt;
}

SessionEvent RigSession::assemble(const Pending& pending) {
  BoardPoseObservation o;
  std::string seen_by;
  for (size_t k = 0; k < sensors_.size(); ++k) {
    const Stream& st = streams_[k];
    const int key = static_cast<int>(k);
    bool has = false;
    if (sensors_[k].kind == SensorKind::kCamera) {
      if (const auto* f = closestWithin(st.cameras, pending.stamp, options_.stamp_tolerance_s)) {
        o.cameras[key] = *f;
        has = true;
      }
    } else if (const auto* f = closestWithin(st.lidars, pending.stamp, options_.stamp_tolerance_s)) {
      o.lidars[key] = *f;
      has = true;
    }
    if (has) seen_by += (seen_by.empty() ? "" : ", ") + names_[k];
  }
  const int sensors_seen = static_cast<int>(o.cameras.size() + o.lidars.size());
  if (sensors_seen < options_.min_sensors)
    return event(SessionEvent::Kind::kRejected,
                 "board pose at t=" + fixed(pending.stamp, 2) + " s seen by " + std::to_string(sensors_seen) +
                     " sensor(s) (" + (seen_by.empty() ? "none" : seen_by) + "); a pose needs " +
                     std::to_string(options_.min_sensors) + " (check the other detectors and stamp_tolerance)");
  if (static_cast<int>(poses_.size()) >= options_.max_poses)
    return event(SessionEvent::Kind::kRejected,
                 "already " + std::to_string(poses_.size()) + " poses (max_poses): solve, or drop poses first");
  o.id = next_id_++;
  RigSessionPose p;
  p.observation = std::move(o);
  p.why = pending.why + "; seen by " + seen_by;
  poses_.push_back(p);
  return event(SessionEvent::Kind::kAccepted, "pose " + std::to_string(p.observation.id) + " (" + p.why + ")",
               p.observation.id);
}

void RigSession::prune() {
  // Per stream, relative to its own newest stamp (clocks of different sensors may be offset);
  // whatever a pending capture may still take is kept.
  for (size_t k = 0; k < streams_.size(); ++k) {
    Stream& st = streams_[k];
    double keep_from = counts_[k].newest_stamp - options_.history_s;
    if (pending_) keep_from = std::min(keep_from, pending_->stamp - options_.stamp_tolerance_s);
    auto old_camera = [&](const CameraBoardFeatures& f) { return f.stamp < keep_from; };
    auto old_lidar = [&](const LidarBoardFeatures& f) { return f.stamp < keep_from; };
    st.cameras.erase(std::remove_if(st.cameras.begin(), st.cameras.end(), old_camera), st.cameras.end());
    st.lidars.erase(std::remove_if(st.lidars.begin(), st.lidars.end(), old_lidar), st.lidars.end());
    if (st.cameras.size() > kMaxFeaturesPerStream)
      st.cameras.erase(st.cameras.begin(), st.cameras.end() - kMaxFeaturesPerStream);
    if (st.lidars.size() > kMaxFeaturesPerStream)
      st.lidars.erase(st.lidars.begin(), st.lidars.end() - kMaxFeaturesPerStream);
  }
}

SessionEvent RigSession::flush() {
  if (!pending_) return event(SessionEvent::Kind::kWaiting, "no capture pending");
  const Pending p = *pending_;
  pending_.reset();
  return assemble(p);
}

SessionEvent RigSession::captureNow() {
  if (pending_) return flush();
  int sensor = -1;
  double stamp = -1e300;
  for (size_t k = 0; k < streams_.size(); ++k) {
    const Stream& st = streams_[k];
    const double s = sensors_[k].kind == SensorKind::kCamera ? (st.cameras.empty() ? -1e300 : st.cameras.back().stamp)
                                                             : (st.lidars.empty() ? -1e300 : st.lidars.back().stamp);
    if (s > stamp) {
      stamp = s;
      sensor = static_cast<int>(k);
    }
  }
  if (sensor < 0)
    return event(SessionEvent::Kind::kRejected, "no sensor has seen the board recently: nothing to capture");
  return assemble(Pending{sensor, stamp, "manual capture at " + names_[sensor] + "'s newest board"});
}

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
  if (c.messages == 0) return names_[k] + ": no board features received (is its detector running and publishing?)";
  if (c.found == 0)
    return names_[k] + ": never saw the board in " + std::to_string(c.messages) + " messages" +
           (c.last_reason.empty() ? "" : " (last: " + c.last_reason + ")");
  if (c.found < kFoundButUnused || poses_.empty()) return "";
  // Offset of its newest stamp to the newest stamp of any other sensor.
  double other = -std::numeric_limits<double>::infinity();
  for (size_t j = 0; j < counts_.size(); ++j)
    if (j != k && counts_[j].messages > 0) other = std::max(other, counts_[j].newest_stamp);
  std::string offset;
  if (std::isfinite(other) && std::isfinite(c.newest_stamp))
    offset = ", its newest stamp is " + fixed(c.newest_stamp - other, 3) + " s from the others'";
  return names_[k] + ": saw the board in " + std::to_string(c.found) + " frames but is in none of the " +
         std::to_string(poses_.size()) + " poses: its stamps may be offset from the other sensors" + offset +
         " (stamp_tolerance_s " + fixed(options_.stamp_tolerance_s, 3) + " s)";
}

std::vector<std::string> RigSession::problems() const {
  std::vector<std::string> out;
  const std::vector<int> in_poses = posesPerSensor();
  for (size_t k = 0; k < sensors_.size(); ++k)
    if (in_poses[k] == 0)
      if (std::string why = whyNoPose(k); !why.empty()) out.push_back(std::move(why));
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
      out[k].why_no_pose = names_[k] + ": saw the board in " + std::to_string(counts_[k].found) +
                           " frames, none of them in a captured pose yet (hold the board still where it and "
                           "another sensor see it)";
  }
  return out;
}

MsgProblem RigSession::problem(int reference_sensor) const {
  MsgProblem p;
  p.sensors = sensors_;
  p.reference_sensor = reference_sensor;
  for (const auto& pose : poses_) p.poses.push_back(pose.observation);
  return p;
}

Status RigSession::dropPose(int id) {
  for (auto it = poses_.begin(); it != poses_.end(); ++it)
    if (it->observation.id == id) {
      poses_.erase(it);
      return Status::success();
    }
  return Status::failure("no pose with id " + std::to_string(id));
}

void RigSession::reset() {
  poses_.clear();
  for (auto& st : streams_) st = Stream{};
  pending_.reset();
  for (auto& c : counts_) c.newest_stamp = -std::numeric_limits<double>::infinity();
  next_id_ = 0;
}

}  // namespace msg
}  // namespace board_calib
