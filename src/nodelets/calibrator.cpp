// Calibrator nodelet: collects LiDAR and camera board features into a PairSession (core),
// solves on ~calibrate off the callback thread, publishes the latched result, broadcasts the
// static TF and writes the result file with launch/URDF snippets. With ~rig_file it runs the
// multi-sensor rig mode instead (calibrator_rig_mode.h). Thin wiring only.
#include "calibrator.h"

#include "calibrator_options.h"

#include <board_calib/calibrator_status.h>
#include <board_calib/core/pipeline/calibration_files.h>
#include <board_calib/core/report/report.h>
#include <board_calib/core/transform.h>

#include <visualization_msgs/MarkerArray.h>
#include <pluginlib/class_list_macros.hpp>

#include <future>

namespace board_calib {

constexpr const char* kAutosaveFileName = "autosave_session.yaml";

void CalibratorNodelet::onInit() {
  ros::NodeHandle& nh = getNodeHandle();
  ros::NodeHandle& pnh = getPrivateNodeHandle();
  std::string rig_file;
  if (pnh.getParam("rig_file", rig_file) && !rig_file.empty()) {
    // Rig mode: N cameras and M LiDARs from the rig YAML, solved as one MSG-Cal graph.
    std::string error;
    rig_mode_ = RigCalibratorMode::create(nh, pnh, rig_file, &error);
    if (!rig_mode_) NODELET_FATAL_STREAM("calibrator: ~rig_file: " << error);
    return;
  }
  std::string target_file;
  if (!pnh.getParam("target_file", target_file)) {
    NODELET_FATAL(
        "calibrator: private parameter ~target_file (the board description YAML) is required");
    return;
  }
  auto target = loadTarget(target_file);
  if (!target) {
    NODELET_FATAL_STREAM("calibrator: " << target.error());
    return;
  }
  pnh.param("method", default_method_, default_method_);
  pnh.param("child_frame", child_frame_, std::string());
  pnh.param("broadcast_tf", broadcast_tf_, true);
  output_dir_ = outputDirParam(pnh);
  session_ = std::make_unique<PairSession>(*target, SessionOptions{});
  std::string session_file;
  if (pnh.getParam("session_file", session_file) && !session_file.empty()) {
    const Status st = session_->load(session_file);
    if (st)
      NODELET_INFO_STREAM("calibrator: loaded " << session_->views().size() << " views from "
                                                << session_file);
    else
      NODELET_ERROR_STREAM("calibrator: " << st.reason);
  }
  startAutosave(pnh);
  advertise(nh, pnh);
  // The calibrator subscribes eagerly: it must see every feature to collect views.
  lidar_sub_ = nh.subscribe("lidar_board", 10, &CalibratorNodelet::onLidar, this);
  camera_sub_ = nh.subscribe("camera_board", 10, &CalibratorNodelet::onCamera, this);
  NODELET_INFO_STREAM("calibrator: target " << targetTypeName(target->type) << " " << target->width
                                            << " x " << target->height << " m; waiting for "
                                            << nh.resolveName("lidar_board") << " and "
                                            << nh.resolveName("camera_board"));
}

void CalibratorNodelet::startAutosave(ros::NodeHandle& pnh) {
  // Autosave: every captured or dropped view is saved, so a crashed manager loses nothing.
  bool autosave_enabled = true, resume = false;
  pnh.param("autosave", autosave_enabled, true);
  pnh.param("resume", resume, false);
  if (!autosave_enabled || output_dir_.empty()) return;
  const auto path = autosavePath(output_dir_, kAutosaveFileName);
  if (!path) {
    NODELET_ERROR_STREAM("calibrator: " << path.error() << ": views are not autosaved");
    return;
  }
  autosave_path_ = *path;
  resumeAutosave(resume);
}

void CalibratorNodelet::advertise(ros::NodeHandle& nh, ros::NodeHandle& pnh) {
  result_pub_ = nh.advertise<CalibrationResult>("calibration_result", 1, true);
  markers_pub_ = nh.advertise<visualization_msgs::MarkerArray>("calibration_markers", 1, true);
  tf_broadcaster_ = std::make_unique<tf2_ros::StaticTransformBroadcaster>();
  reconfigure_server_ = std::make_unique<dynamic_reconfigure::Server<CalibratorConfig>>(pnh);
  reconfigure_server_->setCallback(
      [this](CalibratorConfig& config, uint32_t level) { reconfigure(config, level); });

  services_.push_back(
      pnh.advertiseService("calibrate", &CalibratorNodelet::calibrateChecked, this));
  services_.push_back(pnh.advertiseService("capture", &CalibratorNodelet::capture, this));
  services_.push_back(pnh.advertiseService("reset", &CalibratorNodelet::reset, this));
  services_.push_back(pnh.advertiseService("save_session", &CalibratorNodelet::saveSession, this));
  services_.push_back(pnh.advertiseService("load_session", &CalibratorNodelet::loadSession, this));
  services_.push_back(pnh.advertiseService("drop_view", &CalibratorNodelet::dropView, this));

  diagnostics_ = std::make_unique<diagnostic_updater::Updater>(nh, pnh);
  diagnostics_->setHardwareID(calibrator_status::kHardwareId);
  diagnostics_->add(calibrator_status::kStatusName, this, &CalibratorNodelet::diagnose);
  // force_update on a wall timer: update() paces itself by ROS time, which stops at the end of a
  // replayed bag (use_sim_time) and would freeze the status the user is reading.
  diagnostics_timer_ = nh.createWallTimer(ros::WallDuration(1.0), [this](
                                                                      const ros::WallTimerEvent&) {
    diagnostics_->force_update();
    // Streams quiet: the images still waiting for frames after them (the last pose of a
    // recording, a paused bag) are judged with what there is.
    std::lock_guard<std::mutex> lock(mutex_);
    if (session_ && ros::WallTime::now() - last_feature_wall_ > ros::WallDuration(kQuietStreamsS)) {
      const SessionEvent e = session_->finish();
      if (e.kind != SessionEvent::Kind::kWaiting) report(e, "quiet streams");
    }
  });
}

void CalibratorNodelet::reconfigure(CalibratorConfig& c, uint32_t) {
  std::lock_guard<std::mutex> lock(mutex_);
  const SessionOptions o = sessionOptionsFromConfig(c, session_->options());
  if (const std::string why = o.validate(); !why.empty()) {
    NODELET_WARN_STREAM("calibrator: rejected reconfiguration: " << why);
    return;
  }
  session_->setOptions(o);
  session_->setAutoCapture(c.auto_capture);
  default_method_ = c.method;
}

void CalibratorNodelet::report(const SessionEvent& e, const char* source) {
  last_event_ = std::string(source) + ": " + e.message;
  if (e.kind == SessionEvent::Kind::kAccepted) {
    const CoverageReport cov = session_->coverage();
    NODELET_INFO_STREAM("calibrator: "
                        << e.message << "; " << cov.views << " views"
                        << (cov.advice.empty() ? "" : "; next: " + cov.advice.front()));
    publishMarkers(session_->plainViews(), last_solution_);
    autosave();
  } else if (e.kind == SessionEvent::Kind::kRejected) {
    NODELET_INFO_STREAM_THROTTLE(2.0, "calibrator: view rejected: " << e.message);
  }
}

// Service arguments are checked before the solve: a zero or non-unit quaternion was taken as
// the identity.
bool CalibratorNodelet::calibrateChecked(Calibrate::Request& req, Calibrate::Response& res) {
  if (req.use_initial_guess) {
    if (const std::string why = validateTransform(req.initial_guess); !why.empty()) {
      res.success = false;
      res.message = "initial_guess refused: " + why;
      NODELET_WARN_STREAM("calibrator: ~calibrate: " << res.message);
      return true;
    }
  }
  return calibrate(req, res);
}

void CalibratorNodelet::onLidar(const LidarBoardConstPtr& msg) {
  std::lock_guard<std::mutex> lock(mutex_);
  ++lidar_msgs_;
  last_feature_wall_ = ros::WallTime::now();
  lidar_frame_ = msg->header.frame_id;
  if (!msg->found)
    NODELET_DEBUG_STREAM_THROTTLE(5.0, "calibrator: LiDAR sees no board: " << msg->reason);
  lidar_board_state_ = msg->found ? "found" : "not found: " + msg->reason;
  report(session_->addLidar(fromMsg(*msg)), "lidar");
}

void CalibratorNodelet::onCamera(const CameraBoardConstPtr& msg) {
  std::lock_guard<std::mutex> lock(mutex_);
  ++camera_msgs_;
  last_feature_wall_ = ros::WallTime::now();
  camera_frame_ = msg->header.frame_id;
  if (!msg->found)
    NODELET_DEBUG_STREAM_THROTTLE(5.0, "calibrator: camera sees no board: " << msg->reason);
  camera_board_state_ = msg->found ? "found" : "not found: " + msg->reason;
  report(session_->addCamera(fromMsg(*msg)), "camera");
}

bool CalibratorNodelet::calibrate(Calibrate::Request& req, Calibrate::Response& res) {
  std::lock_guard<std::mutex> solve_lock(solve_mutex_);
  std::vector<View> views;
  Target target;
  std::string method_name;
  std::string camera_frame, lidar_frame;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    views = session_->plainViews();
    target = session_->target();
    method_name = req.method.empty() ? default_method_ : req.method;
    camera_frame =
        camera_frame_.empty() && !views.empty() ? views.front().camera.frame_id : camera_frame_;
    lidar_frame =
        lidar_frame_.empty() && !views.empty() ? views.front().lidar.frame_id : lidar_frame_;
  }
  const auto methods = parseMethods(method_name);
  if (!methods) {
    res.success = false;
    res.message = methods.error();
    return true;
  }
  if (views.empty()) {
    res.success = false;
    std::lock_guard<std::mutex> lock(mutex_);
    res.message = "no views collected yet: " + session_->captureStats().whyNoViews() + " (" +
                  session_->captureStats().summary() + ")";
    return true;
  }
  std::optional<Eigen::Isometry3d> guess;
  if (req.use_initial_guess) guess = fromTransformMsg(req.initial_guess);
  // The solve runs on its own thread; feature callbacks keep flowing meanwhile.
  auto solving = std::async(std::launch::async, [&]() {
    return calibratePair(views, *methods, target, camera_frame, lidar_frame,
                         PairCalibrationOptions{}, guess);
  });
  const PairCalibration run = solving.get();
  std::string capture_cause;  // when the capture refused most candidates for one cause
  {
    std::lock_guard<std::mutex> lock(mutex_);
    capture_cause = session_->captureStats().whyFewViews();
  }
  if (run.runs.empty()) {  // refused before any solve (options, guess, views)
    res.success = false;
    res.message =
        "calibration failed: " + run.reason + (capture_cause.empty() ? "" : "; " + capture_cause);
    NODELET_WARN_STREAM("calibrator: " << res.message);
    return true;
  }
  publishRun(run, views, target, camera_frame, lidar_frame, &res);
  if (run.failed() && !capture_cause.empty()) {
    res.message += "capture: " + capture_cause + "\n";
    NODELET_WARN_STREAM("calibrator: capture: " << capture_cause);
  }
  return true;
}

// The judged run to the caller, the topic, TF and files: a failed run is kept for inspection
// only (never broadcast, never over a good result file).
void CalibratorNodelet::publishRun(const PairCalibration& run, const std::vector<View>& views,
                                   const Target& target, const std::string& camera_frame,
                                   const std::string& lidar_frame, Calibrate::Response* out) {
  Calibrate::Response& res = *out;
  for (const auto& r : run.runs) {
    ResultFile file = makeResultFile(r.solution, run.used_views, target, camera_frame, lidar_frame);
    file.verdict = verdictName(r.verdict.verdict);
    file.verdict_reason = r.verdict.reason;
    res.all_results.push_back(toResultMsg(r.solution, r.verdict, file, ros::Time::now()));
  }
  const MethodRun& shown = run.shownRun();
  res.result = toResultMsg(shown.solution, shown.verdict, run.result, ros::Time::now());
  res.message = verdictSummary(run);
  if (run.failed()) {
    // Never broadcast, never replace a good result file: keep the failed one for inspection.
    res.success = false;
    res.result.success = false;
    if (res.result.reason.empty()) res.result.reason = run.reason;
    const std::string kept = writeFailedResult(run.result);
    if (!kept.empty()) res.message += "failed result kept for inspection in " + kept + "\n";
    if (const std::string report = writeReport(run); !report.empty())
      res.message += "report written to " + report + "\n";
    NODELET_WARN_STREAM("calibrator: calibration FAILED: " << run.reason);
    result_pub_.publish(res.result);
    return;
  }
  res.success = true;
  const CalibrationSolution& chosen = shown.solution;
  if (run.verdict == Verdict::kDoubtful)
    NODELET_WARN_STREAM("calibrator: calibration DOUBTFUL:\n" << res.message);
  else
    NODELET_INFO_STREAM("calibrator:\n"
                        << solutionSummary(chosen, &shown.verdict.stddev) << res.message);

  result_pub_.publish(res.result);
  if (broadcast_tf_) {
    geometry_msgs::TransformStamped tf;
    tf.header.stamp = ros::Time::now();
    tf.header.frame_id = lidar_frame;  // parent: the LiDAR; child: the camera (or a new frame)
    tf.child_frame_id = child_frame_.empty() ? camera_frame : child_frame_;
    tf.transform = toTransformMsg(chosen.camera_T_lidar.inverse());
    tf_broadcaster_->sendTransform(tf);
  }
  const std::string written = writeOutputs(run.result);
  if (!written.empty()) res.message += "result written to " + written + "\n";
  if (const std::string report = writeReport(run); !report.empty())
    res.message += "report written to " + report + "\n";
  {
    std::lock_guard<std::mutex> lock(mutex_);
    session_->setEstimate(chosen.camera_T_lidar);
    last_solution_ = chosen;
    publishMarkers(views, last_solution_);
  }
  return;
}

}  // namespace board_calib

PLUGINLIB_EXPORT_CLASS(board_calib::CalibratorNodelet, nodelet::Nodelet)
