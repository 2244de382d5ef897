// calibrate_bag's command line (see calibrate_bag_args.h).
#include "calibrate_bag_args.h"

#include <board_calib/core/transform.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <sstream>

namespace board_calib {
namespace calibrate_bag {

const char* const kUsage =
    "usage: calibrate_bag --bag FILE [--bag FILE...] --target TARGET.yaml\n"
    "         --image-topic T --camera-info-topic T --cloud-topic T --method ppc|pbpc|msg|all\n"
    "         [--initial-guess x y z qx qy qz qw] [--output result.yaml] [--report DIR]\n"
    "         [--still-frames N] [--sync-tolerance S] [--loss none|huber|cauchy|tukey] "
    "[--loss-scale M]\n"
    "         [--child-frame F] [--save-session FILE] [--load-session FILE] [--truth TRUTH.yaml]\n"
    "         [--check-truth ROT_DEG TRANS_M] [--edge-shift STEPS] [--no-second-chance]\n"
    "         [--no-scene-prepass] [--quiet]\n"
    "       calibrate_bag --config RIG.yaml --bag FILE [--bag FILE...] --method msg [--output "
    "result.yaml]\n"
    "         [--report DIR] [--truth TRUTH.yaml [--check-truth ROT_DEG TRANS_M]] [--capture "
    "still|all]\n"
    "         [--quiet]   (docs/MSG.md)\n"
    "\n"
    "  --initial-guess     camera_T_lidar (p_camera = R p_lidar + t); default: closed-form "
    "initialisation\n"
    "  --still-frames N    frames of the fastest stream that must see the board still around an "
    "image,\n"
    "                      on both sides of it (default 2; 1: no check). Snapshot bags (every "
    "stream\n"
    "                      0.5 s or more between frames) are recognised and need no setting\n"
    "  --sync-tolerance S  max image/cloud stamp difference of one view, s, at most 1 (default "
    "0.05)\n"
    "  --load-session F    solve a saved session (no bag needed); --save-session F keeps the "
    "views\n"
    "  --drop-views IDS    leave out these views (comma-separated ids, as the verdict names them "
    "under\n"
    "                      views_to_check) and solve again; the ids are those of the loaded "
    "session, or\n"
    "                      of the same command's run without this option\n"
    "  --truth FILE        a ground-truth result file (simulate_bag's *.truth.yaml): print the "
    "errors\n"
    "  --check-truth R T   with --truth: exit non-zero if the reported result is off by more than "
    "R deg or T m\n"
    "  --edge-shift STEPS  shift LiDAR edge points outward by STEPS horizontal steps, -2 to 2 "
    "(default 0:\n"
    "                      beam divergence cancels the extremes' inset)\n"
    "  --no-second-chance  no second pass (default: when the first calibration is not failed, the "
    "bags\n"
    "                      are read again and frames whose board one sensor missed are searched "
    "where\n"
    "                      the first result puts the other sensor's board, then solved again)\n"
    "  --no-scene-prepass  plain board: no pre-pass (default: the images are read once first, one "
    "every 1.5 s,\n"
    "                      so that the rectangles and lines static over the recording are not "
    "taken for\n"
    "                      the board from the first frame on)\n"
    "  --loss, --loss-scale  robust loss on point residuals (default tukey, 0.02 m)\n"
    "  --capture MODE      rig: 'still' (default) captures one pose per hold, as the calibrator's "
    "rig mode\n"
    "                      does live; 'all' makes a board pose of every stamp group (offline "
    "only)\n";

// One-line failure, as the contract asks.
void fail(const std::string& why, int code) {
  std::cerr << "calibrate_bag: " << why << std::endl;
  std::exit(code);
}

namespace {

// Ranges of the numeric options: beyond them a value is a typo, not a setting.
constexpr double kMaxStillFrames = 1000;    // frames (at 10 Hz, 100 s of holding still)
constexpr double kMaxSyncToleranceS = 1.0;  // s; the session's limit (SessionOptions::validate)
constexpr double kMaxLossScaleM = 10.0;     // m, larger than any board
// Horizontal LiDAR steps, outward or inward: the solver's limit (SolverOptions::validate).
constexpr double kMaxEdgeShiftSteps = 2.0;
constexpr int kMaxViewId = 1000000;                // far more views than any session holds
constexpr double kQuaternionNormTolerance = 0.01;  // |q| - 1, four typed decimals pass

// A finite number, or a usage error naming the flag and the text.
double parseNumber(const std::string& flag, const std::string& text) {
  double v = 0;
  try {
    size_t used = 0;
    v = std::stod(text, &used);
    if (used != text.size()) throw std::invalid_argument(text);
  } catch (const std::exception&) {
    fail(flag + " expects a number, got '" + text + "'", kExitUsage);
  }
  if (!std::isfinite(v)) fail(flag + " expects a finite number, got '" + text + "'", kExitUsage);
  return v;
}

// A finite number in (min, max] (or [min, max] when min_inclusive).
double parseInRange(const std::string& flag, const std::string& text, double min, double max,
                    bool min_inclusive) {
  const double v = parseNumber(flag, text);
  if (v > max || v < min || (!min_inclusive && v == min)) {
    std::ostringstream s;
    s << flag << " must be in " << (min_inclusive ? "[" : "(") << min << ", " << max << "], got "
      << text;
    fail(s.str(), kExitUsage);
  }
  return v;
}

int parseCount(const std::string& flag, const std::string& text, int min, int max) {
  const double v = parseInRange(flag, text, min, max, true);
  if (v != std::floor(v)) fail(flag + " expects a whole number, got " + text, kExitUsage);
  return static_cast<int>(v);
}

// --initial-guess x y z qx qy qz qw: the quaternion must be a unit one (typed to 4 decimals).
Eigen::Isometry3d parseGuess(const double (&v)[7]) {
  const Eigen::Vector4d q(v[3], v[4], v[5], v[6]);
  if (std::abs(q.norm() - 1.0) > kQuaternionNormTolerance) {
    std::ostringstream s;
    s << "--initial-guess quaternion (qx qy qz qw) = (" << v[3] << " " << v[4] << " " << v[5] << " "
      << v[6] << ") has norm " << q.norm() << ", not 1";
    fail(s.str(), kExitUsage);
  }
  return makeTransform(Eigen::Vector3d(v[0], v[1], v[2]), q);
}

// Two names of one file (relative, through links); a path that cannot be resolved is compared
// as written rather than thrown on.
bool samePath(const std::string& a, const std::string& b) {
  std::error_code ea, eb;
  const auto ca = std::filesystem::weakly_canonical(a, ea);
  const auto cb = std::filesystem::weakly_canonical(b, eb);
  return ea || eb ? a == b : ca == cb;
}

// --drop-views 3,7: whole non-negative ids, appended to `ids`.
void parseViewIds(const std::string& flag, const std::string& text, std::vector<int>* ids) {
  std::stringstream list(text);
  std::string id;
  bool any = false;
  while (std::getline(list, id, ',')) {
    if (id.empty()) fail(flag + " expects ids separated by commas, got '" + text + "'", kExitUsage);
    ids->push_back(parseCount(flag, id, 0, kMaxViewId));
    any = true;
  }
  if (!any || text.back() == ',')
    fail(flag + " expects ids separated by commas, got '" + text + "'", kExitUsage);
}

}  // namespace

Args parseArgs(int argc, char** argv) {
  Args a;
  auto need = [&](int& i, const std::string& flag) -> std::string {
    if (i + 1 >= argc) fail(flag + " needs a value", kExitUsage);
    return argv[++i];
  };
  for (int i = 1; i < argc; ++i) {
    const std::string f = argv[i];
    if (f == "--help" || f == "-h") {
      std::cout << kUsage;
      std::exit(kExitOk);
    } else if (f == "--bag")
      a.bags.push_back(need(i, f));
    else if (f == "--target")
      a.target = need(i, f);
    else if (f == "--image-topic")
      a.image_topic = need(i, f);
    else if (f == "--camera-info-topic")
      a.info_topic = need(i, f);
    else if (f == "--cloud-topic")
      a.cloud_topic = need(i, f);
    else if (f == "--method")
      a.method = need(i, f);
    else if (f == "--output")
      a.output = need(i, f);
    else if (f == "--report")
      a.report = need(i, f);
    else if (f == "--save-session")
      a.save_session = need(i, f);
    else if (f == "--load-session")
      a.load_session = need(i, f);
    else if (f == "--truth")
      a.truth = need(i, f);
    else if (f == "--child-frame")
      a.child_frame = need(i, f);
    else if (f == "--loss")
      a.loss = need(i, f);
    else if (f == "--loss-scale")
      a.loss_scale = parseInRange(f, need(i, f), 0, kMaxLossScaleM, false);
    else if (f == "--sync-tolerance")
      a.sync_tolerance = parseInRange(f, need(i, f), 0, kMaxSyncToleranceS, false);
    else if (f == "--still-frames")
      a.still_frames = parseCount(f, need(i, f), 1, static_cast<int>(kMaxStillFrames));
    else if (f == "--quiet")
      a.quiet = true;
    else if (f == "--no-second-chance")
      a.second_chance = false;
    else if (f == "--no-scene-prepass")
      a.scene_prepass = false;
    else if (f == "--edge-shift")
      a.edge_shift = parseInRange(f, need(i, f), -kMaxEdgeShiftSteps, kMaxEdgeShiftSteps, true);
    else if (f == "--config")
      a.config = need(i, f);
    else if (f == "--capture")
      a.capture = need(i, f);
    else if (f == "--drop-views")
      parseViewIds(f, need(i, f), &a.drop_views);
    else if (f == "--check-truth") {
      a.check_rot_deg = parseInRange(f + " ROT_DEG", need(i, f), 0, 180, false);
      a.check_trans_m = parseInRange(f + " TRANS_M", need(i, f), 0, 1000, false);
    } else if (f == "--initial-guess") {
      double v[7];
      for (double& x : v) x = parseNumber(f, need(i, f));
      a.guess = parseGuess(v);
    } else {
      fail("unknown option '" + f + "' (see --help)", kExitUsage);
    }
  }
  if (a.method.empty()) fail("--method is required (ppc, pbpc, msg or all)", kExitUsage);
  if (a.capture != "all" && a.capture != "still")
    fail("--capture must be all or still, got '" + a.capture + "'", kExitUsage);
  std::sort(a.drop_views.begin(), a.drop_views.end());
  a.drop_views.erase(std::unique(a.drop_views.begin(), a.drop_views.end()), a.drop_views.end());
  if (!a.config.empty()) {
    if (!a.drop_views.empty())
      fail(
          "--drop-views is for a camera-LiDAR pair; a rig's board poses are dropped live "
          "(~drop_view)",
          kExitUsage);
    if (a.method != "msg") fail("--config (a multi-sensor rig) needs --method msg", kExitUsage);
    return a;
  }
  if (a.target.empty() && a.load_session.empty()) fail("--target is required", kExitUsage);
  // The views a user drops stay in the loaded file: it is never overwritten with fewer.
  if (!a.drop_views.empty() && !a.load_session.empty() && !a.save_session.empty() &&
      samePath(a.load_session, a.save_session))
    fail("--save-session with --drop-views would overwrite the loaded session '" + a.load_session +
             "' without the dropped views; save to another file",
         kExitUsage);
  if (a.load_session.empty()) {
    if (a.bags.empty()) fail("--bag is required", kExitUsage);
    if (a.image_topic.empty() || a.info_topic.empty() || a.cloud_topic.empty())
      fail("--image-topic, --camera-info-topic and --cloud-topic are required", kExitUsage);
  }
  return a;
}

}  // namespace calibrate_bag
}  // namespace board_calib
