// Multi-sensor session helper for the MSG graph: groups per-sensor feature streams by stamp
// into board poses (one observation per sensor per pose), for `calibrate_bag --method msg` and
// the calibrator's N-camera / M-LiDAR mode. ROS-free.
#pragma once

#include <board_calib/core/msg_graph/msg_graph.h>

#include <map>
#include <vector>

namespace board_calib {
namespace multi_sensor {

struct GroupingOptions {
  double stamp_tolerance_s =
      0.05;             ///< s, features of one board pose lie within this of its first stamp
  int min_sensors = 2;  ///< sensors with a found board needed to keep a board pose
  std::string validate() const;
};

struct GroupingReport {
  std::vector<BoardPoseObservation> poses;  ///< ids 0, 1, ... in stamp order
  int features_in = 0;                      ///< found features given
  int features_used = 0;                    ///< placed in a kept board pose
  int groups_dropped = 0;                   ///< stamp groups with fewer than min_sensors sensors
  int duplicates_dropped = 0;  ///< a second feature of one sensor within a group (the farther one)
};

/// Groups the streams (keyed by sensor index into `sensors`; features with found = false are
/// ignored) by stamp. Greedy in stamp order: a group opens at the earliest unassigned feature
/// and takes, per sensor, the feature closest to that stamp within the tolerance. Fails with a
/// reason when a stream is keyed to a sensor of the other kind or out of range.
Expected<GroupingReport> groupByStamp(
    const std::vector<SensorSpec>& sensors,
    const std::map<int, std::vector<CameraBoardFeatures>>& cameras,
    const std::map<int, std::vector<LidarBoardFeatures>>& lidars, const GroupingOptions& options);

}  // namespace multi_sensor
}  // namespace board_calib
