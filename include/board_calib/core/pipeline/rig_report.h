// The report folder of an MSG-Cal rig solve, written live (calibrator rig mode, ~output_dir/report)
// and offline (calibrate_bag --config --report): report.md with the rig summary (every sensor,
// every pair, loop and stereo consistency), the rejected observations and the pairwise links,
// and for every camera <- LiDAR pair its own page with the pair report's figures and per-view
// table, judged at the graph's camera_T_lidar. ROS-free.
#pragma once

#include <board_calib/core/camera_model.h>
#include <board_calib/core/msg_graph/msg_graph.h>
#include <board_calib/core/report/report_plots.h>
#include <board_calib/core/result_io.h>
#include <board_calib/core/rig/rig_config.h>
#include <board_calib/core/solvers/solvers.h>

#include <opencv2/core.hpp>

#include <map>
#include <string>
#include <vector>

namespace board_calib {

/// One camera <- LiDAR pair of a rig solve, as the pair solvers would report it.
struct RigPairEvaluation {
  std::string camera_frame, lidar_frame;
  std::string folder;              ///< subfolder of the report ("CAMERA__LIDAR")
  std::vector<View> views;         ///< the board poses both sensors saw (view id = pose id)
  CalibrationSolution evaluation;  ///< residuals of those views at the graph's camera_T_lidar
};

/// Every camera <- LiDAR pair of `result` (msgResultFile of `problem` and `solution`): its
/// views and, per view and edge, the residuals at the graph's pose (MLRE, plane distances), with
/// the graph's 1 sigma. A pair without a shared pose has no views and success = false.
std::vector<RigPairEvaluation> evaluateRigPairs(const multi_sensor::MsgProblem& problem,
                                                const multi_sensor::MsgSolution& solution,
                                                const ResultFile& result);

/// A raw camera image kept for the report's overlays, with the intrinsics valid at its time.
struct RigFrame {
  cv::Mat image;
  CameraIntrinsics intrinsics;
};
/// The raw images one camera kept for the overlays (RigPipeline::overlayFrames).
struct RigCameraFrames {
  int sensor = -1;                    ///< index in MsgProblem order
  std::map<double, RigFrame> images;  ///< stamp (s) -> frame; drawn where a pose has that stamp
};

struct RigReportInputs {
  std::string source;                    ///< "rig `FILE`, bags ..." or "live session"
  std::vector<std::string> input_lines;  ///< detection counts, capture rule (Markdown list items)
  std::string extra_result_text;         ///< appended to the printed result (e.g. errors vs truth)
  std::string verdict_text;  ///< the rig verdict in words (rigVerdictSummary), first section
  bool failed = false;       ///< failed verdict: the result is written as result.failed.yaml
  PlotOptions plots;
  /// Raw images per camera for the overlays (offline); empty: `overlays_note` says why not.
  std::vector<RigCameraFrames> camera_frames;
  std::string overlays_note;  ///< why there are no overlays (e.g. a live session)
};

/// Writes `dir`/report.md, `dir`/result.yaml (result.failed.yaml when failed),
/// `dir`/CAMERA__LIDAR/{report.md, edge_errors.png, pose_coverage.png} for every pair and, for
/// every kept camera image that belongs to a pose, `dir`/overlays/CAMERA_pose_ID.jpg with every
/// LiDAR of that pose drawn at the graph's camera_T_lidar (board points and projected edges),
/// linked from the rig report and the camera's pair pages. Fails only when a file cannot be
/// written.
Status writeRigReport(const std::string& dir, const RigConfig& rig,
                      const multi_sensor::MsgProblem& problem,
                      const multi_sensor::MsgSolution& solution, const ResultFile& result,
                      const RigReportInputs& inputs);

}  // namespace board_calib
