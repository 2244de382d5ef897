// The report folder of an MSG-Cal rig solve, written live (calibrator rig mode, ~output_dir/report)
// and offline (calibrate_bag --config --report): report.md with the rig summary (every sensor,
// every pair, loop and stereo consistency), the rejected observations and the pairwise links,
// and for every camera <- LiDAR pair its own page with the pair report's figures and per-view
// table, judged at the graph's camera_T_lidar. ROS-free.
#pragma once

#include <board_calib/core/msg_graph/msg_graph.h>
#include <board_calib/core/report/report_plots.h>
#include <board_calib/core/result_io.h>
#include <board_calib/core/rig/rig_config.h>
#include <board_calib/core/solvers/solvers.h>

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

struct RigReportInputs {
  std::string source;                    ///< "rig `FILE`, bags ..." or "live session"
  std::vector<std::string> input_lines;  ///< detection counts, capture rule (Markdown list items)
  std::string extra_result_text;         ///< appended to the printed result (e.g. errors vs truth)
  std::string verdict_text;  ///< the rig verdict in words (rigVerdictSummary), first section
  bool failed = false;       ///< failed verdict: the result is written as result.failed.yaml
  PlotOptions plots;
};

/// Writes `dir`/report.md, `dir`/result.yaml (result.failed.yaml when failed) and
/// `dir`/CAMERA__LIDAR/{report.md, edge_errors.png, pose_coverage.png} for every pair. Fails only
/// when a file cannot be written.
Status writeRigReport(const std::string& dir, const RigConfig& rig,
                      const multi_sensor::MsgProblem& problem,
                      const multi_sensor::MsgSolution& solution, const ResultFile& result,
                      const RigReportInputs& inputs);

}  // namespace board_calib
