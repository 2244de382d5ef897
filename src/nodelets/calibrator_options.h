// Calibrator settings shared by its pair and rig modes: dynamic_reconfigure config -> session
// options (pair mode: SessionOptions, rig mode: multi_sensor::RigSessionOptions; the test
// test/ros/test_config_defaults.cpp keeps the .cfg defaults equal to the core defaults), and
// the ~output_dir parameter.
#pragma once

#include <board_calib/CalibratorConfig.h>
#include <board_calib/core/rig/rig_session.h>
#include <board_calib/core/session/session.h>

#include <ros/node_handle.h>

#include <cstdlib>
#include <string>

// (cfg parameter, StillCaptureOptions member): the stillness settings both modes share.
#define BOARD_CALIB_STILL_CAPTURE_FIELDS(X)         \
  X(still_frames, still_frames_required)            \
  X(still_window, still_window_s)                   \
  X(still_max_translation, still_max_translation_m) \
  X(still_max_rotation_deg, still_max_rotation_deg)

// (cfg parameter, SessionOptions member) of cfg/Calibrator.cfg.
#define BOARD_CALIB_SESSION_FIELDS(X)             \
  X(sync_tolerance, sync_tolerance_s)             \
  BOARD_CALIB_STILL_CAPTURE_FIELDS(X)             \
  X(min_view_rotation_deg, min_view_rotation_deg) \
  X(min_view_translation, min_view_translation_m) \
  X(max_size_mismatch, max_size_mismatch)         \
  X(max_plane_angle_deg, max_plane_angle_deg)     \
  X(max_plane_offset, max_plane_offset_m)

// (cfg parameter, multi_sensor::RigSessionOptions member): rig mode. sync_tolerance is not among
// them: the rig file's stamp_tolerance_s applies.
#define BOARD_CALIB_RIG_SESSION_FIELDS(X)         \
  X(auto_capture, auto_capture)                   \
  BOARD_CALIB_STILL_CAPTURE_FIELDS(X)             \
  X(min_view_rotation_deg, min_pose_rotation_deg) \
  X(min_view_translation, min_pose_translation_m)

namespace board_calib {

/// `base` with the reconfigurable fields replaced.
inline SessionOptions sessionOptionsFromConfig(const CalibratorConfig& c,
                                               SessionOptions base = {}) {
#define BOARD_CALIB_ASSIGN(cfg, member) base.member = c.cfg;
  BOARD_CALIB_SESSION_FIELDS(BOARD_CALIB_ASSIGN)
#undef BOARD_CALIB_ASSIGN
  return base;
}

inline multi_sensor::RigSessionOptions rigSessionOptionsFromConfig(
    const CalibratorConfig& c, multi_sensor::RigSessionOptions base = {}) {
#define BOARD_CALIB_ASSIGN(cfg, member) base.member = c.cfg;
  BOARD_CALIB_RIG_SESSION_FIELDS(BOARD_CALIB_ASSIGN)
#undef BOARD_CALIB_ASSIGN
  return base;
}

/// ~output_dir, or when unset or empty $ROS_HOME/board_calib (else ~/.ros/board_calib).
inline std::string outputDirParam(const ros::NodeHandle& pnh) {
  std::string default_dir;
  if (const char* ros_home = std::getenv("ROS_HOME"))
    default_dir = std::string(ros_home) + "/board_calib";
  else if (const char* home = std::getenv("HOME"))
    default_dir = std::string(home) + "/.ros/board_calib";
  std::string dir;
  pnh.param("output_dir", dir, default_dir);
  return dir.empty() ? default_dir : dir;
}

}  // namespace board_calib
