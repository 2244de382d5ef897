// Rig mode of the calibrator nodelet (~rig_file set): N camera and M LiDAR feature streams from
// a rig YAML (docs/MSG.md), board poses captured by a multi_sensor::RigSession, ~calibrate solves
// the MSG-Cal graph and broadcasts every sensor's pose from the reference frame. Thin wiring only.
#pragma once

#include <ros/ros.h>

#include <memory>
#include <string>

namespace board_calib {

class RigCalibratorMode {
 public:
  /// Loads the rig and sets up topics and services; nullptr with `error` set on bad config.
  static std::unique_ptr<RigCalibratorMode> create(ros::NodeHandle nh, ros::NodeHandle pnh,
                                                   const std::string& rig_file, std::string* error);
  ~RigCalibratorMode();

 private:
  RigCalibratorMode();
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace board_calib
