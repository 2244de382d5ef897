// calibrate_bag: offline LiDAR-camera calibration straight from rosbags.
// Reads the bags with the rosbag C++ API (no master, no sim time), runs the same detectors,
// session and solvers as the nodelets, prints the result with its quality figures, and writes
// the result file and an optional report folder. Bad input ends with a one-line reason and a
// non-zero exit.
#include "calibrate_rig.h"
#include "pair_bags.h"

#include <board_calib/core/file_io.h>
#include <board_calib/core/pipeline/pair_calibration.h>
#include <board_calib/core/pipeline/pair_report.h>
#include <board_calib/core/pipeline/pipeline.h>
#include <board_calib/core/projection/projection.h>
#include <board_calib/core/report/report.h>
#include <board_calib/core/report/report_plots.h>
#include <board_calib/core/transform.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <sstream>

using namespace board_calib;

namespace {

constexpr int kExitOk = 0;
constexpr int kExitFailed = 1;
constexpr int kExitUsage = 2;

const char* kUsage =
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
    "  --sync-tolerance S  max image/cloud stamp difference of one view, s (default 0.05)\n"
    "  --load-session F    solve a saved session (no bag needed); --save-session F keeps the "
    "views\n"
    "  --truth FILE        a ground-truth result file (simulate_bag's *.truth.yaml): print the "
    "errors\n"
    "  --check-truth R T   with --truth: exit non-zero if the reported result is off by more than "
    "R deg or T m\n"
    "  --edge-shift STEPS  shift LiDAR edge points outward by STEPS horizontal steps (default 0: "
    "beam\n"
    "                      divergence cancels the extremes' inset)\n"
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
  double edge_shift = -1;         // horizontal steps; < 0: solver default
  std::string capture = "still";  // rig: still | all
};

// One-line failure, as the contract asks.
[[noreturn]] void fail(const std::string& why, int code = kExitFailed) {
  std::cerr << "calibrate_bag: " << why << std::endl;
  std::exit(code);
}

// Ranges of the numeric options: beyond them a value is a typo, not a setting.
constexpr double kMaxStillFrames = 1000;           // frames (at 10 Hz, 100 s of holding still)
constexpr double kMaxSyncToleranceS = 5.0;         // s; sensors are never further apart than this
constexpr double kMaxLossScaleM = 10.0;            // m, larger than any board
constexpr double kMaxEdgeShiftSteps = 100.0;       // horizontal LiDAR steps
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
      a.edge_shift = parseInRange(f, need(i, f), 0, kMaxEdgeShiftSteps, true);
    else if (f == "--config")
      a.config = need(i, f);
    else if (f == "--capture")
      a.capture = need(i, f);
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
  if (!a.config.empty()) {
    if (a.method != "msg") fail("--config (a multi-sensor rig) needs --method msg", kExitUsage);
    return a;
  }
  if (a.target.empty() && a.load_session.empty()) fail("--target is required", kExitUsage);
  if (a.load_session.empty()) {
    if (a.bags.empty()) fail("--bag is required", kExitUsage);
    if (a.image_topic.empty() || a.info_topic.empty() || a.cloud_topic.empty())
      fail("--image-topic, --camera-info-topic and --cloud-topic are required", kExitUsage);
  }
  return a;
}

// Streams the bags through the pipeline; a failure ends the tool.
void readBags(const Args& args, CalibrationPipeline* pipeline, std::string* camera_frame,
              std::string* lidar_frame) {
  const PairBagArgs bag_args{args.bags, args.image_topic, args.info_topic, args.cloud_topic,
                             args.quiet};
  if (const std::string why = readPairBags(bag_args, pipeline, camera_frame, lidar_frame);
      !why.empty())
    fail(why);
}

// The session's views solved by every method, with the verdict.
PairCalibration solveSession(const Args& args, const PairSession& session,
                             const std::vector<Method>& methods, const Target& target,
                             const PairCalibrationOptions& run_options, std::string* camera_frame,
                             std::string* lidar_frame) {
  const std::vector<View> views = session.plainViews();
  if (views.empty())
    fail("no view has the board in both sensors at the same time (check --sync-tolerance)");
  if (camera_frame->empty()) *camera_frame = views.front().camera.frame_id;
  if (lidar_frame->empty()) *lidar_frame = views.front().lidar.frame_id;
  PairCalibration run =
      calibratePair(views, methods, target, *camera_frame, *lidar_frame, run_options, args.guess);
  if (run.runs.empty()) fail("calibration failed: " + run.reason);  // refused before any solve
  return run;
}

// Second chance (issue 14, 3b): the bags read again with the first result as the prior, frames
// whose board one sensor missed searched where it puts the other sensor's board, and the
// session solved again with every check. Its result replaces the first unless its verdict is
// worse.
void secondPass(const Args& args, const std::vector<Method>& methods, const Target& target,
                PipelineOptions options, const PairCalibrationOptions& run_options,
                std::optional<CalibrationPipeline>* pipeline, PairCalibration* run) {
  std::string why_not;
  options.prior =
      secondChancePrior(*run, (*pipeline)->sightings(), options.second_chance, &why_not);
  const size_t first_views = run->used_views.size();
  const int candidates = secondChanceCandidates((*pipeline)->sightings(),
                                                secondChanceWindowS(options.session), target);
  if (options.prior && candidates == 0)
    why_not = "no frame where one sensor found the board and the other did not";
  if (!options.prior || candidates == 0) {
    if (!args.quiet) std::cerr << "calibrate_bag: second chance not run: " << why_not << "\n";
    return;
  }
  if (!args.quiet)
    std::cerr << "calibrate_bag: first pass: " << (*pipeline)->session().views().size()
              << " views, " << first_views << " consistent, verdict " << verdictName(run->verdict)
              << "; " << candidates
              << " frame(s) where one sensor missed the board: second pass with that result as "
                 "the prior\n";
  auto p = CalibrationPipeline::create(target, options);
  if (!p) fail(p.error());
  std::string camera_frame = run->result.camera_frame, lidar_frame = run->result.lidar_frame;
  readBags(args, &*p, &camera_frame, &lidar_frame);
  PairCalibration second =
      solveSession(args, p->session(), methods, target, run_options, &camera_frame, &lidar_frame);
  std::cout << p->stats().second_chance.summary() << "; views " << first_views << " -> "
            << second.used_views.size() << ", verdict " << verdictName(run->verdict) << " -> "
            << verdictName(second.verdict) << "\n";
  if (static_cast<int>(second.verdict) > static_cast<int>(run->verdict)) {
    std::cout << "second chance: its verdict is worse; the first pass's result is kept\n";
    return;
  }
  *run = std::move(second);
  pipeline->emplace(std::move(*p));
}

// Errors of every method against a truth file; --check-truth fails on the reported one.
void checkTruth(const Args& args, const std::vector<CalibrationSolution>& solutions,
                const CalibrationSolution& chosen, const std::string& camera_frame,
                const std::string& lidar_frame) {
  if (!args.truth.empty()) {
    auto truth = loadResultFile(args.truth);
    if (!truth) fail(truth.error());
    Eigen::Isometry3d truth_T = truth->camera_T_lidar;
    for (const auto& p : truth->pairs)
      if (p.camera_frame == camera_frame && p.lidar_frame == lidar_frame)
        truth_T = p.camera_T_lidar;
    for (const auto& s : solutions)
      if (s.success)
        std::cout << "error vs truth (" << methodName(s.method) << "): rotation "
                  << rotationErrorDeg(s.camera_T_lidar, truth_T) << " deg, translation "
                  << translationErrorM(s.camera_T_lidar, truth_T) * 1e3 << " mm\n";
    if (args.check_rot_deg > 0) {
      const double rot = rotationErrorDeg(chosen.camera_T_lidar, truth_T);
      const double trans = translationErrorM(chosen.camera_T_lidar, truth_T);
      if (rot > args.check_rot_deg || trans > args.check_trans_m)
        fail("reported result misses the truth: " + std::to_string(rot) + " deg, " +
             std::to_string(trans * 1e3) + " mm (allowed " + std::to_string(args.check_rot_deg) +
             " deg, " + std::to_string(args.check_trans_m * 1e3) + " mm)");
    }
  } else if (args.check_rot_deg > 0) {
    fail("--check-truth needs --truth", kExitUsage);
  }
}

SolverOptions solverOptions(const Args& args) {
  SolverOptions solver = realLidarSolverOptions();
  if (!args.loss.empty()) {
    auto loss = parseRobustLoss(args.loss);
    if (!loss) fail(loss.error(), kExitUsage);
    solver.loss = *loss;
  }
  if (args.loss_scale > 0) solver.loss_scale_m = args.loss_scale;
  if (args.edge_shift >= 0) solver.edge_outward_shift_steps = args.edge_shift;
  if (auto why = solver.validate(); !why.empty()) fail("solver options: " + why, kExitUsage);
  return solver;
}

// report.md with the overlays of the kept frames (core/pipeline/pair_report.h).
void writeReport(const Args& args, const PairCalibration& run, const PairSession& session,
                 const CalibrationPipeline* pipeline, const std::string& child) {
  PairReportInputs report;
  report.source = "bags:";
  for (const auto& b : args.bags) report.source += " `" + b + "`";
  if (!args.load_session.empty()) report.source = "session `" + args.load_session + "`";
  if (pipeline) {
    const PipelineStats& st = pipeline->stats();
    report.detection = "board found in " + std::to_string(st.images_with_board) + "/" +
                       std::to_string(st.images) + " images and " +
                       std::to_string(st.clouds_with_board) + "/" + std::to_string(st.clouds) +
                       " clouds";
    if (pipeline->options().prior) report.detection += "; " + st.second_chance.summary();
    report.view_images = &pipeline->viewImages();
    report.view_clouds = &pipeline->viewClouds();
    report.camera = pipeline->cameraModel();
  }
  report.child_frame = child;
  if (const Status st = writePairReport(args.report, run, session, report); !st) fail(st.reason);
  std::cout << "report written to " << args.report << "/report.md\n";
}

// A saved session (--load-session): it carries its own board, which --target must match.
void loadSavedSession(const Args& args, std::optional<Target>* target, PairSession* session) {
  const Status st = session->load(args.load_session);
  if (!st) fail(st.reason);
  // A session solved against another board would pair the wrong geometry with the features.
  if (*target && targetToYaml(**target) != targetToYaml(session->target()))
    fail("session '" + args.load_session + "' was recorded with a " +
         targetTypeName(session->target().type) + " board of " +
         std::to_string(session->target().width) + " x " +
         std::to_string(session->target().height) + " m, but --target '" + args.target +
         "' describes a " + targetTypeName((*target)->type) + " board of " +
         std::to_string((*target)->width) + " x " + std::to_string((*target)->height) +
         " m (drop --target to use the session's board)");
  *target = session->target();
  if (session->views().empty()) fail("session '" + args.load_session + "' holds no views");
}

// The folders of the files written at the end exist before the bags are read: a result must
// not be lost to a missing folder after minutes of detection.
void prepareOutputFolders(const Args& args) {
  for (const std::string& file : {args.output, args.save_session}) {
    const std::filesystem::path folder = std::filesystem::path(file).parent_path();
    if (file.empty() || folder.empty()) continue;
    std::error_code error;
    std::filesystem::create_directories(folder, error);
    if (error || !std::filesystem::is_directory(folder))
      fail("cannot create the folder '" + folder.string() + "' for '" + file +
               "': " + (error ? error.message() : "not a folder"),
           kExitUsage);
  }
}

// The result file; a failed result is kept for inspection only, under a name no tool mistakes
// for a calibration.
void writeOutput(const Args& args, const PairCalibration& run) {
  const std::string output =
      run.failed() && !args.output.empty() ? failedResultPath(args.output) : args.output;
  if (output.empty()) return;
  const Status st = writeResultFile(output, run.result);
  if (!st) fail(st.reason);
  std::cout << (run.failed() ? "FAILED result written for inspection to " : "result written to ")
            << output << "\n";
}

// Every method with its verdict, the side-by-side table, the verdict and the notes.
void printRun(const PairCalibration& run) {
  std::vector<CalibrationSolution> solutions;
  for (const auto& r : run.runs) solutions.push_back(r.solution);
  for (const auto& r : run.runs)
    std::cout << solutionSummary(r.solution) << "  verdict: " << verdictName(r.verdict.verdict)
              << " - " << r.verdict.reason << "\n";
  if (solutions.size() > 1) std::cout << "\n" << comparisonTable(solutions);
  std::cout << "\n" << verdictSummary(run);
  const CalibrationSolution& chosen = run.shownRun().solution;
  for (const auto& n : run.result.notes)
    if (std::find(chosen.notes.begin(), chosen.notes.end(), n) == chosen.notes.end())
      std::cout << "note: " << n << "\n";
}

}  // namespace

int main(int argc, char** argv) {
  const Args args = parseArgs(argc, argv);
  prepareOutputFolders(args);
  if (!args.config.empty())
    return runRigCalibration({args.config, args.bags, args.output, args.report, args.truth,
                              args.check_rot_deg, args.check_trans_m, args.quiet, args.capture});
  const auto wall_start = std::chrono::steady_clock::now();

  const auto parsed_methods = parseMethods(args.method);
  if (!parsed_methods) fail(parsed_methods.error(), kExitUsage);
  const std::vector<Method> methods = *parsed_methods;

  const SolverOptions solver = solverOptions(args);

  PipelineOptions options;
  if (args.sync_tolerance > 0) options.session.sync_tolerance_s = args.sync_tolerance;
  std::optional<Target> target;
  if (!args.target.empty()) {
    auto t = loadTarget(args.target);
    if (!t) fail(t.error());
    target = *t;
  }

  std::optional<CalibrationPipeline> pipeline;
  PairSession loaded_session(target ? *target : Target{}, options.session);
  const PairSession* session = nullptr;
  std::string camera_frame, lidar_frame;

  if (!args.load_session.empty()) {
    loadSavedSession(args, &target, &loaded_session);
    session = &loaded_session;  // the session carries its own target
  } else {
    // Stillness is judged by the fastest stream around each image; snapshot recordings (every
    // stream sparse) are recognised from the measured rates (core/capture/stillness.h).
    if (args.still_frames > 0) options.session.still_frames_required = args.still_frames;

    // The whole recording is at hand: the image memory knows the static scene from the first frame.
    if (!args.scene_prepass) options.image_prepass.frames_per_static = 0;
    const PairBagArgs bag_args{args.bags, args.image_topic, args.info_topic, args.cloud_topic,
                               args.quiet};
    if (const std::string why = learnImageScene(bag_args, *target, &options); !why.empty())
      fail(why);
    auto p = CalibrationPipeline::create(*target, options);
    if (!p) fail(p.error());
    pipeline.emplace(std::move(*p));
    readBags(args, &*pipeline, &camera_frame, &lidar_frame);
    session = &pipeline->session();
  }
  // Consistency, every method, the verdict and the choice: the same run as the live calibrator's.
  PairCalibrationOptions run_options;
  run_options.solver = solver;
  PairCalibration run =
      solveSession(args, *session, methods, *target, run_options, &camera_frame, &lidar_frame);
  if (pipeline && args.second_chance) {
    secondPass(args, methods, *target, options, run_options, &pipeline, &run);
    session = &pipeline->session();
  }
  if (!args.save_session.empty()) {
    const Status st = session->save(args.save_session);
    if (!st) fail(st.reason);
  }
  std::vector<CalibrationSolution> solutions;
  for (const auto& r : run.runs) solutions.push_back(r.solution);
  printRun(run);
  const CalibrationSolution& chosen = run.shownRun().solution;
  writeOutput(args, run);

  const std::string child = args.child_frame.empty() ? camera_frame : args.child_frame;

  checkTruth(args, solutions, chosen, camera_frame, lidar_frame);

  if (!args.report.empty())
    writeReport(args, run, *session, pipeline ? &*pipeline : nullptr, child);
  if (run.failed()) fail("calibration failed: " + run.reason);
  if (!args.quiet)
    std::cerr
        << "calibrate_bag: done in "
        << std::chrono::duration<double>(std::chrono::steady_clock::now() - wall_start).count()
        << " s\n";
  return kExitOk;
}
