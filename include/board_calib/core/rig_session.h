// Live multi-sensor session for MSG-Cal: takes the board features of N cameras and M LiDARs as
// they arrive, captures one board pose per still period (the board held still and in a new
// place), assembles every sensor's feature of that moment into a BoardPoseObservation, and keeps
// the captured poses so they can be saved, reloaded, dropped and solved again. ROS-free.
//
// Capture rule: a sensor that sees the board still for `still_frames_required` consecutive
// frames triggers a capture at its stamp, unless that sensor already saw a captured pose within
// `min_pose_rotation_deg` and `min_pose_translation_m`. The pose is assembled once every stream
// has moved past the trigger stamp plus the tolerance (late scans still make it in), or at once
// on captureNow() / flush().
#pragma once

#include <board_calib/core/msg_graph.h>
#include <board_calib/core/rig_config.h>
#include <board_calib/core/session.h>

#include <functional>
#include <limits>
#include <optional>
#include <string>
#include <vector>

namespace board_calib {
namespace msg {

struct RigSessionOptions {
  double stamp_tolerance_s = 0.05;      ///< s, a sensor's feature belongs to a pose within this of its trigger stamp
  bool auto_capture = true;             ///< capture on stillness; false: only captureNow()
  int still_frames_required = 2;        ///< consecutive frames one sensor must see the board still
  double still_max_translation_m = 0.03;  ///< m, board centre motion allowed between those frames
  double still_max_rotation_deg = 1.5;    ///< deg, board normal change allowed between those frames
  double still_max_gap_s = 1.0;         ///< s, frames further apart than this do not count as consecutive
  double min_pose_rotation_deg = 5.0;   ///< deg, a new pose's normal must differ this much ...
  double min_pose_translation_m = 0.20; ///< m, ... or its centre move this much (in the triggering sensor)
  int min_sensors = 2;                  ///< sensors that must see the board for a pose to be kept
  int max_poses = 300;                  ///< poses kept at most
  double history_s = 3.0;               ///< s, features kept per stream for assembly
  std::string validate() const;         ///< empty when usable
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
  double newest_stamp = -std::numeric_limits<double>::infinity();  ///< s, newest message (since a restart)
  bool board_now = false;   ///< the newest message saw the board
};

/// One sensor's part in the session, for diagnostics and the panel.
struct RigSensorHealth {
  std::string name;
  std::string frame;            ///< from its features (the sensor name until one arrived)
  RigSensorCounts counts;
  std::vector<int> pose_ids;    ///< captured poses it takes part in
  std::string why_no_pose;      ///< when in no pose: why, in words (empty otherwise)
};

class RigSession {
 public:
  /// `names` are the rig's sensor names, `sensors` the specs in the same (MsgProblem) order.
  RigSession(std::vector<std::string> names, std::vector<SensorSpec> sensors, RigSessionOptions options);

  /// Feed one camera / LiDAR feature of sensor `sensor` (its index in the specs). Features of
  /// the wrong kind or index give a kRejected event naming the problem.
  SessionEvent addCamera(int sensor, const CameraBoardFeatures& features);
  SessionEvent addLidar(int sensor, const LidarBoardFeatures& features);
  /// Captures the current moment now (the newest found feature's stamp), stillness and novelty
  /// not required; still needs `min_sensors` sensors.
  SessionEvent captureNow();
  /// Assembles a pending capture now (before solving or saving: the last pose of a bag).
  SessionEvent flush();

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
  /// with the measured offset of its newest message). Empty when every sensor takes part.
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
    std::optional<Summary> last;  // newest found feature
    double last_stamp = 0.0;
    int still_count = 0;
    bool triggered_this_still = false;
  };
  struct Pending {
    int sensor = -1;
    double stamp = 0.0;
    std::string why;
  };

  SessionEvent add(int sensor, double stamp, const std::optional<Summary>& summary,
                   const std::string& frame, const std::string& reason, const std::function<void(Stream&)>& keep);
  SessionEvent assemble(const Pending& pending);
  void prune();
  bool readyToAssemble(const Pending& pending) const;
  bool seenBefore(int sensor, const Summary& s, int* pose_id) const;
  std::string whyNoPose(size_t sensor) const;  // empty unless a specific reason is known
  std::optional<Summary> summaryOf(int sensor, const BoardPoseObservation& o) const;
  static std::optional<Summary> summarize(const CameraBoardFeatures& f);  // nullopt unless found
  static std::optional<Summary> summarize(const LidarBoardFeatures& f);   // nullopt unless found with points

  std::vector<std::string> names_;
  std::vector<SensorSpec> sensors_;
  RigSessionOptions options_;
  std::vector<Stream> streams_;
  std::vector<RigSensorCounts> counts_;
  std::vector<RigSessionPose> poses_;
  std::optional<Pending> pending_;
  int next_id_ = 0;
};

}  // namespace msg
}  // namespace board_calib
