// dynamic_reconfigure config -> session options of the calibrator (pair mode: SessionOptions,
// rig mode: msg::RigSessionOptions), shared by the nodelet and the test that keeps the .cfg
// defaults equal to the core defaults (test/ros/test_config_defaults.cpp).
#pragma once

#include <board_calib/CalibratorConfig.h>
#include <board_calib/core/rig_session.h>
#include <board_calib/core/session.h>

// (cfg parameter, SessionOptions member) of cfg/Calibrator.cfg.
#define BOARD_CALIB_SESSION_FIELDS(X)                           \
  X(sync_tolerance, sync_tolerance_s)                           \
  X(still_frames, still_frames_required)                        \
  X(still_max_translation, still_max_translation_m)             \
  X(still_max_rotation_deg, still_max_rotation_deg)             \
  X(min_view_rotation_deg, min_view_rotation_deg)               \
  X(min_view_translation, min_view_translation_m)               \
  X(max_size_mismatch, max_size_mismatch)                       \
  X(max_plane_angle_deg, max_plane_angle_deg)                   \
  X(max_plane_offset, max_plane_offset_m)

// (cfg parameter, msg::RigSessionOptions member): rig mode. sync_tolerance is not among them:
// the rig file's stamp_tolerance_s applies.
#define BOARD_CALIB_RIG_SESSION_FIELDS(X)                       \
  X(auto_capture, auto_capture)                                 \
  X(still_frames, still_frames_required)                        \
  X(still_max_translation, still_max_translation_m)             \
  X(still_max_rotation_deg, still_max_rotation_deg)             \
  X(min_view_rotation_deg, min_pose_rotation_deg)               \
  X(min_view_translation, min_pose_translation_m)

namespace board_calib {

/// `base` with the reconfigurable fields replaced.
inline SessionOptions sessionOptionsFromConfig(const CalibratorConfig& c, SessionOptions base = {}) {
#define BOARD_CALIB_ASSIGN(cfg, member) base.member = c.cfg;
  BOARD_CALIB_SESSION_FIELDS(BOARD_CALIB_ASSIGN)
#undef BOARD_CALIB_ASSIGN
  return base;
}

inline msg::RigSessionOptions rigSessionOptionsFromConfig(const CalibratorConfig& c, msg::RigSessionOptions base = {}) {
#define BOARD_CALIB_ASSIGN(cfg, member) base.member = c.cfg;
  BOARD_CALIB_RIG_SESSION_FIELDS(BOARD_CALIB_ASSIGN)
#undef BOARD_CALIB_ASSIGN
  return base;
}

}  // namespace board_calib
