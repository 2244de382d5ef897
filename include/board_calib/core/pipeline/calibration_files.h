// The calibrator's files in its output folder, for the pair and the rig mode alike: the result
// file with its ready-to-use snippets, a failed result kept for inspection, and the autosaved
// session's run bookkeeping (resume after a respawn, else move it aside). ROS-free: the caller
// passes the run id and the clock.
#pragma once

#include <board_calib/core/msg_graph/msg_graph.h>
#include <board_calib/core/result_io.h>
#include <board_calib/core/rig/rig_session.h>

#include <string>
#include <utility>
#include <vector>

namespace board_calib {

/// A text file written next to the result: (file name suffix, text).
using Snippet = std::pair<std::string, std::string>;

/// Writes `dir`/NAME_result.yaml (creating `dir`) and `dir`/NAME + suffix for every snippet.
/// Returns the result file's path; a snippet that cannot be written is named in `warnings`
/// (the result file is what matters).
Expected<std::string> writeCalibrationFiles(const std::string& dir, const std::string& name,
                                            const ResultFile& file,
                                            const std::vector<Snippet>& snippets,
                                            std::vector<std::string>* warnings);

/// A failed result, under a name no tool mistakes for a calibration:
/// `dir`/NAME_result.failed.yaml. Returns its path.
Expected<std::string> writeFailedCalibrationFile(const std::string& dir, const std::string& name,
                                                 const ResultFile& file);

/// One static_transform_publisher per sensor from the reference sensor's frame (child frames
/// with `child_suffix`), ready to paste into a bring-up launch file.
std::string rigStaticTransformsLaunch(const multi_sensor::MsgSolution& solution,
                                      const std::string& child_suffix);

/// One line per sensor for the rig report's input section: board hits and poses joined.
std::vector<std::string> rigHealthLines(const std::vector<multi_sensor::RigSensorHealth>& health);

/// `output_dir`/`file_name`, the folder created: where the session is autosaved.
Expected<std::string> autosavePath(const std::string& output_dir, const std::string& file_name);

/// An autosaved session found at start-up.
struct AutosaveRun {
  bool exists = false;     ///< there is an autosave to resume or move aside
  bool respawned = false;  ///< it was written in this same run (the manager restarted)
};
/// Checks `path` and the run id recorded beside it (`path`.run_id), then records `run_id` there
/// for the next start.
AutosaveRun checkAutosaveRun(const std::string& path, const std::string& run_id);
/// Moves an autosave that is not resumed aside to `path`.STAMP (never overwritten unseen).
/// Returns the new path.
Expected<std::string> moveAutosaveAside(const std::string& path, long long stamp_s);

}  // namespace board_calib
