// One calibration run of a rig (MSG-Cal, any number of cameras and LiDARs), from captured board
// poses to the judged result file: the views' consistency per camera <- LiDAR pair (observations
// that disagree with the other sensors are left out), the graph solve, and a verdict per pair and
// overall from the same tests as a pair run (core/verdict): residuals against the noise model,
// a cross-validation over poses (the graph solved without a fold of poses, each pair predicting
// them), edge MLRE where edges exist, plus the rig's own checks (loop closure of the pairwise
// estimates, known extrinsics such as a factory stereo calibration). calibrate_bag --config and
// the calibrator's rig mode both call it, so live and offline rigs are the same code.
#pragma once

#include <board_calib/core/msg_graph/msg_graph.h>
#include <board_calib/core/result_io.h>
#include <board_calib/core/rig/rig_config.h>
#include <board_calib/core/solvers/solvers.h>
#include <board_calib/core/target.h>
#include <board_calib/core/verdict/consistency.h>
#include <board_calib/core/verdict/verdict.h>

#include <string>
#include <vector>

namespace board_calib {

struct RigCalibrationOptions {
  multi_sensor::MsgGraphOptions graph;
  ConsistencyOptions consistency;
  VerdictOptions verdict;
  bool cross_validate = true;  ///< false: no left-out solves (faster, doubtful at best)
  /// Each camera <- LiDAR pair also solved with PBPC on its views and doubted when that differs
  /// beyond the combined 1 sigma (PairCalibrationOptions::check_against_pbpc: the graph rests
  /// on planes, which a LiDAR range offset moves).
  bool check_against_pbpc = true;
  SolverOptions pbpc_solver = realLidarSolverOptions();  ///< that check's PBPC
  /// Loop closure of the pairwise estimates: they are independent solves, so a loop's error is
  /// their noise added up; beyond this many times the graph's worst pair 1 sigma (and these
  /// floors) the pairwise links contradict each other.
  double loop_sigmas = 5.0;
  double min_loop_rotation_deg = 0.5;    ///< deg, floor of the loop tolerance
  double min_loop_translation_m = 0.02;  ///< m
  /// Known extrinsics (a factory stereo calibration) against the graph: beyond this many of the
  /// graph's 1 sigma of that transform, plus these floors for the known value's own error.
  double known_sigmas = 3.0;
  double known_floor_rotation_deg = 0.1;     ///< deg
  double known_floor_translation_m = 0.005;  ///< m
  std::string validate() const;
};

/// One camera <- LiDAR pair of the graph, judged as a pair run is.
struct RigPairRun {
  int camera = 0, lidar = 0;  ///< sensor indices (MsgProblem order)
  std::string camera_frame, lidar_frame;
  ConsistencyReport consistency;  ///< of the poses both sensors saw (view id = pose id)
  std::vector<View> views;        ///< the consistent views the verdict judged
  CalibrationSolution solution;   ///< the graph's pair with its residuals on those views
  VerdictReport verdict;
};

struct RigCalibration {
  multi_sensor::MsgProblem problem;  ///< as solved: inconsistent observations removed
  multi_sensor::MsgSolution solution;
  std::vector<RigPairRun> pairs;          ///< solution.pairs' order
  std::vector<std::string> left_out;      ///< observations removed before solving, with the reason
  std::vector<std::string> rig_findings;  ///< loop and known-extrinsic checks, in words
  /// Sensors the graph could not place ("frame: why"); `problem` and `solution` are then the rig
  /// without them, and the run is failed (the rig as configured is not calibrated).
  std::vector<std::string> not_calibrated;
  /// The given problem's sensor index -> the index in `problem` and `solution` (-1: not
  /// calibrated); the identity unless a sensor was left out.
  std::vector<int> solved_index;
  Verdict verdict = Verdict::kFailed;  ///< overall: the worst pair, or the rig's own checks
  std::string reason;                  ///< one line
  std::vector<int> views_to_check;     ///< pose ids
  ResultFile result;                   ///< msgResultFile + verdicts (overall and per pair)

  bool failed() const { return verdict == Verdict::kFailed; }
};

/// Runs the whole rig calibration on `problem` (the rig's sensors and captured poses). `rig`
/// supplies the known extrinsics (may be empty); `target` the board for the noise model.
RigCalibration calibrateRig(const multi_sensor::MsgProblem& problem, const RigConfig& rig,
                            const Target& target, const RigCalibrationOptions& options = {});

/// The verdict in a few lines for a terminal or a log: VERDICT, reason, each pair, poses to check.
std::string rigVerdictSummary(const RigCalibration& run);

}  // namespace board_calib
