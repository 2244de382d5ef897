// calibrate_bag's command line: the usage text, the options and their checks. A bad option
// ends the tool with a one-line reason and exit code 2 (usage), as the contract asks.
#pragma once

#include <Eigen/Geometry>

#include <optional>
#include <string>
#include <vector>

namespace board_calib {
namespace calibrate_bag {

constexpr int kExitOk = 0;
constexpr int kExitFailed = 1;
constexpr int kExitUsage = 2;

extern const char* const kUsage;

struct Args {
  std::vector<std::string> bags;
  std::string target, image_topic, info_topic, cloud_topic, method = "";
  std::optional<Eigen::Isometry3d> guess;
  std::string output, report, save_session, load_session, truth, child_frame;
  int still_frames = 0;  // 0: auto
  double sync_tolerance = -1;
  std::string loss;
  double loss_scale = -1;
  bool quiet = false;
  bool second_chance = true;
  bool scene_prepass = true;
  std::string config;  // multi-sensor rig (MSG-Cal): everything else comes from the rig file
  double check_rot_deg = 0, check_trans_m = 0;
  std::optional<double> edge_shift;  // horizontal steps outward; none: the solver's default
  std::string capture = "still";     // rig: still | all
  std::vector<int> drop_views;       // view ids left out before the final solve, ascending
};

/// One-line failure "calibrate_bag: <why>" on stderr, then exit with `code`.
[[noreturn]] void fail(const std::string& why, int code = kExitFailed);

/// The command line checked; --help prints the usage and exits 0, a bad option fails.
Args parseArgs(int argc, char** argv);

}  // namespace calibrate_bag
}  // namespace board_calib
