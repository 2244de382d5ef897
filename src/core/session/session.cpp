#include <board_calib/core/session.h>
#include <board_calib/core/transform.h>

#include <algorithm>
#include <cmath>
#include <sstream>

namespace board_calib {
namespace {

double angleDeg(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return std::acos(std::clamp(a.normalized().dot(b.normalized()), -1.0, 1.0)) * kDegPerRad;
}

// Board centre seen by the camera (camera frame); the pose is the best-conditioned cue.
Eigen::Vector3d cameraBoardCentre(const CameraBoardFeatures& c, const Target& target) {
  return c.camera_T_board * target.center();
}

std::string fmt(double v, int precision = 2) {
  std::ostringstream s;
  s.setf(std::ios::fixed);
  s.precision(precision);
  s << v;
  return s.str();
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
  if (!(sync_tolerance_s > 0)) return "sync_tolerance_s must be > 0";
  if (still_frames_required < 1) return "still_frames_required must be >= 1";
  if (!(still_max_translation_m > 0) || !(still_max_rotation_deg > 0))
    return "still_max_translation_m and still_max_rotation_deg must be > 0";
  if (min_view_rotation_deg < 0 || min_view_translation_m < 0) return "view diversity thresholds must be >= 0";
  if (!(max_size_mismatch > 0)) return "max_size_mismatch must be > 0";
  if (!(max_plane_angle_deg > 0) || !(max_plane_offset_m > 0)) return "plane agreement thresholds must be > 0";
  if (min_board_points < 3) return "min_board_points must be >= 3";
  if (max_views < 1) return "max_views must be >= 1";
  if (history < 1) return "history must be >= 1";
  return {};
}

CalibrationSession::CalibrationSession(const Target& target, const SessionOptions& options)
    : target_(target), options_(options) {}

SessionEvent CalibrationSession::addLidar(const LidarBoardFeatures& f) {
  lidar_.push_back(f);
  while (static_cast<int>(lidar_.size()) > options_.history) lidar_.pop_front();
  return tryPair(false);
}

SessionEvent CalibrationSession::addCamera(const CameraBoardFeatures& f) {
  camera_.push_back(f);
  while (static_cast<int>(camera_.size()) > options_.history) camera_.pop_front();
  return tryPair(false);
}

SessionEvent CalibrationSession::captureNow() {
  if (!last_pair_) return {SessionEvent::Kind::kRejected, "no synchronised LiDAR/camera pair seen yet", -1};
  const SessionEvent gated = gate(*last_pair_, true);
  if (gated.kind == SessionEvent::Kind::kRejected) return gated;
  return addView(*last_pair_, "manual capture", false);
}

SessionEvent CalibrationSession::tryPair(bool forced) {
  if (lidar_.empty() || camera_.empty()) return {SessionEvent::Kind::kWaiting, "waiting for both sensors", -1};
  // Newest pair within the tolerance: newest item of one stream vs the closest of the other.
  const bool lidar_newest = lidar_.back().stamp >= camera_.back().stamp;
  View pair;
  double best = std::numeric_limits<double>::max();
  if (lidar_newest) {
    pair.lidar = lidar_.back();
    for (const auto& c : camera_)
      if (std::abs(c.stamp - pair.lidar.stamp) < best) {
        best = std::abs(c.stamp - pair.lidar.stamp);
        pair.camera = c;
      }
  } else {
    pair.camera = camera_.back();
    for (const auto& l : lidar_)
      if (std::abs(l.stamp - pair.camera.stamp) < best) {
        best = std::abs(l.stamp - pair.camera.stamp);
        pair.lidar = l;
      }
  }
  if (best > options_.sync_tolerance_s)
    return {SessionEvent::Kind::kWaiting,
            "no LiDAR/camera pair within " + fmt(options_.sync_tolerance_s * 1e3, 0) + " ms (closest " +
                fmt(best * 1e3, 0) + " ms)",
            -1};
  if (last_pair_ && last_pair_->lidar.stamp == pair.lidar.stamp && last_pair_->camera.stamp == pair.camera.stamp)
    return {SessionEvent::Kind::kWaiting, "pair already considered", -1};

  // Stillness: the board in both sensors barely moved since the previous pair.
  bool still_step = false;
  if (last_pair_ && pair.lidar.found && pair.camera.found && last_pair_->lidar.found && last_pair_->camera.found) {
    const double cam_move = (cameraBoardCentre(pair.camera, target_) - cameraBoardCentre(last_pair_->camera, target_)).norm();
    const double cam_turn = angleDeg(pair.camera.plane.normal, last_pair_->camera.plane.normal);
    const double lidar_turn = angleDeg(pair.lidar.plane.normal, last_pair_->lidar.plane.normal);
    const double lidar_shift = std::abs(pair.lidar.plane.offset - last_pair_->lidar.plane.offset);
    still_step = cam_move < options_.still_max_translation_m && cam_turn < options_.still_max_rotation_deg &&
                 lidar_turn < options_.still_max_rotation_deg && lidar_shift < options_.still_max_translation_m;
  }
  if (still_step) {
    ++still_count_;
  } else {
    still_count_ = 1;
    captured_this_still_ = false;
  }
  last_pair_ = pair;
  if (!auto_capture_ && !forced) return {SessionEvent::Kind::kWaiting, "auto-capture is off", -1};
  if (still_count_ < options_.still_frames_required)
    return {SessionEvent::Kind::kWaiting,
            "board moving or just arrived (" + std::to_string(still_count_) + "/" +
                std::to_string(options_.still_frames_required) + " still frames)",
            -1};
  if (captured_this_still_) return {SessionEvent::Kind::kWaiting, "view already taken; move the board to a new pose", -1};
  const SessionEvent gated = gate(pair, forced);
  if (gated.kind == SessionEvent::Kind::kRejected) return gated;
  const SessionEvent added = addView(pair, "auto: board still for " + std::to_string(still_count_) + " frames", true);
  if (added.kind == SessionEvent::Kind::kAccepted) captured_this_still_ = true;
  return added;
}

SessionEvent CalibrationSession::gate(const View& v, bool /*forced*/) const {
  const auto reject = [](const std::string& why) { return SessionEvent{SessionEvent::Kind::kRejected, why, -1}; };
  if (!v.lidar.found) return reject("LiDAR: no board (" + v.lidar.reason + ")");
  if (!v.camera.found) return reject("camera: no board (" + v.camera.reason + ")");
  if (static_cast<int>(v.lidar.board_points.size()) < options_.min_board_points)
    return reject("LiDAR: only " + std::to_string(v.lidar.board_points.size()) + " board points (need " +
                  std::to_string(options_.min_board_points) + ")");
  if (!v.lidar.plane.normal.allFinite() || !v.camera.plane.normal.allFinite() || !std::isfinite(v.lidar.plane.offset) ||
      !std::isfinite(v.camera.plane.offset))
    return reject("non-finite board plane");
  // Both sensors must agree this is the board: the LiDAR's measured size against the target.
  // Side by side: the detector pairs measured_size_m.x() with the width, .y() with the height.
  if (v.lidar.measured_size_m.minCoeff() > 0) {
    const Eigen::Vector2d declared(target_.width, target_.height);
    const Eigen::Vector2d mismatch = (v.lidar.measured_size_m.cwiseQuotient(declared).array() - 1.0).abs();
    if (mismatch.maxCoeff() > options_.max_size_mismatch)
      return reject("LiDAR board measures " + fmt(v.lidar.measured_size_m.x()) + " x " +
                    fmt(v.lidar.measured_size_m.y()) + " m, the target is " + fmt(target_.width) + " x " +
                    fmt(target_.height) + " m");
  }
  if (estimate_) {
    const Plane lidar_in_camera = v.lidar.plane.transformed(*estimate_);
    const double angle = angleDeg(lidar_in_camera.normal, v.camera.plane.normal);
    const double offset = std::abs(lidar_in_camera.offset - v.camera.plane.offset);
    if (angle > options_.max_plane_angle_deg || offset > options_.max_plane_offset_m)
      return reject("sensors disagree on the board plane under the current estimate (" + fmt(angle, 1) + " deg, " +
                    fmt(offset * 100, 1) + " cm)");
  }
  if (static_cast<int>(views_.size()) >= options_.max_views)
    return reject("session holds the maximum of " + std::to_string(options_.max_views) + " views");
  return {SessionEvent::Kind::kWaiting, "passes the sanity gates", -1};
}

SessionEvent CalibrationSession::addView(const View& view, const std::string& why, bool check_diversity) {
  if (check_diversity) {
    for (const auto& kept : views_) {
      const double turn = angleDeg(kept.view.camera.plane.normal, view.camera.plane.normal);
      const double move =
          (cameraBoardCentre(kept.view.camera, target_) - cameraBoardCentre(view.camera, target_)).norm();
      if (turn < options_.min_view_rotation_deg && move < options_.min_view_translation_m)
        return {SessionEvent::Kind::kRejected,
                "too similar to view " + std::to_string(kept.view.id) + " (" + fmt(turn, 1) + " deg, " +
                    fmt(move * 100, 0) + " cm); move or tilt the board more",
                -1};
    }
  }
  SessionView sv;
  sv.view = view;
  sv.view.id = next_id_++;
  sv.why = why;
  views_.push_back(sv);
  return {SessionEvent::Kind::kAccepted, "view " + std::to_string(sv.view.id) + " accepted (" + why + ")", sv.view.id};
}

std::vector<View> CalibrationSession::plainViews() const {
  std::vector<View> out;
  out.reserve(views_.size());
  for (const auto& v : views_) out.push_back(v.view);
  return out;
}

Status CalibrationSession::dropView(int view_id) {
  const auto it = std::find_if(views_.begin(), views_.end(), [&](const SessionView& v) { return v.view.id == view_id; });
  if (it == views_.end()) return Status::failure("no view with id " + std::to_string(view_id));
  views_.erase(it);
  return Status::success();
}

void CalibrationSession::reset() {
  views_.clear();
  lidar_.clear();
  camera_.clear();
  last_pair_.reset();
  estimate_.reset();
  still_count_ = 0;
  captured_this_still_ = false;
  next_id_ = 0;
}

CoverageReport CalibrationSession::coverage() const {
  CoverageReport r;
  r.views = static_cast<int>(views_.size());
  if (views_.empty()) {
    r.advice.push_back("no views yet: hold the board still, about 2-4 m away, tilted like a diamond");
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
      r.tilt_span_deg = std::max(r.tilt_span_deg, angleDeg(c.plane.normal, views_[j].view.camera.plane.normal));
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
  constexpr double kTiltWanted = 0.25;      // sin(~15 deg) each way
  constexpr double kRangeSpreadWanted = 1.0;  // m
  if (r.views < 3) r.advice.push_back("collect at least 3 views with different tilts (PPC needs 3 non-coplanar)");
  if (max_lr < kTiltWanted) r.advice.push_back("tilt the board to turn its face towards the camera's left");
  if (min_lr > -kTiltWanted) r.advice.push_back("tilt the board to turn its face towards the camera's right");
  if (max_ud < kTiltWanted) r.advice.push_back("tilt the board top towards the camera");
  if (min_ud > -kTiltWanted) r.advice.push_back("tilt the board top away from the camera");
  if (r.range_max_m - r.range_min_m < kRangeSpreadWanted)
    r.advice.push_back("vary the distance: current views span " + fmt(r.range_min_m, 1) + "-" + fmt(r.range_max_m, 1) +
                       " m");
  if (r.image_coverage < 0.5) r.advice.push_back("move the board across the image (left/right/top/bottom)");
  if (r.views < kEnoughViews) r.advice.push_back(std::to_string(kEnoughViews - r.views) + " more views recommended");
  return r;
}

}  // namespace board_calib
