// One calibration run of a camera/LiDAR pair, from collected views to the result file: the
// consistency check, the solve of every asked method from the consensus start, the verdict of
// each (cross-validation included), the choice of the method to report and the result file.
// calibrate_bag and the calibrator nodelet both call it, so live and offline runs are the same
// code by construction.
#pragma once

#include <board_calib/core/result_io.h>
#include <board_calib/core/solvers/solvers.h>
#include <board_calib/core/target.h>
#include <board_calib/core/verdict/consistency.h>
#include <board_calib/core/verdict/verdict.h>

#include <optional>
#include <string>
#include <vector>

namespace board_calib {

struct PairCalibrationOptions {
  SolverOptions solver = realLidarSolverOptions();
  ConsistencyOptions consistency;
  VerdictOptions verdict;
  bool cross_validate = true;  ///< false: no left-out solves (faster, doubtful at best)
  /// PPC or MSG asked without PBPC: also solve PBPC on the same views (not reported as a run)
  /// and doubt the asked method when PBPC differs beyond its combined 1 sigma. The planes move
  /// with a LiDAR range offset, the edges do not: 3 cm gave PPC and MSG "good" 31 mm off.
  bool check_against_pbpc = true;
  std::string validate() const;
};

struct MethodRun {
  CalibrationSolution solution;
  VerdictReport verdict;
};

struct PairCalibration {
  ConsistencyReport consistency;
  std::vector<View> used_views;        ///< the consistent views the methods were solved on
  std::vector<MethodRun> runs;         ///< one per asked method, in order
  int chosen = -1;                     ///< index into runs; -1 when every method failed
  std::string choice;                  ///< why that method, in words
  Verdict verdict = Verdict::kFailed;  ///< of the chosen run (failed when none)
  std::string reason;                  ///< one line
  ResultFile result;  ///< the chosen run's (or the first run's when all failed), with the verdict

  bool failed() const { return verdict == Verdict::kFailed; }
  const MethodRun* chosenRun() const {
    return chosen >= 0 ? &runs[static_cast<size_t>(chosen)] : nullptr;
  }
  /// The run the result file shows: the chosen one, or the first when every method failed.
  /// Needs at least one run (calibratePair makes one per asked method).
  const MethodRun& shownRun() const { return runs[chosen >= 0 ? static_cast<size_t>(chosen) : 0]; }
};

/// Methods by name: "ppc", "pbpc", "msg" or "all".
Expected<std::vector<Method>> parseMethods(const std::string& name);

/// PPC and MSG put the LiDAR's board planes on the camera's: a LiDAR range offset (or a declared
/// size) moves every plane along its view and the translation follows, with residuals as the
/// noise predicts, while PBPC's edges hardly move. A PBPC solve on `views` judged as a run
/// (nullopt when it fails or its verdict does), to check a plane method's result against.
std::optional<MethodRun> pbpcReferee(const std::vector<View>& views, const Target& target,
                                     const ConsistencyReport& consistency,
                                     const SolverOptions& solver, const VerdictOptions& verdict,
                                     bool cross_validate,
                                     const std::optional<Eigen::Isometry3d>& start);
/// `verdict` (of `solution`) doubtful when the referee differs beyond their combined 1 sigma,
/// saying why the two can differ.
void judgeAgainstPbpc(const MethodRun& referee, const CalibrationSolution& solution,
                      const VerdictOptions& options, VerdictReport* verdict);

PairCalibration calibratePair(const std::vector<View>& views, const std::vector<Method>& methods,
                              const Target& target, const std::string& camera_frame,
                              const std::string& lidar_frame,
                              const PairCalibrationOptions& options = {},
                              const std::optional<Eigen::Isometry3d>& initial_guess = std::nullopt);

/// The verdict in a few lines for a terminal or a log: VERDICT, reason, method choice, views to
/// check.
std::string verdictSummary(const PairCalibration& run);

}  // namespace board_calib
