// MSG-Cal mode of calibrate_bag (docs/MSG.md): streams every topic of a rig from the bags, runs
// one image detector per camera and the LiDAR detector per LiDAR, groups the features by stamp
// into board poses, solves the multi-sensor graph and prints / writes every sensor pose, every
// camera<->LiDAR pair with its MLRE and the consistency figures.
#include "calibrate_rig.h"

#include <board_calib/bag_reader.h>
#include <board_calib/core/file_io.h>
#include <board_calib/core/camera_model.h>
#include <board_calib/core/image_board_detector.h>
#include <board_calib/core/lidar_board_detector.h>
#include <board_calib/core/msg_graph.h>
#include <board_calib/core/msg_session.h>
#include <board_calib/core/result_io.h>
#include <board_calib/core/rig_config.h>
#include <board_calib/core/pipeline/rig_report.h>
#include <board_calib/core/rig_report.h>
#include <board_calib/core/rig_session.h>
#include <board_calib/core/target.h>
#include <board_calib/core/transform.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
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
// Images kept per camera while its first camera_info has not arrived yet.
constexpr size_t kMaxWaitingImages = 20;

int failWith(const std::string& why, int code = kExitFailed) {
  std::cerr << "calibrate_bag: " << why << "\n";
  return code;
}

bool makeDirs(const std::string& path) {
  std::error_code error;
  std::filesystem::create_directories(path, error);
  return !error;
}

struct CameraStream {
  std::optional<ImageBoardDetector> detector;
  std::optional<CameraModel> model;
  std::vector<ImageFrame> waiting;  // images before the first camera_info
  std::vector<CameraBoardFeatures> features;
  std::string frame_id;
  int images = 0, found = 0;
  std::map<std::string, int> failures;
};

struct LidarStream {
  std::vector<LidarBoardFeatures> features;
  std::string frame_id;
  int clouds = 0, found = 0;
  std::map<std::string, int> failures;
};

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

}  // namespace

int runRigCalibration(const RigArgs& args) {
  const auto wall_start = std::chrono::steady_clock::now();
  if (args.config.empty()) return failWith("--config is required", kExitUsage);
  if (args.bags.empty()) return failWith("--bag is required with --config", kExitUsage);
  if (args.capture != "all" && args.capture != "still")
    return failWith("--capture must be 'all' or 'still', not '" + args.capture + "'", kExitUsage);
  if ((args.check_rotation_deg > 0 || args.check_translation_m > 0) && args.truth.empty())
    return failWith("--check-truth needs --truth", kExitUsage);

  auto rig = loadRigConfig(args.config);
  if (!rig) return failWith(rig.error());
  auto target = loadTarget(rig->target_path);
  if (!target) return failWith("rig target: " + target.error());

  // Check every topic up front: one reason naming all missing topics beats a late failure.
  auto counts = bagTopicCounts(args.bags);
  if (!counts) return failWith(counts.error());
  std::vector<std::string> missing;
  BagTopics topics;
  for (const auto& c : rig->cameras) {
    topics.image_topics.push_back(c.image_topic);
    topics.camera_info_topics.push_back(c.camera_info_topic);
  }
  for (const auto& l : rig->lidars) topics.cloud_topics.push_back(l.cloud_topic);
  for (const auto* list : {&topics.image_topics, &topics.camera_info_topics, &topics.cloud_topics})
    for (const auto& t : *list)
      if (!counts->count(t) || counts->at(t) == 0) missing.push_back(t);
  if (!missing.empty()) {
    std::string all;
    for (const auto& t : missing) all += (all.empty() ? "" : ", ") + t;
    return failWith("topic(s) not in the bags: " + all);
  }

  const size_t num_cameras = rig->cameras.size();
  std::vector<CameraStream> cameras(num_cameras);
  std::vector<LidarStream> lidars(rig->lidars.size());
  std::map<std::string, size_t> image_index, info_index, cloud_index;
  for (size_t i = 0; i < num_cameras; ++i) {
    auto det = ImageBoardDetector::create(*target, ImageBoardDetectorOptions{});
    if (!det) return failWith("image detector: " + det.error());
    cameras[i].detector.emplace(std::move(*det));
    image_index[rig->cameras[i].image_topic] = i;
    info_index[rig->cameras[i].camera_info_topic] = i;
  }
  for (size_t i = 0; i < rig->lidars.size(); ++i) cloud_index[rig->lidars[i].cloud_topic] = i;

  std::string stream_error;
  auto detectImage = [&](CameraStream& cs, const ImageFrame& f) {
    ImageDetection d = cs.detector->detect(f.image, *cs.model);
    d.features.stamp = f.stamp;
    if (d.features.frame_id.empty()) d.features.frame_id = f.frame_id;
    ++cs.images;
    if (d.features.found) {
      ++cs.found;
      cs.features.push_back(std::move(d.features));
    } else {
      ++cs.failures[d.features.reason];
    }
  };
  std::map<std::string, int> bad_messages;
  BagCallbacks cb;
  cb.on_camera_info = [&](const std::string& topic, const std::string&, const CameraIntrinsics& in) {
    CameraStream& cs = cameras[info_index.at(topic)];
    if (cs.model) return;  // intrinsics are fixed for the run
    auto model = CameraModel::create(in);
    if (!model) {
      if (stream_error.empty()) stream_error = "camera_info on '" + topic + "': " + model.error();
      return;
    }
    cs.model.emplace(std::move(*model));
    for (const auto& f : cs.waiting) detectImage(cs, f);
    cs.waiting.clear();
  };
  cb.on_image = [&](const ImageFrame& f) {
    CameraStream& cs = cameras[image_index.at(f.topic)];
    if (cs.frame_id.empty()) cs.frame_id = f.frame_id;
    if (!cs.model) {
      if (cs.waiting.size() < kMaxWaitingImages) cs.waiting.push_back(f);
      return;
    }
    detectImage(cs, f);
  };
  cb.on_cloud = [&](const std::string& topic, const LidarCloud& cloud) {
    LidarStream& ls = lidars[cloud_index.at(topic)];
    if (ls.frame_id.empty()) ls.frame_id = cloud.frame_id;
    LidarBoardDetection d = detectLidarBoard(cloud, *target);
    if (d.features.frame_id.empty()) d.features.frame_id = cloud.frame_id;
    ++ls.clouds;
    if (d.features.found) {
      ++ls.found;
      ls.features.push_back(std::move(d.features));
    } else {
      ++ls.failures[d.features.reason];
    }
  };
  cb.on_bad_message = [&](const std::string& topic, const std::string& why) {
    if (bad_messages[topic + ": " + why]++ == 0 && !args.quiet)
      std::cerr << "calibrate_bag: skipping a message on " << topic << ": " << why << "\n";
  };
  const Status read = readBags(args.bags, topics, cb);
  if (!read) return failWith(read.reason);
  if (!stream_error.empty()) return failWith(stream_error);
  const double detect_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - wall_start).count();

  // Sensors are named by their bag frame_id (what TF and the truth file use).
  std::vector<msg::SensorSpec> specs = rig->sensorSpecs();
  std::map<int, std::vector<CameraBoardFeatures>> camera_streams;
  std::map<int, std::vector<LidarBoardFeatures>> lidar_streams;
  for (size_t i = 0; i < num_cameras; ++i) {
    const auto& cs = cameras[i];
    if (!cs.model) return failWith("no valid camera_info on '" + rig->cameras[i].camera_info_topic + "'");
    if (!cs.frame_id.empty()) specs[i].frame = cs.frame_id;
    if (!args.quiet) {
      std::cerr << "calibrate_bag: camera " << rig->cameras[i].name << ": board found in " << cs.found << "/"
                << cs.images << " images\n";
      for (const auto& [why, n] : cs.failures) std::cerr << "  " << n << " x " << why << "\n";
    }
    if (cs.found == 0) return failWith("the board was never found by camera '" + rig->cameras[i].name + "'");
    camera_streams[static_cast<int>(i)] = cs.features;
  }
  for (size_t i = 0; i < lidars.size(); ++i) {
    const auto& ls = lidars[i];
    const int k = static_cast<int>(num_cameras + i);
    if (!ls.frame_id.empty()) specs[k].frame = ls.frame_id;
    if (!args.quiet) {
      std::cerr << "calibrate_bag: LiDAR " << rig->lidars[i].name << ": board found in " << ls.found << "/"
                << ls.clouds << " clouds\n";
      for (const auto& [why, n] : ls.failures) std::cerr << "  " << n << " x " << why << "\n";
    }
    if (ls.found == 0) return failWith("the board was never found by LiDAR '" + rig->lidars[i].name + "'");
    lidar_streams[k] = ls.features;
  }

  std::vector<msg::BoardPoseObservation> poses;
  if (args.capture == "still") {
    // The live rule (msg::RigSession): the features in stamp order, one pose per still period.
    struct Item {
      double stamp;
      int sensor;
      const CameraBoardFeatures* camera;
      const LidarBoardFeatures* lidar;
    };
    std::vector<Item> items;
    for (const auto& [k, fs] : camera_streams)
      for (const auto& f : fs) items.push_back({f.stamp, k, &f, nullptr});
    for (const auto& [k, fs] : lidar_streams)
      for (const auto& f : fs) items.push_back({f.stamp, k, nullptr, &f});
    std::stable_sort(items.begin(), items.end(), [](const Item& a, const Item& b) { return a.stamp < b.stamp; });
    msg::RigSession session(rig->sensorNames(), specs, msg::rigSessionOptionsFor(*rig));
    for (const auto& it : items) {
      if (it.camera) session.addCamera(it.sensor, *it.camera);
      else session.addLidar(it.sensor, *it.lidar);
    }
    session.flush();
    for (const auto& p : session.poses()) poses.push_back(p.observation);
    if (!args.quiet) {
      std::cerr << "calibrate_bag: " << poses.size() << " board poses captured (one per still period)\n";
      for (const auto& p : session.problems()) std::cerr << "  warning: " << p << "\n";
    }
  } else {
    msg::GroupingOptions grouping;
    grouping.stamp_tolerance_s = rig->stamp_tolerance_s;
    auto grouped = msg::groupByStamp(specs, camera_streams, lidar_streams, grouping);
    if (!grouped) return failWith("grouping: " + grouped.error());
    if (!args.quiet)
      std::cerr << "calibrate_bag: " << grouped->poses.size() << " board poses (" << grouped->features_used << "/"
                << grouped->features_in << " features used, " << grouped->groups_dropped
                << " stamp groups with fewer than " << grouping.min_sensors << " sensors dropped)\n";
    poses = grouped->poses;
  }
  if (poses.empty()) return failWith("no board pose was seen by two sensors at once (check stamp_tolerance_s)");

  msg::MsgProblem problem;
  problem.sensors = specs;
  problem.reference_sensor = rig->sensorIndex(rig->reference);
  problem.poses = poses;
  const msg::MsgSolution solution = msg::solveMsgGraph(problem, msg::MsgGraphOptions{});
  if (!solution.success) return failWith("MSG graph failed: " + solution.reason);

  const ResultFile result = msg::msgResultFile(problem, solution);
  std::ostringstream out;
  out << rigSolutionSummary(*rig, solution, result) << std::fixed;

  bool check_failed = false;
  if (!args.truth.empty()) {
    auto truth = loadResultFile(args.truth);
    if (!truth) return failWith("truth: " + truth.error());
    out << "error vs truth (rotation, translation):\n";
    for (const auto& p : result.pairs) {
      const auto T = truthPair(*truth, p.camera_frame, p.lidar_frame);
      if (!T) return failWith("truth file has no pair " + p.camera_frame + " <- " + p.lidar_frame);
      const double rot = rotationErrorDeg(p.camera_T_lidar, *T);
      const double trans = translationErrorM(p.camera_T_lidar, *T);
      const bool bad = (args.check_rotation_deg > 0 && rot > args.check_rotation_deg) ||
                       (args.check_translation_m > 0 && trans > args.check_translation_m);
      check_failed |= bad;
      out << "  " << p.camera_frame << " <- " << p.lidar_frame << ": " << std::setprecision(3) << rot << " deg, "
          << std::setprecision(1) << trans * 1e3 << " mm" << (bad ? "  ** above the --check-truth limit **" : "")
          << "\n";
    }
  }
  std::cout << out.str();

  if (!args.output.empty()) {
    const Status st = writeResultFile(args.output, result);
    if (!st) return failWith(st.reason);
    std::cout << "result written to " << args.output << "\n";
  }
  if (!args.report.empty()) {
    if (!makeDirs(args.report)) return failWith("cannot create report folder '" + args.report + "'");
    RigReportInputs inputs;
    inputs.source = "rig `" + args.config + "`, bags:";
    for (const auto& b : args.bags) inputs.source += " `" + b + "`";
    for (size_t i = 0; i < num_cameras; ++i)
      inputs.input_lines.push_back("camera `" + specs[i].frame + "`: board in " + std::to_string(cameras[i].found) +
                                   "/" + std::to_string(cameras[i].images) + " images");
    for (size_t i = 0; i < lidars.size(); ++i)
      inputs.input_lines.push_back("LiDAR `" + specs[num_cameras + i].frame + "`: board in " +
                                   std::to_string(lidars[i].found) + "/" + std::to_string(lidars[i].clouds) + " clouds");
    inputs.input_lines.push_back("capture: " + args.capture);
    const std::string printed = out.str(), summary = rigSolutionSummary(*rig, solution, result);
    if (printed.size() > summary.size()) inputs.extra_result_text = printed.substr(summary.size());  // vs truth
    const Status st = writeRigReport(args.report, *rig, problem, solution, result, inputs);
    if (!st) return failWith(st.reason);
    std::cout << "report written to " << args.report << "/report.md\n";
  }
  if (!args.quiet)
    std::cerr << "calibrate_bag: done in "
              << std::chrono::duration<double>(std::chrono::steady_clock::now() - wall_start).count()
              << " s (reading + detection " << detect_s << " s)\n";
  if (check_failed) return failWith("a pair is outside the --check-truth limits");
  return kExitOk;
}

}  // namespace board_calib
