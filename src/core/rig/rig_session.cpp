// Live multi-sensor session (see rig_session.h).
#include <board_calib/core/common/format.h>
#include <board_calib/core/rig/rig_session.h>
#include <board_calib/core/transform.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>
#include <sstream>

namespace board_calib {
namespace multi_sensor {
namespace {

constexpr size_t kMaxFeaturesPerStream = 100;
// Stillness samples per stream: history_s of a 20 Hz LiDAR with room to spare.
constexpr size_t kMaxSamplesPerStream = 400;
constexpr double kNever = -std::numeric_limits<double>::infinity();  // no stamp yet

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
    if (std::abs(f.stamp - stamp) <= tolerance &&
        (!best || std::abs(f.stamp - stamp) < std::abs(best->stamp - stamp)))
      best = &f;
  return best;
}

}  // namespace

std::string RigSessionOptions::validate() const {
  if (!(stamp_tolerance_s > 0.0) || !std::isfinite(stamp_tolerance_s))
    return "stamp_tolerance_s must be finite and > 0";
  if (auto why = stillness().validate(); !why.empty()) return why;
  if (!(min_pose_rotation_deg >= 0.0) || !(min_pose_translation_m >= 0.0))
    return "min_pose_* must be >= 0";
  if (min_sensors < 2) return "min_sensors must be >= 2 (a pose links sensors)";
  if (max_poses < 1) return "max_poses must be >= 1";
  if (!(history_s >= 2.0 * std::max(stamp_tolerance_s, still_window_s)) ||
      !std::isfinite(history_s))
    return "history_s must be at least twice stamp_tolerance_s and still_window_s";
  return "";
}

RigSessionOptions rigSessionOptionsFor(const RigConfig& rig) {
  RigSessionOptions o;
  o.stamp_tolerance_s = rig.stamp_tolerance_s;
  o.history_s = std::max(o.history_s, 2.0 * o.stamp_tolerance_s);
  return o;
}

RigSession::RigSession(std::vector<std::string> names, std::vector<SensorSpec> sensors,
                       RigSessionOptions options, std::optional<Target> target)
    : names_(std::move(names)),
      sensors_(std::move(sensors)),
      options_(options),
      target_(std::move(target)) {
  names_.resize(sensors_.size());
  for (size_t i = 0; i < names_.size(); ++i)
    if (names_[i].empty()) names_[i] = sensors_[i].frame;
  streams_.resize(sensors_.size());
  counts_.resize(sensors_.size());
  newest_when_heard_.assign(sensors_.size(), std::vector<double>(sensors_.size(), kNever));
}

SessionEvent RigSession::addCamera(int sensor, const CameraBoardFeatures& f) {
  if (sensor < 0 || sensor >= static_cast<int>(sensors_.size()) ||
      sensors_[sensor].kind != SensorKind::kCamera)
    return event(SessionEvent::Kind::kRejected, "camera features given for sensor " +
                                                    std::to_string(sensor) +
                                                    ", which is not a camera of this rig");
  const std::string malformed = malformedFeatures(f);
  BoardSample sample = boardSampleOf(f, target_ ? &*target_ : nullptr);  // not found if malformed
  sample.found = sample.found && summarize(f).has_value();
  const std::string reason = malformed.empty() ? f.reason : "malformed features: " + malformed;
  return add(sensor, f.stamp, sample, f.frame_id, reason, [&](Stream& st) {
    if (st.cameras.empty() || f.stamp >= st.cameras.back().stamp) st.cameras.push_back(f);
  });
}

SessionEvent RigSession::addLidar(int sensor, const LidarBoardFeatures& f) {
  if (sensor < 0 || sensor >= static_cast<int>(sensors_.size()) ||
      sensors_[sensor].kind != SensorKind::kLidar)
    return event(SessionEvent::Kind::kRejected, "LiDAR features given for sensor " +
                                                    std::to_string(sensor) +
                                                    ", which is not a LiDAR of this rig");
  const std::string malformed = malformedFeatures(f);
  BoardSample sample = boardSampleOf(f);  // not found if malformed
  sample.found = sample.found && summarize(f).has_value();
  const std::string reason = malformed.empty() ? f.reason : "malformed features: " + malformed;
  return add(sensor, f.stamp, sample, f.frame_id, reason, [&](Stream& st) {
    if (st.lidars.empty() || f.stamp >= st.lidars.back().stamp) st.lidars.push_back(f);
  });
}

SessionEvent RigSession::add(int sensor, double stamp, const BoardSample& sample,
                             const std::string& frame, const std::string& reason,
                             const std::function<void(Stream&)>& keep) {
  if (!std::isfinite(stamp))
    return event(SessionEvent::Kind::kRejected, names_[sensor] + ": non-finite stamp");
  SessionEvent result =
      event(SessionEvent::Kind::kWaiting, "waiting for the board to be held still");
  RigSensorCounts& count = counts_[sensor];
  if (count.messages > 0 && stamp < count.newest_stamp - kStreamTimeJumpBackS) {
    // This sensor's time went back: the source restarted (a bag looped). Keep the poses, forget
    // the streams (their stamps no longer compare). Judged per sensor, so a sensor whose clock
    // is offset from the others' does not look like a restart.
    result = stronger(result, flush());
    for (auto& st : streams_) st = Stream{};
    for (auto& c : counts_) c.newest_stamp = kNever;
    for (auto& heard : newest_when_heard_) std::fill(heard.begin(), heard.end(), kNever);
    hold_pose_id_ = -1;
  }
  ++count.messages;
  count.board_now = sample.found;
  count.newest_stamp = std::max(count.newest_stamp, stamp);
  for (size_t j = 0; j < counts_.size(); ++j)
    newest_when_heard_[sensor][j] = counts_[j].newest_stamp;
  Stream& st = streams_[sensor];
  if (!st.samples.empty() && stamp < st.samples.back().stamp)
    return result;  // out of order: not judged
  st.samples.push_back(sample);
  st.clock.add(stamp);
  if (!sample.found) {
    count.last_reason = reason;
  } else {
    ++count.found;
    if (!frame.empty()) sensors_[sensor].frame = frame;
    keep(st);
    // Every found frame is a candidate moment; the best moment of a hold (most sensors,
    // closest stamps) ends up as its pose.
    if (options_.auto_capture) {
      auto at = std::upper_bound(candidates_.begin(), candidates_.end(), stamp,
                                 [](double t, const Candidate& c) { return t < c.stamp; });
      candidates_.insert(at, Candidate{sensor, stamp});
    }
  }
  result = stronger(result, decideCandidates(false));
  prune();
  return result;
}

double RigSession::silentFor(size_t k) const {
  double silent = 0.0;
  for (size_t j = 0; j < counts_.size(); ++j)
    if (j != k && std::isfinite(counts_[j].newest_stamp) && std::isfinite(newest_when_heard_[k][j]))
      silent = std::max(silent, counts_[j].newest_stamp - newest_when_heard_[k][j]);
  return silent;
}

bool RigSession::readyToJudge(const Candidate& c) const {
  // Every stream that can still contribute has passed the still window (and the stamp
  // tolerance). A stream far from the moment (an offset clock) or one the others have gone on
  // without for history_s (it stopped: a driver died, a topic's recording ended) cannot and is
  // not waited for, even when it is the candidate's own; the candidate's own stream moving on
  // by history_s ends any wait.
  const double reach = std::max(options_.still_window_s, options_.stamp_tolerance_s);
  if (counts_[c.sensor].newest_stamp > c.stamp + options_.history_s) return true;
  for (size_t k = 0; k < counts_.size(); ++k) {
    const double newest = counts_[k].newest_stamp;
    if (counts_[k].messages == 0 || !std::isfinite(newest) ||
        std::abs(newest - c.stamp) > options_.history_s || silentFor(k) > options_.history_s)
      continue;
    if (newest < c.stamp + reach) return false;
  }
  return true;
}

SessionEvent RigSession::decideCandidates(bool ended) {
  SessionEvent result =
      event(SessionEvent::Kind::kWaiting, candidates_.empty() ? "waiting for a board to capture"
                                                              : "waiting for the still window");
  while (!candidates_.empty() && (ended || readyToJudge(candidates_.front()))) {
    const Candidate c = candidates_.front();
    candidates_.pop_front();
    result = stronger(result, decide(c));
  }
  return result;
}

SessionEvent RigSession::skip(const std::string& kind, const std::string& why) {
  stats_.skipped[kind]++;
  stats_.last_why[kind] = why;
  return event(SessionEvent::Kind::kRejected, why);
}

SessionEvent RigSession::decide(const Candidate& c) {
  // The streams that see the board around the moment are judged; the others count only for
  // the snapshot rule (a sensor the board is outside of says nothing about its motion).
  std::vector<StillnessStream> streams;
  for (size_t k = 0; k < streams_.size(); ++k) {
    const Stream& st = streams_[k];
    const BoardSample* nearest = nullptr;
    for (const auto& x : st.samples)
      if (std::abs(x.stamp - c.stamp) <= options_.still_window_s &&
          (!nearest || std::abs(x.stamp - c.stamp) < std::abs(nearest->stamp - c.stamp)))
        nearest = &x;
    streams.push_back({&st.samples, &st.clock, names_[k], nearest && nearest->found});
  }
  // A sensor that lost the board around the moment (the board at the edge of its view) is left
  // out of this pose; the others may still hold it still.
  std::set<int> lost;
  std::string lost_why;
  StillnessJudgement judged = judgeStillness(streams, c.stamp, options_.stillness(), true);
  while (judged.state == StillState::kNoBoard && judged.lost_stream >= 0) {
    int judged_left = 0;
    for (size_t k = 0; k < streams.size(); ++k)
      judged_left += streams[k].judged && static_cast<int>(k) != judged.lost_stream ? 1 : 0;
    if (judged_left < options_.min_sensors) break;
    streams[static_cast<size_t>(judged.lost_stream)].judged = false;
    lost.insert(judged.lost_stream);
    lost_why += "; left out: " + judged.why;
    judged = judgeStillness(streams, c.stamp, options_.stillness(), true);
  }
  ++stats_.candidates;
  stats_.last_stillness = judged.why;
  if (judged.state == StillState::kMoving || judged.state == StillState::kNoBoard)
    hold_pose_id_ = -1;
  if (judged.state == StillState::kMoving) return skip(movingKind(judged), judged.why);
  if (judged.state == StillState::kNoBoard) return skip("board lost around the moment", judged.why);
  if (judged.state == StillState::kTooFewFrames || judged.state == StillState::kPending)
    return skip("too few frames to judge stillness", judged.why);

  std::string seen_by;
  BoardPoseObservation o = observationAt(c.stamp, lost, &seen_by);
  const int sensors_seen = static_cast<int>(o.cameras.size() + o.lidars.size());
  if (sensors_seen < options_.min_sensors)
    return skip("seen by too few sensors",
                "board pose at t=" + formatFixed(c.stamp, 2) + " s seen by " +
                    std::to_string(sensors_seen) + " sensor(s) (" +
                    (seen_by.empty() ? "none" : seen_by) + "); a pose needs " +
                    std::to_string(options_.min_sensors) +
                    " (check the other detectors and stamp_tolerance)");
  SessionEvent kept =
      keepPose(std::move(o), "auto: " + judged.why + "; seen by " + seen_by + lost_why,
               judged.state == StillState::kSnapshot);
  if (kept.kind == SessionEvent::Kind::kAccepted)
    for (int k : lost) ++counts_[static_cast<size_t>(k)].lost_at_capture;
  return kept;
}

BoardPoseObservation RigSession::observationAt(double stamp, const std::set<int>& left_out,
                                               std::string* seen_by) const {
  BoardPoseObservation o;
  for (size_t k = 0; k < sensors_.size(); ++k) {
    if (left_out.count(static_cast<int>(k))) continue;
    const Stream& st = streams_[k];
    const int key = static_cast<int>(k);
    bool has = false;
    if (sensors_[k].kind == SensorKind::kCamera) {
      if (const auto* f = closestWithin(st.cameras, stamp, options_.stamp_tolerance_s)) {
        o.cameras[key] = *f;
        has = true;
      }
    } else if (const auto* f = closestWithin(st.lidars, stamp, options_.stamp_tolerance_s)) {
      o.lidars[key] = *f;
      has = true;
    }
    if (has) *seen_by += (seen_by->empty() ? "" : ", ") + names_[k];
  }
  return o;
}

SessionEvent RigSession::keepPose(BoardPoseObservation o, const std::string& why, bool snapshot) {
  // One pose per hold: a later moment of the same hold replaces it when it is better.
  auto held = std::find_if(poses_.begin(), poses_.end(), [&](const RigSessionPose& p) {
    return p.observation.id == hold_pose_id_;
  });
  if (!snapshot && held != poses_.end() && sameHold(o)) {
    auto score = [](const BoardPoseObservation& x) {
      double lo = 1e300, hi = -1e300;
      for (const auto& [k, f] : x.cameras) lo = std::min(lo, f.stamp), hi = std::max(hi, f.stamp);
      for (const auto& [k, f] : x.lidars) lo = std::min(lo, f.stamp), hi = std::max(hi, f.stamp);
      return std::make_pair(static_cast<int>(x.cameras.size() + x.lidars.size()), -(hi - lo));
    };
    if (score(o) <= score(held->observation))
      return skip("pose already taken",
                  "pose " + std::to_string(hold_pose_id_) + " already holds this board pose");
    o.id = held->observation.id;
    held->observation = std::move(o);
    held->why = why + " (a better moment of the same hold)";
    ++stats_.captured;
    return event(
        SessionEvent::Kind::kAccepted,
        "pose " + std::to_string(hold_pose_id_) + " replaced by a better moment of the same hold",
        hold_pose_id_);
  }
  int seen_pose = -1;
  if (seenBefore(o, &seen_pose)) {
    stats_.skipped["pose already taken"]++;
    return event(SessionEvent::Kind::kWaiting, "a sensor already saw this board pose (pose " +
                                                   std::to_string(seen_pose) +
                                                   "): move or tilt the board");
  }
  if (static_cast<int>(poses_.size()) >= options_.max_poses)
    return skip("session full", "already " + std::to_string(poses_.size()) +
                                    " poses (max_poses): solve, or drop poses first");
  o.id = next_id_++;
  RigSessionPose p;
  p.observation = std::move(o);
  p.why = why;
  poses_.push_back(p);
  hold_pose_id_ = p.observation.id;
  ++stats_.captured;
  return event(SessionEvent::Kind::kAccepted,
               "pose " + std::to_string(p.observation.id) + " (" + p.why + ")", p.observation.id);
}

bool RigSession::sameHold(const BoardPoseObservation& o) const {
  // Every sensor that saw both moments saw the board in the same place (within the still
  // tolerances), and at least one saw both.
  const auto held = std::find_if(poses_.begin(), poses_.end(), [&](const RigSessionPose& p) {
    return p.observation.id == hold_pose_id_;
  });
  if (held == poses_.end()) return false;
  int shared = 0;
  for (size_t k = 0; k < sensors_.size(); ++k) {
    const auto a = summaryOf(static_cast<int>(k), o),
               b = summaryOf(static_cast<int>(k), held->observation);
    if (!a || !b) continue;
    ++shared;
    if ((a->centre - b->centre).norm() > options_.still_max_translation_m ||
        angleBetweenDeg(a->normal, b->normal) > options_.still_max_rotation_deg)
      return false;
  }
  return shared > 0;
}

// Normals and centres only: MSG-Cal constrains plane to plane, so a board turned within its own
// plane adds nothing (the pair session's PBPC edges do count that turn).
bool RigSession::seenBefore(const BoardPoseObservation& o, int* pose_id) const {
  for (const auto& p : poses_)
    for (size_t k = 0; k < sensors_.size(); ++k) {
      const auto seen = summaryOf(static_cast<int>(k), p.observation),
                 now = summaryOf(static_cast<int>(k), o);
      if (!seen || !now) continue;
      if (angleBetweenDeg(seen->normal, now->normal) < options_.min_pose_rotation_deg &&
          (seen->centre - now->centre).norm() < options_.min_pose_translation_m) {
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

std::optional<RigSession::Summary> RigSession::summaryOf(int sensor,
                                                         const BoardPoseObservation& o) const {
  if (auto it = o.cameras.find(sensor); it != o.cameras.end()) return summarize(it->second);
  if (auto it = o.lidars.find(sensor); it != o.lidars.end()) return summarize(it->second);
  return std::nullopt;
}

void RigSession::prune() {
  // Per stream, relative to its own newest stamp (clocks of different sensors may be offset);
  // whatever a waiting candidate may still use is kept.
  for (size_t k = 0; k < streams_.size(); ++k) {
    Stream& st = streams_[k];
    double keep_from = counts_[k].newest_stamp - options_.history_s;
    // A stream far from the candidate (an offset clock) keeps only its own history: its frames
    // near the candidate's stamp were taken at another time.
    if (!candidates_.empty() &&
        std::abs(counts_[k].newest_stamp - candidates_.front().stamp) <= options_.history_s)
      keep_from =
          std::min(keep_from, candidates_.front().stamp -
                                  std::max(options_.still_window_s, options_.stamp_tolerance_s));
    auto old_camera = [&](const CameraBoardFeatures& f) { return f.stamp < keep_from; };
    auto old_lidar = [&](const LidarBoardFeatures& f) { return f.stamp < keep_from; };
    st.cameras.erase(std::remove_if(st.cameras.begin(), st.cameras.end(), old_camera),
                     st.cameras.end());
    st.lidars.erase(std::remove_if(st.lidars.begin(), st.lidars.end(), old_lidar), st.lidars.end());
    while (!st.samples.empty() && st.samples.front().stamp < keep_from) st.samples.pop_front();
    if (st.cameras.size() > kMaxFeaturesPerStream)
      st.cameras.erase(st.cameras.begin(), st.cameras.end() - kMaxFeaturesPerStream);
    if (st.lidars.size() > kMaxFeaturesPerStream)
      st.lidars.erase(st.lidars.begin(), st.lidars.end() - kMaxFeaturesPerStream);
    while (st.samples.size() > kMaxSamplesPerStream) st.samples.pop_front();
  }
  while (candidates_.size() > kMaxSamplesPerStream) candidates_.pop_front();
}

SessionEvent RigSession::flush() { return decideCandidates(true); }

SessionEvent RigSession::captureNow() {
  int sensor = -1;
  double stamp = -1e300;
  for (size_t k = 0; k < streams_.size(); ++k) {
    const Stream& st = streams_[k];
    const double s = sensors_[k].kind == SensorKind::kCamera
                         ? (st.cameras.empty() ? -1e300 : st.cameras.back().stamp)
                         : (st.lidars.empty() ? -1e300 : st.lidars.back().stamp);
    if (s > stamp) {
      stamp = s;
      sensor = static_cast<int>(k);
    }
  }
  if (sensor < 0)
    return event(SessionEvent::Kind::kRejected,
                 "no sensor has seen the board recently: nothing to capture");
  std::string seen_by;
  BoardPoseObservation o = observationAt(stamp, {}, &seen_by);
  const int sensors_seen = static_cast<int>(o.cameras.size() + o.lidars.size());
  if (sensors_seen < options_.min_sensors)
    return event(SessionEvent::Kind::kRejected,
                 "board pose at t=" + formatFixed(stamp, 2) + " s seen by " +
                     std::to_string(sensors_seen) + " sensor(s) (" +
                     (seen_by.empty() ? "none" : seen_by) + "); a pose needs " +
                     std::to_string(options_.min_sensors));
  if (static_cast<int>(poses_.size()) >= options_.max_poses)
    return event(SessionEvent::Kind::kRejected,
                 "already " + std::to_string(poses_.size()) + " poses (max_poses)");
  o.id = next_id_++;
  poses_.push_back({std::move(o),
                    "manual capture at " + names_[sensor] + "'s newest board; seen by " + seen_by});
  return event(
      SessionEvent::Kind::kAccepted,
      "pose " + std::to_string(poses_.back().observation.id) + " (" + poses_.back().why + ")",
      poses_.back().observation.id);
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
  candidates_.clear();
  hold_pose_id_ = -1;
  stats_ = CaptureStats{};
  for (auto& c : counts_) c.newest_stamp = kNever;
  for (auto& heard : newest_when_heard_) std::fill(heard.begin(), heard.end(), kNever);
  next_id_ = 0;
}

}  // namespace multi_sensor
}  // namespace board_calib
