// Calibration session: pairs LiDAR and camera board features by stamp, accepts a view only
// when the board is still, both sensors agree and the view adds information, and keeps every
// accepted view (with why) so it can be saved, reloaded, dropped and solved again.
//
// Capture rule: every image that sees the board is a candidate. It is judged once the fastest
// stream has passed the end of the still window around it (capture/stillness.h): still in
// every stream -> paired with the nearest cloud and gated; each hold (the board still in one
// place) gives one view, replaced by a better frame of the same hold (more edges, closer
// stamps). Snapshot recordings (every stream sparse) make every synchronised pair a candidate.
#pragma once

#include <board_calib/core/capture/stillness.h>
#include <board_calib/core/features.h>
#include <board_calib/core/target.h>

#include <deque>
#include <map>
#include <optional>
#include <string>
#include <vector>

namespace board_calib {

/// The pair session's options; the stillness settings (still_*, snapshot_interval_s) are the
/// rig session's too (StillCaptureOptions).
struct SessionOptions : StillCaptureOptions {
  double sync_tolerance_s = 0.05;      ///< s, max |t_camera - t_lidar| for one view
  double min_view_rotation_deg = 5.0;  ///< deg, a new view's board must be turned this much (tilt
                                       ///< or in-plane turn) ...
  double min_view_translation_m =
      0.20;                          ///< m, ... or its centre move this much from every kept view
  double max_size_mismatch = 0.15;   ///< relative, LiDAR-measured board size vs the target
  double max_plane_angle_deg = 5.0;  ///< deg, plane agreement once an estimate exists
  double max_plane_offset_m = 0.15;  ///< m, plane agreement once an estimate exists
  int min_board_points = 30;         ///< LiDAR board points a view needs
  int max_views = 200;               ///< views kept at most
  int history = 400;                 ///< features kept per stream at most (also pruned by time)
  std::string validate() const;
};

/// A kept view with its provenance.
struct SessionView {
  View view;
  std::string why;  ///< why it was accepted (e.g. "auto: still 2 frames, 12.4 deg from view 3")
};

/// What happened to a candidate (an image and its cloud).
struct SessionEvent {
  enum class Kind { kWaiting, kRejected, kAccepted };
  Kind kind = Kind::kWaiting;
  std::string message;  ///< specific: why waiting / rejected / accepted
  int view_id = -1;     ///< accepted view id
};
const char* sessionEventName(SessionEvent::Kind kind);

/// Where the kept views leave gaps, with advice for the next board pose.
struct CoverageReport {
  int views = 0;
  double tilt_span_deg = 0.0;                   ///< spread of board normals (max pairwise angle)
  double range_min_m = 0.0, range_max_m = 0.0;  ///< distances of the board centres
  double image_coverage = 0.0;  ///< fraction of a 3x3 image grid visited by board centres
  std::vector<std::string> advice;
};

/// Why candidates were not captured, counted by kind ("board moving", "no cloud within the sync
/// tolerance", "pose already taken", a gate's reason...), for diagnostics and logs.
struct CaptureStats {
  int candidates = 0;  ///< images with the board that were judged
  int captured = 0;    ///< views accepted (a hold's later, better frame counts once more)
  std::map<std::string, int> skipped;           ///< kind -> count
  std::map<std::string, std::string> last_why;  ///< kind -> its latest specific reason
  std::string last_stillness;                   ///< the last judgement in words
  std::string summary() const;                  ///< one line, most frequent reasons first
  /// Why no view was captured, from the most frequent reason, and what to change (for a session
  /// that ends without views).
  std::string whyNoViews() const;
  /// When the capture refused most candidates for one cause, more than it kept (a board always
  /// moving, stamps apart): that cause and what to change; empty otherwise. Added to a failed
  /// result's reason, so the cause is in the headline.
  std::string whyFewViews() const;
};

class PairSession {
 public:
  PairSession(const Target& target, const SessionOptions& options);

  const Target& target() const { return target_; }
  const SessionOptions& options() const { return options_; }
  void setOptions(const SessionOptions& options) { options_ = options; }

  /// Feeds one detector output. Auto-captures (when enabled) once the pairing, stillness,
  /// agreement and diversity gates pass.
  SessionEvent addLidar(const LidarBoardFeatures& features);
  SessionEvent addCamera(const CameraBoardFeatures& features);
  /// Forces a capture of the newest synchronised pair (skips stillness and diversity, keeps
  /// the sanity gates).
  SessionEvent captureNow();
  /// Judges every image still waiting for later frames with what is there (end of a bag, or the
  /// streams went quiet). Returns the most significant event.
  SessionEvent finish();
  const CaptureStats& captureStats() const { return stats_; }
  /// Stamp of the oldest image still waiting for its judgement (its frames must be kept).
  std::optional<double> oldestPendingStamp() const {
    return pending_.empty() ? std::nullopt : std::optional<double>(pending_.front().stamp);
  }
  void setAutoCapture(bool enabled) { auto_capture_ = enabled; }
  bool autoCapture() const { return auto_capture_; }

  /// The current extrinsic estimate enables the plane-agreement gate.
  void setEstimate(const Eigen::Isometry3d& camera_T_lidar) { estimate_ = camera_T_lidar; }
  const std::optional<Eigen::Isometry3d>& estimate() const { return estimate_; }

  const std::vector<SessionView>& views() const { return views_; }
  std::vector<View> plainViews() const;
  Status dropView(int view_id);
  /// Forgets views, buffers and the estimate.
  void reset();

  CoverageReport coverage() const;

  /// Saves/loads the whole session (target, options, views with their features) as YAML.
  Status save(const std::string& path) const;
  Status load(const std::string& path);

  /// Adds a view directly (offline tools that pair features themselves, tests).
  SessionEvent addView(const View& view, const std::string& why, bool check_diversity);

 private:
  enum class Admission { kKeep, kKeepAsNoBoard, kDrop };
  Admission admit(double stamp, const std::string& malformed, const StreamClock& clock,
                  const char* stream, SessionEvent* refused);
  void forgetBuffers();
  SessionEvent decidePending(bool ended);
  SessionEvent decide(const CameraBoardFeatures& camera, bool ended, bool* decided);
  std::optional<LidarBoardFeatures> nearestLidar(double stamp, double* gap) const;
  SessionEvent skip(const std::string& kind, const std::string& why);
  void prune();
  void updateLastPair();
  SessionEvent gate(const View& view, bool forced) const;

  Target target_;
  SessionOptions options_;
  bool auto_capture_ = true;
  std::optional<Eigen::Isometry3d> estimate_;
  std::deque<LidarBoardFeatures> lidar_;
  std::deque<CameraBoardFeatures> camera_;
  std::deque<BoardSample> lidar_samples_,
      camera_samples_;  ///< stillness cues, parallel to the above
  StreamClock lidar_clock_, camera_clock_;
  std::deque<CameraBoardFeatures> pending_;  ///< images with the board awaiting their judgement
  std::optional<View> last_pair_;            ///< newest synchronised pair (manual capture)
  int hold_view_id_ = -1;                    ///< view taken in the current hold, -1 when none
  BoardSample hold_reference_;               ///< camera board of the current hold
  CaptureStats stats_;
  std::vector<SessionView> views_;
  int next_id_ = 0;
};

}  // namespace board_calib
