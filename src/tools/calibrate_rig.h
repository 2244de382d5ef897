// Multi-sensor (MSG-Cal) mode of calibrate_bag: `calibrate_bag --config RIG.yaml --method msg`.
#pragma once

#include <string>
#include <vector>

namespace board_calib {

struct RigArgs {
  std::string config;  ///< rig YAML (docs/MSG.md)
  std::vector<std::string> bags;
  std::string output;  ///< result file (empty: none)
  std::string report;  ///< report folder (empty: none)
  std::string truth;   ///< ground-truth result file (empty: none)
  double check_rotation_deg =
      0.0;  ///< deg, > 0 with `truth`: fail when a pair's rotation error exceeds it
  double check_translation_m =
      0.0;  ///< m, > 0 with `truth`: fail when a pair's translation error exceeds it
  bool quiet = false;
  std::string capture =
      "still";  ///< "still": one pose per hold (the live rule); "all": a pose per stamp group
};

/// Runs the whole rig calibration; returns the process exit code (0 ok, 1 failed, 2 usage).
/// Bad input prints a one-line reason on stderr.
int runRigCalibration(const RigArgs& args);

}  // namespace board_calib
