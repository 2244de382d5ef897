// calibrate_bag: offline LiDAR-camera calibration straight from rosbags.
// Reads the bags with the rosbag C++ API (no master, no sim time), runs the same detectors,
// session and solvers as the nodelets, prints the result with its quality figures, and writes
// the result file and an optional report folder. Bad input ends with a one-line reason and a
// non-zero exit.
#include "calibrate_bag_args.h"
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
using namespace board_calib::calibrate_bag;

namespace {

// A failed run's reason with the capture's cause when that refused most candidates (a board
// always moving leaves too few views; the views' reason alone hides why).
std::string withCaptureCause(const std::string& reason, const CaptureStats& capture) {
  const std::string cause = capture.whyFewViews();
  return cause.empty() ? reason : reason + "; " + cause;
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
  if (views.empty()) fail(session.captureStats().whyNoViews());
  if (camera_frame->empty()) *camera_frame = views.front().camera.frame_id;
  if (lidar_frame->empty()) *lidar_frame = views.front().lidar.frame_id;
  PairCalibration run =
      calibratePair(views, methods, target, *camera_frame, *lidar_frame, run_options, args.guess);
  if (run.runs.empty())  // refused before any solve
    fail("calibration failed: " + withCaptureCause(run.reason, session.captureStats()));
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
  std::string consensus;
  if (!options.prior && target.type == TargetType::kPlain) {
    // No first calibration: the session's moving board may still fix a prior.
    std::string why_consensus;
    options.prior = consensusPrior((*pipeline)->sightings(), options.session.sync_tolerance_s,
                                   target, options.second_chance, &why_consensus, &consensus);
    if (!options.prior) why_not += "; no prior from the session's boards either: " + why_consensus;
  }
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
              << " frame(s) where one sensor missed the board: second pass with "
              << (consensus.empty() ? "that result"
                                    : "a prior from the session's boards (" + consensus + ")")
              << " as the prior\n";
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

// Ascending ids as ranges: "0-3, 5, 7-9".
std::string idRanges(std::vector<int> ids) {
  std::sort(ids.begin(), ids.end());
  std::string out;
  for (size_t i = 0; i < ids.size();) {
    size_t j = i;
    while (j + 1 < ids.size() && ids[j + 1] == ids[j] + 1) ++j;
    out += (out.empty() ? "" : ", ") + std::to_string(ids[i]) +
           (j > i ? "-" + std::to_string(ids[j]) : std::string());
    i = j + 1;
  }
  return out.empty() ? "none" : out;
}

// --drop-views: the views the user judged bad are left out and the session is solved again with
// every check, so the verdict is the one of the views kept.
void dropViewsAndSolve(const Args& args, PairSession* session, const std::vector<Method>& methods,
                       const Target& target, const PairCalibrationOptions& run_options,
                       std::string* camera_frame, std::string* lidar_frame, PairCalibration* run) {
  std::vector<int> ids;
  for (const SessionView& v : session->views()) ids.push_back(v.view.id);
  for (const int id : args.drop_views)
    if (std::find(ids.begin(), ids.end(), id) == ids.end())
      fail("--drop-views: no view " + std::to_string(id) +
               " in the session (its views: " + idRanges(ids) + ")",
           kExitUsage);
  for (const int id : args.drop_views)
    if (const Status st = session->dropView(id); !st) fail("--drop-views: " + st.reason);
  const std::string dropped = idRanges(args.drop_views);
  if (session->plainViews().empty())
    fail("--drop-views " + dropped + " leaves no view to solve", kExitUsage);
  std::cout << "views " << dropped << " left out (--drop-views): " << ids.size() << " -> "
            << session->views().size() << " views, solved again\n";
  *run = solveSession(args, *session, methods, target, run_options, camera_frame, lidar_frame);
  run->result.notes.push_back("views " + dropped + " left out by the user (--drop-views)");
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
  if (args.edge_shift) solver.edge_outward_shift_steps = *args.edge_shift;
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
    if (const Status st = createFolder(folder.string()); !st)
      fail(st.reason + " (for '" + file + "')", kExitUsage);
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
  std::vector<PoseStddev> judged;
  for (const auto& r : run.runs) {
    solutions.push_back(r.solution);
    judged.push_back(r.verdict.stddev);
  }
  for (const auto& r : run.runs)
    std::cout << solutionSummary(r.solution, &r.verdict.stddev)
              << "  verdict: " << verdictName(r.verdict.verdict) << " - " << r.verdict.reason
              << "\n";
  if (solutions.size() > 1) std::cout << "\n" << comparisonTable(solutions, &judged);
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
  PairCalibration run;
  // Views to drop: the whole session is solved only when the second pass needs its result.
  const bool second_pass = pipeline && args.second_chance;
  if (second_pass && target->type == TargetType::kPlain && session->plainViews().empty())
    run.reason = session->captureStats().whyNoViews();  // the second pass may still find views
  else if (args.drop_views.empty() || second_pass)
    run = solveSession(args, *session, methods, *target, run_options, &camera_frame, &lidar_frame);
  if (second_pass) {
    secondPass(args, methods, *target, options, run_options, &pipeline, &run);
    session = &pipeline->session();
  }
  if (!args.drop_views.empty()) {
    PairSession* kept = pipeline ? &pipeline->session() : &loaded_session;
    dropViewsAndSolve(args, kept, methods, *target, run_options, &camera_frame, &lidar_frame, &run);
    session = kept;
  }
  if (run.runs.empty()) fail(withCaptureCause(run.reason, session->captureStats()));
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
  if (run.failed())
    fail("calibration failed: " + withCaptureCause(run.reason, session->captureStats()));
  if (!args.quiet)
    std::cerr
        << "calibrate_bag: done in "
        << std::chrono::duration<double>(std::chrono::steady_clock::now() - wall_start).count()
        << " s\n";
  return kExitOk;
}
