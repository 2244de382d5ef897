// Live multi-sensor session for MSG-Cal: takes the board features of N cameras and M LiDARs as
// they arrive, captures one board pose per hold (the board held still in a new place),
// assembles every sensor's feature of that moment into a BoardPoseObservation, and keeps the
// captured poses so they can be saved, reloaded, dropped and solved again. ROS-free.
//
// Capture rule: the same stillness judge as the pair session (capture/stillness.h). Every
// found frame of any sensor is a candidate moment, judged once
// every active stream has passed the still window around it: the streams that see the board
// there must agree it is still, the fastest of them counted on both sides of the moment;
// snapshot recordings (every stream sparse) make every moment a candidate. A still moment seen
// by `min_sensors` sensors within `stamp_tolerance_s` becomes a pose, unless a sensor already
// saw a captured pose there (`min_pose_*`); later frames of the same hold replace it when they
// are better (more sensors, closer stamps). Why candidates were skipped is counted in words.
#pragma once

#include <board_calib/core/capture/stillness.h>
#include <board_calib/core/msg_graph/msg_graph.h>
#include <board_calib/core/rig/rig_config.h>
#include <board_calib/core/session/session.h>

#include <deque>

#include <functional>
#include <limits>
#include <optional>
#include <set>
#include <string>
#include <vector>

namespace board_calib {
namespace multi_sensor {

/// The rig session's options; the stillness settings are the pair session's
/// (StillCaptureOptions).
struct RigSessionOptions : StillCaptureOptions {
  double stamp_tolerance_s =
      0.05;                  ///< s, a sensor's feature belongs to a pose within this of its moment
  bool auto_capture = true;  ///< capture on stillness; false: only captureNow()
  double min_pose_rotation_deg = 5.0;  ///< deg, a new pose's normal must differ this much ...
  double min_pose_translation_m =
      0.20;                ///< m, ... or its centre move this much (in every sensor that saw both)
  int min_sensors = 2;     ///< sensors that must see the board for a pose to be kept
  int max_poses = 300;     ///< poses kept at most
  double history_s = 3.0;  ///< s, features kept per stream for assembly and judgement
  std::string validate() const;  ///< empty when usable
};

/// Defaults with the rig file's stamp tolerance (and a history long enough for it).
RigSessionOptions rigSessionOptionsFor(const RigConfig& rig);

/// One captured pose with why it was kept.
struct RigSessionPose {
  BoardPoseObservation observation;
  std::string why;
};

/// Messages seen per sensor (for diagnostics).
struct RigSensorCounts {
  int messages = 0;
  int found = 0;
  std::string last_reason;  ///< newest "not found" reason
  double newest_stamp =
      -std::numeric_limits<double>::infinity();  ///< s, newest message (since a restart)
  bool board_now = false;                        ///< the newest message saw the board
  int lost_at_capture = 0;  ///< poses captured without it: it lost the board around the moment
};

/// One sensor's part in the session, for diagnostics and the panel.
struct RigSensorHealth {
  std::string name;
  std::string frame;  ///< from its features (the sensor name until one arrived)
  RigSensorCounts counts;
  std::vector<int> pose_ids;  ///< captured poses it takes part in
  std::string why_no_pose;    ///< when in no pose: why, in words (empty otherwise)
};

class RigSession {
 public:
  /// `names` are the rig's sensor names, `sensors` the specs in the same (MsgProblem) order;
  /// `target` (when known) sizes the cameras' stillness noise.
  RigSession(std::vector<std::string> names, std::vector<SensorSpec> sensors,
             RigSessionOptions options, std::optional<Target> target = std::nullopt);

  /// Feed one camera / LiDAR feature of sensor `sensor` (its index in the specs). Features of
  /// the wrong kind or index give a kRejected event naming the problem.
  SessionEvent addCamera(int sensor, const CameraBoardFeatures& features);
  SessionEvent addLidar(int sensor, const LidarBoardFeatures& features);
  /// Captures the current moment now (the newest found feature's stamp), stillness and novelty
  /// not required; still needs `min_sensors` sensors.
  SessionEvent captureNow();
  /// Judges every candidate still waiting for later frames with what is there (end of a bag,
  /// before solving or saving). Returns the most significant event.
  SessionEvent flush();
  /// Why candidates were captured or skipped, counted by kind.
  const CaptureStats& captureStats() const { return stats_; }

  const std::vector<RigSessionPose>& poses() const { return poses_; }
  /// The problem to solve: sensors (frames from the features seen) and every captured pose.
  MsgProblem problem(int reference_sensor) const;
  Status dropPose(int id);
  void reset();  ///< drops every pose and the stream state
  const std::vector<SensorSpec>& sensors() const { return sensors_; }
  const std::vector<std::string>& names() const { return names_; }
  const std::vector<RigSensorCounts>& counts() const { return counts_; }
  const RigSessionOptions& options() const { return options_; }
  /// Captured poses each sensor takes part in (index as the specs).
  std::vector<int> posesPerSensor() const;
  /// Per sensor (index as the specs): counts, whether it sees the board now, the poses it joined
  /// and, when none, why.
  std::vector<RigSensorHealth> health() const;
  /// Specific hints about sensors that do not join the poses: never saw the board (with the last
  /// reason), or saw it often but never within stamp_tolerance_s of the others (stamps offset,
  /// with the measured offset of its newest message); and about sensors that stopped publishing
  /// while the others went on. Empty when every sensor takes part throughout.
  std::vector<std::string> problems() const;
  void setOptions(const RigSessionOptions& options) { options_ = options; }

  /// Saves / loads the captured poses (features, not images) as YAML. Loading checks that the
  /// file's sensors (kinds, in order) match this rig and replaces the current poses.
  Status save(const std::string& path) const;
  Status load(const std::string& path);

 private:
  struct Summary {  // where a sensor sees the board: centre and plane normal in its frame
    Eigen::Vector3d centre = Eigen::Vector3d::Zero();
    Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();
  };
  struct Stream {
    std::vector<CameraBoardFeatures> cameras;  // found features, stamp order
    std::vector<LidarBoardFeatures> lidars;
    std::deque<BoardSample> samples;  // every frame (found or not), for the stillness judge
    StreamClock clock;
  };
  struct Candidate {
    int sensor = -1;
    double stamp = 0.0;
  };

  SessionEvent add(int sensor, double stamp, const BoardSample& sample, const std::string& frame,
                   const std::string& reason, const std::function<void(Stream&)>& keep);
  SessionEvent decideCandidates(bool ended);
  SessionEvent decide(const Candidate& c);
  SessionEvent skip(const std::string& kind, const std::string& why);
  SessionEvent keepPose(BoardPoseObservation o, const std::string& why, bool snapshot);
  BoardPoseObservation observationAt(double stamp, const std::set<int>& left_out,
                                     std::string* seen_by) const;
  bool readyToJudge(const Candidate& c) const;
  // How far the other streams' clocks went on since stream k last spoke (s; 0 when none did).
  // Offset clocks cancel out, so a stream that stopped is told from one that lags.
  double silentFor(size_t k) const;
  bool seenBefore(const BoardPoseObservation& o, int* pose_id) const;
  bool sameHold(const BoardPoseObservation& o) const;
  void prune();
  std::string whyNoPose(size_t sensor) const;  // empty unless a specific reason is known
  std::string whySilent(size_t sensor) const;  // empty unless it stopped while others went on
  std::optional<Summary> summaryOf(int sensor, const BoardPoseObservation& o) const;
  static std::optional<Summary> summarize(const CameraBoardFeatures& f);  // nullopt unless found
  static std::optional<Summary> summarize(
      const LidarBoardFeatures& f);  // nullopt unless found with points

  std::vector<std::string> names_;
  std::vector<SensorSpec> sensors_;
  RigSessionOptions options_;
  std::optional<Target> target_;
  std::vector<Stream> streams_;
  std::vector<RigSensorCounts> counts_;
  std::vector<std::vector<double>> newest_when_heard_;  // [k][j]: j's newest stamp when k spoke
  std::vector<RigSessionPose> poses_;
  std::deque<Candidate> candidates_;  // stamp order, awaiting their judgement
  int hold_pose_id_ = -1;             // pose taken in the current hold, -1 when none
  CaptureStats stats_;
  int next_id_ = 0;
};

}  // namespace multi_sensor
}  // namespace board_calib
