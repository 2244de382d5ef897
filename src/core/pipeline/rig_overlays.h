// The rig report's overlays (private to the pipeline module): per camera, every kept raw image
// that belongs to a board pose, with each LiDAR of that pose drawn at the graph's
// camera_T_lidar by the pair report's drawing (core/projection/view_overlay.h).
#pragma once

#include <board_calib/core/pipeline/rig_report.h>

#include <optional>
#include <string>
#include <vector>

namespace board_calib {

struct RigOverlayLidar {
  std::string frame;
  std::optional<double> inside;   ///< share of its board points inside the image board
  std::optional<double> mlre_px;  ///< its projected-edges check
};

struct RigOverlay {
  std::string camera_frame;
  int pose_id = -1;
  std::string file;  ///< relative to the report folder
  std::vector<RigOverlayLidar> lidars;
};

/// Draws and writes `dir`/overlays/CAMERA_pose_ID.jpg for every kept image of `frames` whose
/// camera saw a pose (same stamp) with at least one LiDAR. Fails when a file cannot be written.
Expected<std::vector<RigOverlay>> writeRigOverlays(const std::string& dir,
                                                   const multi_sensor::MsgProblem& problem,
                                                   const multi_sensor::MsgSolution& solution,
                                                   const ResultFile& result,
                                                   const std::vector<RigCameraFrames>& frames);

/// Markdown: the overlays of camera `camera_frame` (every camera when empty), links prefixed
/// with `prefix`, with the figures of LiDAR `lidar_frame` only when given.
std::string rigOverlaysMarkdown(const std::vector<RigOverlay>& overlays,
                                const std::string& camera_frame, const std::string& lidar_frame,
                                const std::string& prefix);

}  // namespace board_calib
