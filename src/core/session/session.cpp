#include <board_calib/core/common/format.h>
#include <board_calib/core/session/session.h>
#include <board_calib/core/transform.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <set>
#include <sstream>

namespace board_calib {
namespace {

// Board centre seen by the camera (camera frame); the pose is the best-conditioned cue.
Eigen::Vector3d cameraBoardCentre(const CameraBoardFeatures& c, const Target& target) {
  return c.camera_T_board * target.center();
}

}  // namespace

const char* sessionEventName(SessionEvent::Kind kind) {
  switch (kind) {
    case SessionEvent::Kind::kWaiting: return "waiting";
    case SessionEvent::Kind::kRejected: return "rejected";
    case SessionEvent::Kind::kAccepted: return "accepted";
  }
  return "unknown";
}

std::string SessionOptions::validate() const {
  if (!(sync_tolerance_s > 0) || !std::isfinite(sync_tolerance_s) || sync_tolerance_s > 1.0)
    return "sync_tolerance_s must be in (0, 1] s";
  if (auto why = stillness().validate(); !why.empty()) return why;
  if (!(min_view_rotation_deg >= 0) || !(min_view_translation_m >= 0) ||
      !std::isfinite(min_view_rotation_deg) || !std::isfinite(min_view_translation_m))
    return "view diversity thresholds must be finite and >= 0";
  if (!(max_size_mismatch > 0) || !std::isfinite(max_size_mismatch))
    return "max_size_mismatch must be finite and > 0";
  if (!(max_plane_angle_deg > 0) || !(max_plane_offset_m > 0) ||
      !std::isfinite(max_plane_angle_deg) || !std::isfinite(max_plane_offset_m))
    return "plane agreement thresholds must be finite and > 0";
  if (min_board_points < 3) return "min_board_points must be >= 3";
  if (max_views < 1 || max_views > 100000) return "max_views must be in [1, 100000]";
  if (history < 1 || history > 100000) return "history must be in [1, 100000]";
  return {};
}

std::string CaptureStats::summary() const {
  std::vector<std::pair<int, std::string>> order;
  for (const auto& [kind, n] : skipped) order.emplace_back(-n, kind);
  std::sort(order.begin(), order.end());
  std::ostringstream s;
  s << candidates << " candidate images, " << captured << " captured";
  for (const auto& [n, kind] : order) s << "; " << -n << " x " << kind;
  return s.str();
}

namespace {

// The kind of a view refused for the LiDAR board's size: one kind whatever the sizes measured,
// so that it counts as one cause.
constexpr const char* kOtherSize = "LiDAR board of another size than the target";

// What to change, by the capture step that refused the most candidates (pair and rig words).
std::string remedyFor(const std::string& kind) {
  static const std::map<std::string, std::string> kRemedy = {
      {kOtherSize,
       "measure the board and fix the target file (the LiDAR measured every such board alike), "
       "or, when the board is right, look for another flat object the LiDAR took for it"},
      {"too few frames to judge stillness",
       "each pose must be held for the stillness window's frames on both sides of an image: hold "
       "each pose longer, or lower the still-frames setting (1: no stillness check)"},
      {"no cloud within the sync tolerance",
       "the image and cloud stamps lie further apart than the sync tolerance: check the stamps "
       "or raise the tolerance"},
      {"seen by too few sensors",
       "a pose needs two or more sensors to see the board within the stamp tolerance"},
      {"board moving", "hold the board still at each pose"},
      {kDifferentObjects,
       "a sensor found the board at places too far apart for one hand-held board: keep the "
       "board well inside its view and away from flat objects of its size, and check that the "
       "sensor looks at the board (not at the ground or a wall)"},
      {"board lost around the image", "keep the board inside both sensors' views at each pose"},
      {"board lost around the moment", "keep the board inside the sensors' views at each pose"},
  };
  const auto it = kRemedy.find(kind);
  return it == kRemedy.end() ? "" : it->second;
}

// The skip kind that refused the most candidates; with `only_causes`, kinds that are no fault
// of the recording (a hold's later frames, a full session) do not count.
std::pair<std::string, int> mostSkipped(const CaptureStats& stats, bool only_causes) {
  static const std::set<std::string> kNoFault = {"pose already taken", "too similar to a kept view",
                                                 "session full", "time went back"};
  std::pair<std::string, int> most{"", 0};
  for (const auto& [kind, n] : stats.skipped)
    if (n > most.second && !(only_causes && kNoFault.count(kind))) most = {kind, n};
  return most;
}

}  // namespace

std::string CaptureStats::whyNoViews() const {
  if (candidates == 0)
    return "no board was found to capture: hold it still in front of the sensors";
  const auto [kind, most] = mostSkipped(*this, false);
  std::ostringstream s;
  s << "no view was captured: " << (kind.empty() ? std::string("none judged") : kind) << " ("
    << most << " of " << candidates << " candidates)";
  if (const std::string remedy = remedyFor(kind); !remedy.empty()) s << "; " << remedy;
  if (const auto it = last_why.find(kind);
      it != last_why.end() && !it->second.empty() && it->second != kind)
    s << " (the latest: " << it->second << ")";
  return s.str();
}

std::string CaptureStats::whyFewViews() const {
  const auto [kind, most] = mostSkipped(*this, true);
  if (kind.empty() || most <= captured || 2 * most <= candidates) return "";
  std::ostringstream s;
  s << "the capture refused " << most << " of " << candidates << " candidates as " << kind
    << " and kept " << captured;
  if (const std::string remedy = remedyFor(kind); !remedy.empty()) s << ": " << remedy;
  return s.str();
}

PairSession::PairSession(const Target& target, const SessionOptions& options)
    : target_(target), options_(options) {}

namespace {

constexpr double kPruneMarginS =
    1.0;  // s, kept beyond what the still window and sync tolerance reach

}  // namespace

SessionEvent PairSession::addLidar(const LidarBoardFeatures& f) {
  SessionEvent refused;
  const Admission a = admit(f.stamp, malformedFeatures(f), lidar_clock_, "LiDAR", &refused);
  if (a == Admission::kDrop) return refused;
  lidar_.push_back(f);
  lidar_.back().found = f.found && a == Admission::kKeep;
  lidar_samples_.push_back(boardSampleOf(f));  // not found if malformed
  lidar_clock_.add(f.stamp);
  prune();
  updateLastPair();
  const SessionEvent e = decidePending(false);
  return a == Admission::kKeep || e.kind == SessionEvent::Kind::kAccepted ? e : refused;
}

SessionEvent PairSession::addCamera(const CameraBoardFeatures& f) {
  SessionEvent refused;
  const Admission a = admit(f.stamp, malformedFeatures(f), camera_clock_, "camera", &refused);
  if (a == Admission::kDrop) return refused;
  camera_.push_back(f);
  camera_.back().found = f.found && a == Admission::kKeep;
  camera_samples_.push_back(boardSampleOf(f, &target_));  // not found if malformed
  camera_clock_.add(f.stamp);
  updateLastPair();
  if (camera_.back().found) pending_.push_back(f);
  prune();
  const SessionEvent e = decidePending(false);
  return a == Admission::kKeep || e.kind == SessionEvent::Kind::kAccepted ? e : refused;
}

// A message from outside the process may carry anything: a stamp that is no time is dropped
// (it cannot be placed among the others); a stream whose time went back restarted (a bag played
// again, a clock reset, or a stamp far in the future before), so the buffered frames, which no
// longer compare, are forgotten and the captured views kept; malformed features count as a
// frame without the board.
PairSession::Admission PairSession::admit(double stamp, const std::string& malformed,
                                          const StreamClock& clock, const char* stream,
                                          SessionEvent* refused) {
  if (!std::isfinite(stamp)) {
    *refused = skip("malformed message",
                    std::string(stream) + " features with a non-finite stamp: message ignored");
    return Admission::kDrop;
  }
  if (!clock.empty() && stamp < clock.newest() - kStreamTimeJumpBackS) {
    skip("time went back", std::string(stream) + " stamps went back " +
                               formatFixed(clock.newest() - stamp, 1) +
                               " s (a bag played again, a clock reset): frames awaiting "
                               "capture dropped, captured views kept");
    forgetBuffers();
  }
  if (malformed.empty()) return Admission::kKeep;
  *refused =
      skip("malformed message", "malformed " + std::string(stream) +
                                    " features (a corrupted or hostile message?): " + malformed +
                                    "; taken as no board");
  return Admission::kKeepAsNoBoard;
}

void PairSession::forgetBuffers() {
  lidar_.clear();
  camera_.clear();
  lidar_samples_.clear();
  camera_samples_.clear();
  lidar_clock_.clear();
  camera_clock_.clear();
  pending_.clear();
  last_pair_.reset();
  hold_view_id_ = -1;
}

void PairSession::updateLastPair() {
  if (camera_.empty()) return;
  double gap = 0.0;
  if (auto lidar = nearestLidar(camera_.back().stamp, &gap);
      lidar && gap <= options_.sync_tolerance_s) {
    View pair;
    pair.lidar = *lidar;
    pair.camera = camera_.back();
    last_pair_ = pair;
  }
}

void PairSession::prune() {
  // Keep what the still window and the sync tolerance can still reach, plus a margin.
  // Images still waiting for their judgement keep what lies around them (snapshot recordings
  // learn their rates only from later frames).
  const double reach = options_.still_window_s + options_.sync_tolerance_s + kPruneMarginS;
  const double newest = std::max(lidar_clock_.newest(), camera_clock_.newest());
  double cutoff = newest - 2.0 * reach;
  if (!pending_.empty()) cutoff = std::min(cutoff, pending_.front().stamp - reach);
  auto trim = [&](auto& items, auto& samples) {
    while (!items.empty() &&
           (static_cast<int>(items.size()) > options_.history || items.front().stamp < cutoff)) {
      items.pop_front();
      samples.pop_front();
    }
  };
  trim(lidar_, lidar_samples_);
  trim(camera_, camera_samples_);
  while (static_cast<int>(pending_.size()) > options_.history) pending_.pop_front();
}

std::optional<LidarBoardFeatures> PairSession::nearestLidar(double stamp, double* gap) const {
  std::optional<LidarBoardFeatures> best;
  *gap = std::numeric_limits<double>::infinity();
  for (const auto& l : lidar_)
    if (std::abs(l.stamp - stamp) < *gap) {
      *gap = std::abs(l.stamp - stamp);
      best = l;
    }
  return best;
}

SessionEvent PairSession::skip(const std::string& kind, const std::string& why) {
  stats_.skipped[kind]++;
  stats_.last_why[kind] = why;
  return {SessionEvent::Kind::kRejected, why, -1};
}

SessionEvent PairSession::finish() { return decidePending(true); }

// Accepted beats rejected beats waiting: the caller logs the most significant outcome.
SessionEvent PairSession::decidePending(bool ended) {
  SessionEvent result{SessionEvent::Kind::kWaiting,
                      pending_.empty() ? "waiting for an image that sees the board"
                                       : "waiting for the still window",
                      -1};
  while (!pending_.empty()) {
    bool decided = false;
    const SessionEvent e = decide(pending_.front(), ended, &decided);
    if (!decided) break;
    pending_.pop_front();
    if (e.kind == SessionEvent::Kind::kAccepted || result.kind == SessionEvent::Kind::kWaiting ||
        (e.kind == SessionEvent::Kind::kRejected && result.kind != SessionEvent::Kind::kAccepted))
      result = e;
  }
  return result;
}

SessionEvent PairSession::decide(const CameraBoardFeatures& camera, bool ended, bool* decided) {
  *decided = false;
  double gap = 0.0;
  const auto lidar = nearestLidar(camera.stamp, &gap);
  // Until a cloud at or after the image arrives, a closer cloud may still come.
  if (!ended && lidar_clock_.newest() < camera.stamp)
    return {SessionEvent::Kind::kWaiting, "waiting for the cloud of the image", -1};
  const StillnessOptions still = options_.stillness();
  const std::vector<StillnessStream> streams{{&lidar_samples_, &lidar_clock_, "LiDAR"},
                                             {&camera_samples_, &camera_clock_, "camera"}};
  const StillnessJudgement judged = judgeStillness(streams, camera.stamp, still, ended);
  if (judged.state == StillState::kPending)
    return {SessionEvent::Kind::kWaiting, "waiting for the still window", -1};
  *decided = true;
  ++stats_.candidates;
  stats_.last_stillness = judged.why;
  if (!lidar || gap > options_.sync_tolerance_s)
    return skip("no cloud within the sync tolerance",
                "no LiDAR cloud within " + formatFixed(options_.sync_tolerance_s * 1e3, 0) +
                    " ms of the image (closest " +
                    (lidar ? formatFixed(gap * 1e3, 0) + " ms" : std::string("none")) +
                    "): check sync_tolerance");
  if (judged.state == StillState::kMoving || judged.state == StillState::kNoBoard)
    hold_view_id_ = -1;
  if (judged.state == StillState::kMoving) return skip(movingKind(judged), judged.why);
  if (judged.state == StillState::kNoBoard) return skip("board lost around the image", judged.why);
  if (judged.state == StillState::kTooFewFrames)
    return skip("too few frames to judge stillness", judged.why);
  if (!auto_capture_) return {SessionEvent::Kind::kWaiting, "auto-capture is off", -1};

  View view;
  view.lidar = *lidar;
  view.camera = camera;
  const SessionEvent gated = gate(view, false);
  if (gated.kind == SessionEvent::Kind::kRejected)
    return skip(gated.message.substr(0, gated.message.find(" (")), gated.message);
  // One view per hold: a later frame of the same still pose replaces it when it is better.
  const BoardSample here = boardSampleOf(camera, &target_);
  const bool snapshot = judged.state == StillState::kSnapshot;
  const bool same_hold =
      !snapshot && hold_view_id_ >= 0 &&
      (here.centre - hold_reference_.centre).norm() <=
          still.max_translation_m +
              still.noise_factor *
                  std::hypot(here.centre_sigma_m, hold_reference_.centre_sigma_m) &&
      angleBetweenDeg(here.normal, hold_reference_.normal) <= still.max_rotation_deg;
  if (same_hold) {
    auto it = std::find_if(views_.begin(), views_.end(),
                           [&](const SessionView& v) { return v.view.id == hold_view_id_; });
    if (it == views_.end())
      return skip("pose already taken",
                  "view of this pose was dropped; move the board to a new pose");
    auto score = [](const View& v) {
      int edges = 0;
      for (int j = 0; j < kNumEdges; ++j) edges += v.lidar.edge_valid[j] + v.camera.edge_valid[j];
      return std::make_pair(edges, -std::abs(v.lidar.stamp - v.camera.stamp));
    };
    if (score(view) > score(it->view)) {
      view.id = it->view.id;
      it->view = view;
      it->why = "auto: " + judged.why + " (a better frame of the same hold)";
      ++stats_.captured;
      return {SessionEvent::Kind::kAccepted,
              "view " + std::to_string(view.id) + " replaced by a better frame of the same hold",
              view.id};
    }
    return skip("pose already taken", "view " + std::to_string(hold_view_id_) +
                                          " already holds this pose; move the board");
  }
  const SessionEvent added = addView(view, "auto: " + judged.why, true);
  if (added.kind == SessionEvent::Kind::kAccepted) {
    hold_view_id_ = added.view_id;
    hold_reference_ = here;
  } else {
    stats_.skipped["too similar to a kept view"]++;
  }
  return added;
}

SessionEvent PairSession::captureNow() {
  if (!last_pair_)
    return {SessionEvent::Kind::kRejected, "no synchronised LiDAR/camera pair seen yet", -1};
  const SessionEvent gated = gate(*last_pair_, true);
  if (gated.kind == SessionEvent::Kind::kRejected) return gated;
  return addView(*last_pair_, "manual capture", false);
}

SessionEvent PairSession::gate(const View& v, bool /*forced*/) const {
  const auto reject = [](const std::string& why) {
    return SessionEvent{SessionEvent::Kind::kRejected, why, -1};
  };
  if (!v.lidar.found) return reject("LiDAR: no board (" + v.lidar.reason + ")");
  if (!v.camera.found) return reject("camera: no board (" + v.camera.reason + ")");
  if (static_cast<int>(v.lidar.board_points.size()) < options_.min_board_points)
    return reject("LiDAR: too few board points (" + std::to_string(v.lidar.board_points.size()) +
                  ", need " + std::to_string(options_.min_board_points) + ")");
  if (!v.lidar.plane.normal.allFinite() || !v.camera.plane.normal.allFinite() ||
      !std::isfinite(v.lidar.plane.offset) || !std::isfinite(v.camera.plane.offset))
    return reject("non-finite board plane");
  // Both sensors must agree this is the board: the LiDAR's measured size against the target.
  // Side by side: the detector pairs measured_size_m.x() with the width, .y() with the height.
  if (v.lidar.measured_size_m.minCoeff() > 0) {
    const Eigen::Vector2d declared(target_.width, target_.height);
    const Eigen::Vector2d mismatch =
        (v.lidar.measured_size_m.cwiseQuotient(declared).array() - 1.0).abs();
    if (mismatch.maxCoeff() > options_.max_size_mismatch)
      return reject(std::string(kOtherSize) + " (it measures " +
                    formatFixed(v.lidar.measured_size_m.x()) + " x " +
                    formatFixed(v.lidar.measured_size_m.y()) + " m, the target is " +
                    formatFixed(target_.width) + " x " + formatFixed(target_.height) + " m)");
  }
  if (estimate_) {
    const Plane lidar_in_camera = v.lidar.plane.transformed(*estimate_);
    const double angle = angleBetweenDeg(lidar_in_camera.normal, v.camera.plane.normal);
    const double offset = std::abs(lidar_in_camera.offset - v.camera.plane.offset);
    if (angle > options_.max_plane_angle_deg || offset > options_.max_plane_offset_m)
      return reject("sensors disagree on the board plane under the current estimate (" +
                    formatFixed(angle, 1) + " deg, " + formatFixed(offset * 100, 1) + " cm)");
  }
  if (static_cast<int>(views_.size()) >= options_.max_views)
    return reject("session holds the maximum of " + std::to_string(options_.max_views) + " views");
  return {SessionEvent::Kind::kWaiting, "passes the sanity gates", -1};
}

SessionEvent PairSession::addView(const View& view, const std::string& why, bool check_diversity) {
  if (check_diversity) {
    for (const auto& kept : views_) {
      // The whole board rotation: a turn within the board's plane changes the edge directions
      // (PBPC's edge constraints) although the normal stays.
      const double turn =
          rotationErrorDeg(kept.view.camera.camera_T_board, view.camera.camera_T_board);
      const double move =
          (cameraBoardCentre(kept.view.camera, target_) - cameraBoardCentre(view.camera, target_))
              .norm();
      if (turn < options_.min_view_rotation_deg && move < options_.min_view_translation_m)
        return {SessionEvent::Kind::kRejected,
                "too similar to view " + std::to_string(kept.view.id) + " (" +
                    formatFixed(turn, 1) + " deg, " + formatFixed(move * 100, 0) +
                    " cm); move or tilt the board more",
                -1};
    }
  }
  SessionView sv;
  sv.view = view;
  sv.view.id = next_id_++;
  sv.why = why;
  views_.push_back(sv);
  ++stats_.captured;
  return {SessionEvent::Kind::kAccepted,
          "view " + std::to_string(sv.view.id) + " accepted (" + why + ")", sv.view.id};
}

std::vector<View> PairSession::plainViews() const {
  std::vector<View> out;
  out.reserve(views_.size());
  for (const auto& v : views_) out.push_back(v.view);
  return out;
}

Status PairSession::dropView(int view_id) {
  const auto it = std::find_if(views_.begin(), views_.end(),
                               [&](const SessionView& v) { return v.view.id == view_id; });
  if (it == views_.end()) return Status::failure("no view with id " + std::to_string(view_id));
  views_.erase(it);
  return Status::success();
}

void PairSession::reset() {
  views_.clear();
  forgetBuffers();
  estimate_.reset();
  stats_ = CaptureStats{};
  next_id_ = 0;
}

CoverageReport PairSession::coverage() const {
  CoverageReport r;
  r.views = static_cast<int>(views_.size());
  if (views_.empty()) {
    r.advice.push_back(
        "no views yet: hold the board still, about 2-4 m away, tilted like a diamond");
    return r;
  }
  constexpr int kGrid = 3;  // 3x3 image regions
  bool visited[kGrid][kGrid] = {};
  r.range_min_m = std::numeric_limits<double>::max();
  double min_lr = 1, max_lr = -1, min_ud = 1, max_ud = -1;
  for (size_t i = 0; i < views_.size(); ++i) {
    const auto& c = views_[i].view.camera;
    const Eigen::Vector3d centre = cameraBoardCentre(c, target_);
    r.range_min_m = std::min(r.range_min_m, centre.norm());
    r.range_max_m = std::max(r.range_max_m, centre.norm());
    for (size_t j = i + 1; j < views_.size(); ++j)
      r.tilt_span_deg = std::max(
          r.tilt_span_deg, angleBetweenDeg(c.plane.normal, views_[j].view.camera.plane.normal));
    if (centre.z() > 0 && c.image_width > 0 && c.image_height > 0) {
      const double u = c.K(0, 0) * centre.x() / centre.z() + c.K(0, 2);
      const double v = c.K(1, 1) * centre.y() / centre.z() + c.K(1, 2);
      const int gu = std::clamp(static_cast<int>(u / c.image_width * kGrid), 0, kGrid - 1);
      const int gv = std::clamp(static_cast<int>(v / c.image_height * kGrid), 0, kGrid - 1);
      visited[gv][gu] = true;
    }
    // Normal components across the line of sight: left/right and up/down tilt.
    const Eigen::Vector3d n = c.plane.normal;
    const Eigen::Vector3d sight = centre.normalized();
    const Eigen::Vector3d across = n - n.dot(sight) * sight;
    min_lr = std::min(min_lr, across.x());
    max_lr = std::max(max_lr, across.x());
    min_ud = std::min(min_ud, across.y());
    max_ud = std::max(max_ud, across.y());
  }
  int cells = 0;
  for (auto& row : visited)
    for (bool b : row) cells += b;
  r.image_coverage = static_cast<double>(cells) / (kGrid * kGrid);

  constexpr int kEnoughViews = 20;
  constexpr double kTiltWanted = 0.25;        // sin(~15 deg) each way
  constexpr double kRangeSpreadWanted = 1.0;  // m
  if (r.views < 3)
    r.advice.push_back("collect at least 3 views with different tilts (PPC needs 3 non-coplanar)");
  if (max_lr < kTiltWanted)
    r.advice.push_back("tilt the board to turn its face towards the camera's left");
  if (min_lr > -kTiltWanted)
    r.advice.push_back("tilt the board to turn its face towards the camera's right");
  if (max_ud < kTiltWanted) r.advice.push_back("tilt the board top towards the camera");
  if (min_ud > -kTiltWanted) r.advice.push_back("tilt the board top away from the camera");
  if (r.range_max_m - r.range_min_m < kRangeSpreadWanted)
    r.advice.push_back("vary the distance: current views span " + formatFixed(r.range_min_m, 1) +
                       "-" + formatFixed(r.range_max_m, 1) + " m");
  if (r.image_coverage < 0.5)
    r.advice.push_back("move the board across the image (left/right/top/bottom)");
  if (r.views < kEnoughViews)
    r.advice.push_back(std::to_string(kEnoughViews - r.views) + " more views recommended");
  return r;
}

}  // namespace board_calib
