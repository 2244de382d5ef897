// Turns solver results into what users read: the result file, a summary with
// the quality figures and what they mean, a side-by-side table of methods, per-view tables,
// consistency findings (e.g. the board is larger than declared) and ready-to-paste snippets.
#pragma once

#include <board_calib/core/result_io.h>
#include <board_calib/core/solvers/solvers.h>
#include <board_calib/core/target.h>

#include <string>
#include <vector>

namespace board_calib {

/// Findings about the data, independent of the solve: LiDAR-measured board size against the
/// declared target, camera plane vs LiDAR points offset, the estimated plane scale.
std::vector<std::string> consistencyNotes(const std::vector<View>& views, const Target& target,
                                          const CalibrationSolution& solution);

/// One clause naming a declared board size the data contradict: the LiDAR's measured size, else
/// the plane scale the solve estimated, off by more than 10 % (past what LiDAR edge bloom gives);
/// "" otherwise. A verdict that is not good adds it to its reason, since a wrong target file
/// makes views disagree for no visible reason.
std::string declaredSizeDoubt(const std::vector<View>& views, const Target& target,
                              const CalibrationSolution& solution);

/// The contract result file, with quality figures and notes.
ResultFile makeResultFile(const CalibrationSolution& solution, const std::vector<View>& views,
                          const Target& target, const std::string& camera_frame,
                          const std::string& lidar_frame);

/// Multi-line human-readable summary: pose, quality figures with their meaning, notes. With
/// `judged`, the 1 sigma shown is the verdict's (the one the result file carries) and the
/// solver's own is named beside it; without, the solver's.
std::string solutionSummary(const CalibrationSolution& solution,
                            const PoseStddev* judged = nullptr);
/// One row per method: MLRE, plane RMS, 1 sigma, pose difference to the first successful row.
/// With `judged` (one per solution), the 1 sigma columns are the verdicts'.
std::string comparisonTable(const std::vector<CalibrationSolution>& solutions,
                            const std::vector<PoseStddev>* judged = nullptr);
/// Per-view residuals (Markdown table).
std::string perViewTable(const CalibrationSolution& solution);

/// `<node pkg="tf2_ros" type="static_transform_publisher" .../>` broadcasting the camera in the
/// LiDAR frame (parent LiDAR, child `child_frame`).
std::string staticTransformLaunchSnippet(const ResultFile& result, const std::string& child_frame);
/// A URDF `<joint>` placing the camera frame under the LiDAR frame.
std::string urdfJointSnippet(const ResultFile& result, const std::string& child_frame);

/// Picks the solution to report for "all": the smallest MLRE among successful ones that have
/// it, otherwise the smallest plane RMS. Returns -1 when none succeeded.
int bestSolutionIndex(const std::vector<CalibrationSolution>& solutions);

}  // namespace board_calib
