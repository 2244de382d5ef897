// MSG-Cal mode of calibrate_bag (docs/MSG.md): argument checks and bag reading only. The frames
// go through core/pipeline/rig_pipeline.h (detectors, capture) and the captured poses through
// core/pipeline/rig_calibration.h (consistency, graph solve, verdict, result file): the code
// the calibrator's rig mode runs live.
#include "calibrate_rig.h"

#include <board_calib/bag_reader.h>
#include <board_calib/core/file_io.h>
#include <board_calib/core/pipeline/rig_calibration.h>
#include <board_calib/core/pipeline/rig_pipeline.h>
#include <board_calib/core/pipeline/rig_report.h>
#include <board_calib/core/result_io.h>
#include <board_calib/core/rig/rig_config.h>
#include <board_calib/core/rig/rig_summary.h>
#include <board_calib/core/transform.h>

#include <chrono>
#include <filesystem>
#include <iomanip>
#include <iostream>
#include <map>
#include <optional>
#include <sstream>

namespace board_calib {
namespace {

constexpr int kExitOk = 0;
constexpr int kExitFailed = 1;
constexpr int kExitUsage = 2;

int failWith(const std::string& why, int code = kExitFailed) {
  std::cerr << "calibrate_bag: " << why << "\n";
  return code;
}

// Ground truth a_T_b from a truth result file: a listed pair, else the two sensor poses.
std::optional<Eigen::Isometry3d> truthPair(const ResultFile& truth, const std::string& camera,
                                           const std::string& lidar) {
  for (const auto& p : truth.pairs)
    if (p.camera_frame == camera && p.lidar_frame == lidar) return p.camera_T_lidar;
  std::optional<Eigen::Isometry3d> ref_T_c, ref_T_l;
  for (const auto& s : truth.sensors) {
    if (s.frame == camera) ref_T_c = s.reference_T_sensor;
    if (s.frame == lidar) ref_T_l = s.reference_T_sensor;
  }
  if (ref_T_c && ref_T_l) return ref_T_c->inverse() * *ref_T_l;
  return std::nullopt;
}

// The rig's topics, every one present in the bags (one reason naming all missing topics).
Expected<BagTopics> rigTopics(const RigConfig& rig, const std::vector<std::string>& bags) {
  auto counts = bagTopicCounts(bags);
  if (!counts) return Expected<BagTopics>::failure(counts.error());
  BagTopics topics;
  for (const auto& c : rig.cameras) {
    topics.image_topics.push_back(c.image_topic);
    topics.camera_info_topics.push_back(c.camera_info_topic);
  }
  for (const auto& l : rig.lidars) topics.cloud_topics.push_back(l.cloud_topic);
  std::string missing;
  for (const auto* list : {&topics.image_topics, &topics.camera_info_topics, &topics.cloud_topics})
    for (const auto& t : *list)
      if (!counts->count(t) || counts->at(t) == 0) missing += (missing.empty() ? "" : ", ") + t;
  if (!missing.empty()) return Expected<BagTopics>::failure("topic(s) not in the bags: " + missing);
  return topics;
}

// Streams the bags into the pipeline; a reason when a sensor gave nothing usable.
Status readRig(const RigArgs& args, const BagTopics& topics, RigPipeline* pipeline) {
  const RigConfig& rig = pipeline->rig();
  std::map<std::string, int> camera_of, lidar_of;
  for (size_t i = 0; i < rig.cameras.size(); ++i)
    camera_of[rig.cameras[i].image_topic] = static_cast<int>(i);
  for (size_t i = 0; i < rig.lidars.size(); ++i)
    lidar_of[rig.lidars[i].cloud_topic] = static_cast<int>(i);
  std::map<std::string, int> bad_messages;
  BagFrameCallbacks cb;
  cb.on_image = [&](const ImageFrame& f, const CameraIntrinsics& in) {
    pipeline->addImage(camera_of.at(f.topic), f.image, in, f.frame_id, f.stamp);
  };
  cb.on_cloud = [&](const std::string& topic, const LidarCloud& cloud) {
    pipeline->addCloud(lidar_of.at(topic), cloud);
  };
  cb.on_bad_message = [&](const std::string& topic, const std::string& why) {
    if (bad_messages[topic + ": " + why]++ == 0 && !args.quiet)
      std::cerr << "calibrate_bag: skipping a message on " << topic << ": " << why << "\n";
  };
  const auto read = readBagFrames(args.bags, topics, cb);
  if (!read) return Status::failure(read.error());
  pipeline->finish();
  for (const auto& [topic, n] : read->images_dropped)
    if (n > 0 && !args.quiet)
      std::cerr << "calibrate_bag: warning: " << n << " images on " << topic
                << " found no camera_info and were skipped\n";
  const auto& stats = pipeline->stats();
  for (size_t k = 0; k < stats.size(); ++k) {
    const bool camera = k < rig.cameras.size();
    if (!args.quiet) {
      std::cerr << "calibrate_bag: " << (camera ? "camera " : "LiDAR ") << stats[k].name
                << ": board found in " << stats[k].found << "/" << stats[k].frames
                << (camera ? " images\n" : " clouds\n");
      for (const auto& [why, n] : stats[k].failures) std::cerr << "  " << n << " x " << why << "\n";
    }
    // One sensor without the board does not stop the others: the calibration names it as not
    // calibrated and solves the rest.
    if (args.quiet) continue;
    if (camera && stats[k].frames == 0)
      std::cerr << "calibrate_bag: warning: no image of camera '" << stats[k].name
                << "' could be used (no valid camera_info on '" << rig.cameras[k].camera_info_topic
                << "'?): it cannot be calibrated\n";
    else if (stats[k].found == 0)
      std::cerr << "calibrate_bag: warning: the board was never found by "
                << (camera ? "camera '" : "LiDAR '") << stats[k].name
                << "': it cannot be calibrated\n";
  }
  return Status::success();
}

// Error of every pair against a truth file; `check_failed` when a pair misses the limits.
Status truthErrors(const RigArgs& args, const ResultFile& result, std::ostream& out,
                   bool* check_failed) {
  auto truth = loadResultFile(args.truth);
  if (!truth) return Status::failure("truth: " + truth.error());
  out << "error vs truth (rotation, translation):\n" << std::fixed;
  for (const auto& p : result.pairs) {
    const auto T = truthPair(*truth, p.camera_frame, p.lidar_frame);
    if (!T)
      return Status::failure("truth file has no pair " + p.camera_frame + " <- " + p.lidar_frame);
    const double rot = rotationErrorDeg(p.camera_T_lidar, *T);
    const double trans = translationErrorM(p.camera_T_lidar, *T);
    const bool bad = (args.check_rotation_deg > 0 && rot > args.check_rotation_deg) ||
                     (args.check_translation_m > 0 && trans > args.check_translation_m);
    *check_failed |= bad;
    out << "  " << p.camera_frame << " <- " << p.lidar_frame << ": " << std::setprecision(3) << rot
        << " deg, " << std::setprecision(1) << trans * 1e3 << " mm"
        << (bad ? "  ** above the --check-truth limit **" : "") << "\n";
  }
  return Status::success();
}

Status writeReport(const RigArgs& args, const RigConfig& rig, const RigPipeline& pipeline,
                   const RigCalibration& run, const std::string& printed) {
  RigReportInputs inputs;
  inputs.source = "rig `" + args.config + "`, bags:";
  for (const auto& b : args.bags) inputs.source += " `" + b + "`";
  for (const auto& s : pipeline.stats())
    inputs.input_lines.push_back("`" + s.frame_id + "`: board in " + std::to_string(s.found) + "/" +
                                 std::to_string(s.frames) + " frames");
  inputs.input_lines.push_back(
      std::to_string(run.problem.poses.size()) +
      " board poses seen by two or more sensors (capture: " + args.capture + "; " +
      pipeline.session().captureStats().summary() + ")");
  const std::string summary = rigSolutionSummary(rig, run.solution, run.result);
  if (printed.size() > summary.size())
    inputs.extra_result_text = printed.substr(summary.size());  // verdict, vs truth
  inputs.verdict_text = rigVerdictSummary(run);
  inputs.failed = run.failed();
  // The pipeline's cameras in the rig's order; the solved problem may have left a sensor out.
  for (RigCameraFrames frames : pipeline.overlayFrames()) {
    if (frames.sensor < 0 || frames.sensor >= static_cast<int>(run.solved_index.size())) continue;
    frames.sensor = run.solved_index[static_cast<size_t>(frames.sensor)];
    if (frames.sensor >= 0) inputs.camera_frames.push_back(std::move(frames));
  }
  return writeRigReport(args.report, rig, run.problem, run.solution, run.result, inputs);
}

}  // namespace

int runRigCalibration(const RigArgs& args) {
  const auto wall_start = std::chrono::steady_clock::now();
  if (args.config.empty()) return failWith("--config is required", kExitUsage);
  if (args.bags.empty()) return failWith("--bag is required with --config", kExitUsage);
  const auto capture = parseRigCapture(args.capture);
  if (!capture) return failWith("--" + capture.error(), kExitUsage);
  if ((args.check_rotation_deg > 0 || args.check_translation_m > 0) && args.truth.empty())
    return failWith("--check-truth needs --truth", kExitUsage);

  auto rig = loadRigConfig(args.config);
  if (!rig) return failWith(rig.error());
  auto target = loadTarget(rig->target_path);
  if (!target) return failWith("rig target: " + target.error());
  auto topics = rigTopics(*rig, args.bags);
  if (!topics) return failWith(topics.error());
  RigPipelineOptions options = rigPipelineOptionsFor(*rig);
  options.capture = *capture;
  auto pipeline = RigPipeline::create(*rig, *target, options);
  if (!pipeline) return failWith(pipeline.error());
  if (const Status read = readRig(args, *topics, &*pipeline); !read) return failWith(read.reason);
  auto problem = pipeline->problem();
  if (!problem) return failWith(problem.error());
  if (!args.quiet)
    std::cerr << "calibrate_bag: " << problem->poses.size() << " board poses (capture "
              << args.capture << ": " << pipeline->session().captureStats().summary() << ")\n";
  for (const auto& p : pipeline->session().problems())
    if (!args.quiet) std::cerr << "  warning: " << p << "\n";
  if (problem->poses.empty())
    return failWith("no board pose was seen still by two sensors at once: " +
                    pipeline->session().captureStats().whyNoViews());

  const RigCalibration run = calibrateRig(*problem, *rig, *target);
  if (!run.solution.success) return failWith("calibration failed: " + run.reason);
  std::ostringstream out;
  out << rigSolutionSummary(*rig, run.solution, run.result) << "\n" << rigVerdictSummary(run);
  bool check_failed = false;
  if (!args.truth.empty())
    if (const Status st = truthErrors(args, run.result, out, &check_failed); !st)
      return failWith(st.reason);
  std::cout << out.str();
  // A failed result is kept for inspection only, under a name no tool mistakes for a calibration.
  if (!args.output.empty()) {
    const std::string output = run.failed() ? failedResultPath(args.output) : args.output;
    if (const Status st = writeResultFile(output, run.result); !st) return failWith(st.reason);
    std::cout << (run.failed() ? "FAILED result written for inspection to " : "result written to ")
              << output << "\n";
  }
  if (!args.report.empty()) {
    if (const Status st = writeReport(args, *rig, *pipeline, run, out.str()); !st)
      return failWith(st.reason);
    std::cout << "report written to " << args.report << "/report.md\n";
  }
  if (!args.quiet)
    std::cerr
        << "calibrate_bag: done in "
        << std::chrono::duration<double>(std::chrono::steady_clock::now() - wall_start).count()
        << " s\n";
  if (run.failed()) return failWith("calibration failed: " + run.reason);
  if (check_failed) return failWith("a pair is outside the --check-truth limits");
  return kExitOk;
}

}  // namespace board_calib
