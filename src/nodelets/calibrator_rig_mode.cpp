// Rig mode of the calibrator nodelet (see calibrator_rig_mode.h): start-up, the feature
// callbacks and the solve; the services, files and diagnostics are in
// calibrator_rig_mode_services.cpp.
#include "calibrator_rig_mode_impl.h"

#include "calibrator_options.h"

#include <board_calib/calibrator_status.h>
#include <board_calib/core/pipeline/calibration_files.h>
#include <board_calib/core/rig/rig_summary.h>

#include <future>
#include <sstream>

namespace board_calib {

void RigCalibratorMode::Impl::onCamera(int k, const CameraBoardConstPtr& m) {
  std::lock_guard<std::mutex> lock(mutex);
  last_message_wall[k] = ros::WallTime::now();
  report(session->addCamera(k, fromMsg(*m)), rig.cameras[k].name);
}

void RigCalibratorMode::Impl::onLidar(int k, const LidarBoardConstPtr& m) {
  std::lock_guard<std::mutex> lock(mutex);
  last_message_wall[k] = ros::WallTime::now();
  const size_t i = static_cast<size_t>(k) - rig.cameras.size();
  report(session->addLidar(k, fromMsg(*m)), rig.lidars[i].name);
}

bool RigCalibratorMode::Impl::calibrate(Calibrate::Request& req, Calibrate::Response& res) {
  std::lock_guard<std::mutex> solve_lock(solve_mutex);
  if (!req.method.empty() && req.method != "msg" && req.method != "all") {
    res.success = false;
    res.message =
        "rig mode solves the MSG-Cal graph (method msg); '" + req.method +
        "' is a single camera-LiDAR method: start the calibrator without ~rig_file for it";
    return true;
  }
  if (req.use_initial_guess)
    ROS_WARN_STREAM_NAMED(
        kRigLog,
        "calibrator: rig mode initialises from the pairwise solutions; the guess is ignored");
  multi_sensor::MsgProblem problem;
  std::vector<std::string> problems;  // sensors that take part in no pose, and why
  {
    std::lock_guard<std::mutex> lock(mutex);
    report(session->flush(), "calibrate");
    problem = session->problem(reference);
    problems = session->problems();
  }
  for (const auto& p : problems) ROS_WARN_STREAM_NAMED(kRigLog, "calibrator: " << p);
  if (problem.poses.empty()) {
    res.success = false;
    res.message =
        "no board poses captured yet: hold the board still where at least two sensors see it";
    for (const auto& p : problems) res.message += "; " + p;
    return true;
  }
  // The solve and its verdict run on their own thread; feature callbacks keep flowing meanwhile.
  auto solving =
      std::async(std::launch::async, [&]() { return calibrateRig(problem, rig, target); });
  const RigCalibration run = solving.get();
  const multi_sensor::MsgSolution& solution = run.solution;
  if (!solution.success) {
    res.success = false;
    res.message = "calibration failed: " + run.reason;
    ROS_WARN_STREAM_NAMED(kRigLog, "calibrator: " << res.message);
    return true;
  }
  publishRun(run, problems, &res);
  return true;
}

// A judged run to the caller, the topic, TF and files: a failed one is kept for inspection only
// (never broadcast, never over the good file).
void RigCalibratorMode::Impl::publishRun(const RigCalibration& run,
                                         const std::vector<std::string>& problems,
                                         Calibrate::Response* out) {
  Calibrate::Response& res = *out;
  const multi_sensor::MsgSolution& solution = run.solution;
  const ResultFile& file = run.result;
  res.message = rigSolutionSummary(rig, solution, file) + rigVerdictSummary(run);
  for (const auto& p : problems) res.message += "warning: " + p + "\n";
  if (run.failed()) {
    // Never broadcast, never over the good file: kept for inspection only.
    res.success = false;
    const std::string written = writeFailed(file);
    if (!written.empty())
      res.message += "FAILED result written for inspection to " + written + "\n";
    ROS_ERROR_STREAM_NAMED(kRigLog, "calibrator: calibration failed: " << run.reason << "\n"
                                                                       << res.message);
    return;
  }
  res.success = true;
  res.reference_frame = solution.sensors[solution.reference_sensor].frame;
  for (const auto& s : solution.sensors) res.sensors.push_back(toSensorPoseMsg(s));
  for (size_t i = 0; i < file.pairs.size() && i < run.pairs.size(); ++i)
    res.all_results.push_back(
        toPairResultMsg(file.pairs[i], run.pairs[i], solution, ros::Time::now()));
  if (!res.all_results.empty()) {
    res.result = res.all_results.front();
    result_pub.publish(res.result);
  }
  ROS_INFO_STREAM_NAMED(kRigLog, "calibrator:\n" << res.message);

  if (broadcast_tf) broadcastPoses(solution);
  const std::string written = writeOutputs(file, solution);
  if (!written.empty()) res.message += "result written to " + written + "\n";
  const std::string report = writeReport(run.problem, solution, file);
  if (!report.empty()) res.message += "report written to " + report + "\n";
  std::lock_guard<std::mutex> lock(mutex);
  last_solution = solution;
}

// Eager subscriptions: the calibrator must see every feature to capture poses. Returns the
// resolved topics, for the start-up log.
std::string RigCalibratorMode::Impl::subscribeFeatures() {
  std::ostringstream topics;
  for (size_t i = 0; i < rig.cameras.size(); ++i) {
    const int k = static_cast<int>(i);
    subscribers.push_back(
        nh.subscribe<CameraBoard>(rig.cameras[i].features_topic, 10,
                                  [this, k](const CameraBoardConstPtr& f) { onCamera(k, f); }));
    topics << " " << nh.resolveName(rig.cameras[i].features_topic);
  }
  for (size_t i = 0; i < rig.lidars.size(); ++i) {
    const int k = static_cast<int>(rig.cameras.size() + i);
    subscribers.push_back(
        nh.subscribe<LidarBoard>(rig.lidars[i].features_topic, 10,
                                 [this, k](const LidarBoardConstPtr& f) { onLidar(k, f); }));
    topics << " " << nh.resolveName(rig.lidars[i].features_topic);
  }
  return topics.str();
}

void RigCalibratorMode::Impl::startAutosave() {
  bool autosave_enabled = true, resume = false;
  pnh.param("autosave", autosave_enabled, true);
  pnh.param("resume", resume, false);
  if (!autosave_enabled || output_dir.empty()) return;
  const auto path = autosavePath(output_dir, "autosave_rig_session.yaml");
  if (!path) {
    ROS_ERROR_STREAM_NAMED(kRigLog,
                           "calibrator: " << path.error() << ": board poses are not autosaved");
    return;
  }
  autosave_path = *path;
  resumeAutosave(resume);
}

void RigCalibratorMode::Impl::advertise() {
  result_pub = nh.advertise<CalibrationResult>("calibration_result", 1, true);
  tf_broadcaster = std::make_unique<tf2_ros::StaticTransformBroadcaster>();
  reconfigure_server = std::make_unique<dynamic_reconfigure::Server<CalibratorConfig>>(pnh);
  reconfigure_server->setCallback(
      [this](CalibratorConfig& c, uint32_t level) { reconfigure(c, level); });
  services.push_back(pnh.advertiseService("calibrate", &Impl::calibrate, this));
  services.push_back(pnh.advertiseService("capture", &Impl::capture, this));
  services.push_back(pnh.advertiseService("reset", &Impl::reset, this));
  services.push_back(pnh.advertiseService("save_session", &Impl::save, this));
  services.push_back(pnh.advertiseService("load_session", &Impl::load, this));
  services.push_back(pnh.advertiseService("drop_view", &Impl::drop, this));
  diagnostics = std::make_unique<diagnostic_updater::Updater>(nh, pnh);
  diagnostics->setHardwareID(calibrator_status::kHardwareId);
  diagnostics->add(calibrator_status::kStatusName,
                   [this](diagnostic_updater::DiagnosticStatusWrapper& s) { diagnose(s); });
  // Wall time and force_update: with a replayed bag the sim clock stops at its end, and
  // Updater::update() paces itself by that clock, so health would freeze just when it is read.
  diagnostics_timer = nh.createWallTimer(
      ros::WallDuration(1.0), [this](const ros::WallTimerEvent&) { diagnostics->force_update(); });
}

RigCalibratorMode::RigCalibratorMode() : impl_(std::make_unique<Impl>()) {}
RigCalibratorMode::~RigCalibratorMode() = default;

std::unique_ptr<RigCalibratorMode> RigCalibratorMode::create(ros::NodeHandle nh,
                                                             ros::NodeHandle pnh,
                                                             const std::string& rig_file,
                                                             std::string* error) {
  auto rig = loadRigConfig(rig_file);
  if (!rig) {
    *error = rig.error();
    return nullptr;
  }
  std::unique_ptr<RigCalibratorMode> mode(new RigCalibratorMode());
  Impl& m = *mode->impl_;
  m.nh = nh;
  m.pnh = pnh;
  m.rig = *rig;
  m.rig_file = rig_file;
  std::string reference = rig->reference;
  pnh.param("reference", reference, reference);
  m.reference = rig->sensorIndex(reference);
  if (m.reference < 0) {
    *error = "~reference '" + reference + "' is not a sensor of the rig " + rig_file;
    return nullptr;
  }
  pnh.param("child_frame_suffix", m.child_frame_suffix, std::string());
  pnh.param("broadcast_tf", m.broadcast_tf, true);
  m.output_dir = outputDirParam(pnh);

  m.last_message_wall.assign(rig->cameras.size() + rig->lidars.size(), ros::WallTime());
  auto target = loadTarget(rig->target_path);
  if (!target) {
    *error = "rig target: " + target.error();
    return nullptr;
  }
  m.target = *target;
  m.session = std::make_unique<multi_sensor::RigSession>(
      rig->sensorNames(), rig->sensorSpecs(), multi_sensor::rigSessionOptionsFor(*rig), m.target);
  std::string session_file;
  if (pnh.getParam("session_file", session_file) && !session_file.empty()) {
    const Status st = m.session->load(session_file);
    if (st)
      ROS_INFO_STREAM_NAMED(kRigLog, "calibrator: loaded " << m.session->poses().size()
                                                           << " board poses from " << session_file);
    else
      ROS_ERROR_STREAM_NAMED(kRigLog, "calibrator: " << st.reason);
  }
  m.startAutosave();
  m.advertise();
  const std::string topics = m.subscribeFeatures();
  ROS_INFO_STREAM_NAMED(kRigLog, "calibrator: rig mode ("
                                     << rig_file << "): " << rig->cameras.size() << " camera(s), "
                                     << rig->lidars.size() << " LiDAR(s), reference " << reference
                                     << "; waiting for" << topics);
  return mode;
}

}  // namespace board_calib
