// Calibrator nodelet: collects LiDAR and camera board features into a PairSession (core),
// solves on ~calibrate off the callback thread, publishes the latched result, broadcasts the
// static TF and writes the result file with launch/URDF snippets. With ~rig_file it runs the
// multi-sensor rig mode instead (calibrator_rig_mode.h). Thin wiring only.
#include "calibrator_options.h"
#include "calibrator_rig_mode.h"

#include <board_calib/Calibrate.h>
#include <board_calib/CalibrationResult.h>
#include <board_calib/CalibratorConfig.h>
#include <board_calib/DropView.h>
#include <board_calib/SessionFile.h>
#include <board_calib/calibrator_status.h>
#include <board_calib/conversions.h>
#include <board_calib/core/file_io.h>
#include <board_calib/core/pipeline/pair_calibration.h>
#include <board_calib/core/pipeline/pair_report.h>
#include <board_calib/core/report/report.h>
#include <board_calib/core/session/session.h>
#include <board_calib/core/transform.h>

#include <diagnostic_updater/diagnostic_updater.h>
#include <dynamic_reconfigure/server.h>
#include <nodelet/nodelet.h>
#include <ros/ros.h>
#include <std_srvs/Trigger.h>
#include <tf2_ros/static_transform_broadcaster.h>
#include <visualization_msgs/MarkerArray.h>
#include <pluginlib/class_list_macros.hpp>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <future>
#include <mutex>

namespace board_calib {

constexpr const char* kAutosaveFileName = "autosave_session.yaml";
constexpr double kAutosaveWarnPeriodS = 10.0;

class CalibratorNodelet : public nodelet::Nodelet {
 private:
  void onInit() override;
  void onLidar(const LidarBoardConstPtr& msg);
  void onCamera(const CameraBoardConstPtr& msg);
  void report(const SessionEvent& event, const char* source);
  void reconfigure(CalibratorConfig& config, uint32_t level);
  bool calibrate(Calibrate::Request& req, Calibrate::Response& res);
  bool calibrateChecked(Calibrate::Request& req, Calibrate::Response& res);
  void resumeAutosave(bool resume);
  void autosave();
  bool capture(std_srvs::Trigger::Request& req, std_srvs::Trigger::Response& res);
  bool reset(std_srvs::Trigger::Request& req, std_srvs::Trigger::Response& res);
  bool saveSession(SessionFile::Request& req, SessionFile::Response& res);
  bool loadSession(SessionFile::Request& req, SessionFile::Response& res);
  bool dropView(DropView::Request& req, DropView::Response& res);
  void publishMarkers(const std::vector<View>& views,
                      const std::optional<CalibrationSolution>& solution);
  void diagnose(diagnostic_updater::DiagnosticStatusWrapper& stat);
  std::string writeOutputs(const ResultFile& file);
  std::string writeFailedResult(const ResultFile& file);
  std::string writeReport(const PairCalibration& run);

  std::mutex mutex_;  // guards session_, last_event_, last_solution_
  std::unique_ptr<PairSession> session_;
  std::string default_method_ = "pbpc";
  std::string child_frame_;
  std::string output_dir_;
  bool broadcast_tf_ = true;
  std::string last_event_ = "waiting for features";
  std::optional<CalibrationSolution> last_solution_;
  std::string camera_frame_, lidar_frame_;
  int lidar_msgs_ = 0, camera_msgs_ = 0;
  std::string lidar_board_state_ = "no message",
              camera_board_state_ = "no message";  // for /diagnostics
  std::mutex solve_mutex_;                         // one solve at a time
  std::string autosave_path_;                      // empty: autosave off

  ros::Subscriber lidar_sub_, camera_sub_;
  ros::Publisher result_pub_, markers_pub_;
  std::vector<ros::ServiceServer> services_;
  std::unique_ptr<tf2_ros::StaticTransformBroadcaster> tf_broadcaster_;
  std::unique_ptr<dynamic_reconfigure::Server<CalibratorConfig>> reconfigure_server_;
  std::unique_ptr<diagnostic_updater::Updater> diagnostics_;
  ros::WallTimer diagnostics_timer_;
  ros::WallTime last_feature_wall_;
  static constexpr double kQuietStreamsS = 2.0;  // s of wall time without features
  std::unique_ptr<RigCalibratorMode> rig_mode_;  // set when ~rig_file is given
};

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
  // Autosave: every captured or dropped view is saved, so a crashed manager loses nothing.
  bool autosave_enabled = true, resume = false;
  pnh.param("autosave", autosave_enabled, true);
  pnh.param("resume", resume, false);
  if (autosave_enabled && !output_dir_.empty()) {
    std::error_code error;
    std::filesystem::create_directories(output_dir_, error);
    if (error) {
      NODELET_ERROR_STREAM("calibrator: cannot create " << output_dir_ << " (" << error.message()
                                                        << "): views are not autosaved");
    } else {
      autosave_path_ = output_dir_ + "/" + kAutosaveFileName;
      resumeAutosave(resume);
    }
  }

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

  // The calibrator subscribes eagerly: it must see every feature to collect views.
  lidar_sub_ = nh.subscribe("lidar_board", 10, &CalibratorNodelet::onLidar, this);
  camera_sub_ = nh.subscribe("camera_board", 10, &CalibratorNodelet::onCamera, this);
  NODELET_INFO_STREAM("calibrator: target " << targetTypeName(target->type) << " " << target->width
                                            << " x " << target->height << " m; waiting for "
                                            << nh.resolveName("lidar_board") << " and "
                                            << nh.resolveName("camera_board"));
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

// A starting calibrator finds an autosave. A respawn within the same roslaunch run (same
// /run_id: the manager crashed) always resumes it; one of an earlier run only with ~resume
// (yesterday's views may come from another mounting). Otherwise, or for another board, the file
// is moved aside under a dated name: it is never overwritten unseen.
void CalibratorNodelet::resumeAutosave(bool resume) {
  std::string run_id;
  ros::param::get("/run_id", run_id);
  const std::string run_id_path = autosave_path_ + ".run_id";
  std::error_code error;
  if (!std::filesystem::exists(autosave_path_, error)) {
    (void)writeFileAtomic(run_id_path, run_id);
    return;
  }
  const auto previous_run = readTextFile(run_id_path, "autosave run id");
  const bool respawned = previous_run && !run_id.empty() && *previous_run == run_id;
  PairSession found(session_->target(), session_->options());
  const Status st = found.load(autosave_path_);
  std::string not_resumed;
  if (!st)
    not_resumed = st.reason;
  else if (targetToYaml(found.target()) != targetToYaml(session_->target()))
    not_resumed = std::string("it was recorded with another board (") +
                  targetTypeName(found.target().type) + ")";
  else if (!resume && !respawned)
    not_resumed = "it is from an earlier run (set ~resume true to resume it)";
  (void)writeFileAtomic(run_id_path, run_id);
  if (not_resumed.empty() && session_->load(autosave_path_)) {
    NODELET_INFO_STREAM("calibrator: found an autosaved session in "
                        << autosave_path_ << ": resumed " << session_->views().size() << " views"
                        << (respawned ? " after a restart" : "") << " (~reset drops them)");
    return;
  }
  const std::string aside =
      autosave_path_ + "." + std::to_string(static_cast<long long>(ros::WallTime::now().sec));
  std::filesystem::rename(autosave_path_, aside, error);
  NODELET_WARN_STREAM("calibrator: found an autosaved session in "
                      << autosave_path_ << " with " << found.views().size()
                      << " views, not resumed: " << not_resumed << "; "
                      << (error
                              ? "could not move it aside (" + error.message() + "), autosave is off"
                              : "kept as " + aside));
  if (error) autosave_path_.clear();
}

// Called with mutex_ held, after every change of the kept views.
void CalibratorNodelet::autosave() {
  if (autosave_path_.empty()) return;
  const Status st = session_->save(autosave_path_);
  if (!st)
    NODELET_WARN_STREAM_THROTTLE(kAutosaveWarnPeriodS,
                                 "calibrator: autosave failed: " << st.reason);
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

// The same report folder as calibrate_bag --report (no overlays: the calibrator keeps features,
// not raw frames), in ~output_dir/report.
std::string CalibratorNodelet::writeReport(const PairCalibration& run) {
  if (output_dir_.empty()) return "";
  PairReportInputs inputs;
  inputs.source = "live session";
  inputs.child_frame = child_frame_;
  std::lock_guard<std::mutex> lock(mutex_);
  const Status st = writePairReport(output_dir_ + "/report", run, *session_, inputs);
  if (!st) {
    NODELET_ERROR_STREAM("calibrator: report: " << st.reason);
    return "";
  }
  return output_dir_ + "/report/report.md";
}

std::string CalibratorNodelet::writeFailedResult(const ResultFile& file) {
  if (output_dir_.empty()) return "";
  std::error_code error;
  std::filesystem::create_directories(output_dir_, error);
  const std::string path = failedResultPath(output_dir_ + "/" + file.method + "_result.yaml");
  const Status st = writeResultFile(path, file);
  if (!st) {
    NODELET_ERROR_STREAM("calibrator: " << st.reason);
    return "";
  }
  return path;
}

std::string CalibratorNodelet::writeOutputs(const ResultFile& file) {
  if (output_dir_.empty()) return "";
  std::error_code error;
  std::filesystem::create_directories(output_dir_, error);
  if (error) {
    NODELET_ERROR_STREAM("calibrator: cannot create " << output_dir_ << ": " << error.message());
    return "";
  }
  const std::string child = child_frame_.empty() ? file.camera_frame : child_frame_;
  const std::string base = output_dir_ + "/" + file.method;
  const Status st = writeResultFile(base + "_result.yaml", file);
  if (!st) {
    NODELET_ERROR_STREAM("calibrator: " << st.reason);
    return "";
  }
  for (const auto& [path, text] :
       {std::make_pair(base + "_static_transform.launch",
                       staticTransformLaunchSnippet(file, child)),
        std::make_pair(base + "_urdf_joint.xml", urdfJointSnippet(file, child))})
    if (const Status written = writeFileAtomic(path, text); !written)
      NODELET_ERROR_STREAM("calibrator: " << written.reason);
  return base + "_result.yaml";
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
    res.message = "no views collected yet: hold the board still in front of both sensors (" +
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
  if (run.runs.empty()) {  // refused before any solve (options, guess, views)
    res.success = false;
    res.message = "calibration failed: " + run.reason;
    NODELET_WARN_STREAM("calibrator: " << res.message);
    return true;
  }
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
    return true;
  }
  res.success = true;
  const CalibrationSolution& chosen = shown.solution;
  if (run.verdict == Verdict::kDoubtful)
    NODELET_WARN_STREAM("calibrator: calibration DOUBTFUL:\n" << res.message);
  else
    NODELET_INFO_STREAM("calibrator:\n" << solutionSummary(chosen) << res.message);

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
  return true;
}

bool CalibratorNodelet::capture(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res) {
  std::lock_guard<std::mutex> lock(mutex_);
  const SessionEvent e = session_->captureNow();
  report(e, "capture");
  res.success = e.kind == SessionEvent::Kind::kAccepted;
  res.message = e.message;
  return true;
}

bool CalibratorNodelet::reset(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res) {
  std::lock_guard<std::mutex> lock(mutex_);
  const size_t dropped = session_->views().size();
  session_->reset();
  last_solution_.reset();
  publishMarkers({}, std::nullopt);
  autosave();
  res.success = true;
  res.message = "session reset (" + std::to_string(dropped) + " views dropped)";
  NODELET_INFO_STREAM("calibrator: " << res.message);
  return true;
}

bool CalibratorNodelet::saveSession(SessionFile::Request& req, SessionFile::Response& res) {
  std::lock_guard<std::mutex> lock(mutex_);
  const Status st = session_->save(req.path);
  res.success = st.ok;
  res.views = static_cast<uint32_t>(session_->views().size());
  res.message = st.ok ? "saved " + std::to_string(res.views) + " views to " + req.path : st.reason;
  return true;
}

bool CalibratorNodelet::loadSession(SessionFile::Request& req, SessionFile::Response& res) {
  std::lock_guard<std::mutex> lock(mutex_);
  // A session of another board would switch the board type and drop the current views.
  PairSession candidate(session_->target(), session_->options());
  Status st = candidate.load(req.path);
  if (st && targetToYaml(candidate.target()) != targetToYaml(session_->target()))
    st = Status::failure("'" + req.path + "' was recorded with a " +
                         targetTypeName(candidate.target().type) +
                         " board that differs from this calibrator's target; current views kept");
  if (st) st = session_->load(req.path);
  res.success = st.ok;
  res.views = static_cast<uint32_t>(session_->views().size());
  res.message =
      st.ok ? "loaded " + std::to_string(res.views) + " views from " + req.path : st.reason;
  if (st.ok) {
    publishMarkers(session_->plainViews(), std::nullopt);
    autosave();
  }
  return true;
}

bool CalibratorNodelet::dropView(DropView::Request& req, DropView::Response& res) {
  std::lock_guard<std::mutex> lock(mutex_);
  const Status st = session_->dropView(static_cast<int>(req.view_id));
  res.success = st.ok;
  res.message = st.ok ? "view " + std::to_string(req.view_id) + " dropped" : st.reason;
  if (st.ok) {
    publishMarkers(session_->plainViews(), last_solution_);
    autosave();
  }
  return true;
}

void CalibratorNodelet::publishMarkers(const std::vector<View>& views,
                                       const std::optional<CalibrationSolution>& solution) {
  markers_pub_.publish(toViewMarkers(views, solution ? &*solution : nullptr));
}

void CalibratorNodelet::diagnose(diagnostic_updater::DiagnosticStatusWrapper& stat) {
  std::lock_guard<std::mutex> lock(mutex_);
  const CoverageReport cov = session_->coverage();
  using diagnostic_msgs::DiagnosticStatus;
  if (lidar_msgs_ == 0 || camera_msgs_ == 0)
    stat.summary(DiagnosticStatus::WARN, lidar_msgs_ == 0 ? "no LiDAR board features received"
                                                          : "no camera board features received");
  else if (cov.views < 3)
    stat.summary(DiagnosticStatus::WARN, "collecting views (" + std::to_string(cov.views) + ")");
  else
    stat.summary(DiagnosticStatus::OK, std::to_string(cov.views) + " views collected");
  stat.add(calibrator_status::kServices, getPrivateNodeHandle().getNamespace());
  stat.add(calibrator_status::kViews, cov.views);
  std::string ids;
  for (const auto& v : session_->views())
    ids += (ids.empty() ? "" : " ") + std::to_string(v.view.id);
  stat.add(calibrator_status::kViewIds, ids);
  stat.add(calibrator_status::kLidarBoard, lidar_board_state_);
  stat.add(calibrator_status::kCameraBoard, camera_board_state_);
  // The last image's stillness judgement, in words ("board still for ...", "board moving: ...").
  const std::string& stillness = session_->captureStats().last_stillness;
  stat.add(calibrator_status::kBoardMotion,
           stillness.empty() ? std::string("no image judged yet") : stillness);
  stat.add("lidar feature messages", lidar_msgs_);
  stat.add("camera feature messages", camera_msgs_);
  stat.add(calibrator_status::kLastEvent, last_event_);
  stat.add("capture", session_->captureStats().summary());
  stat.add("tilt span (deg)", cov.tilt_span_deg);
  stat.add("range (m)", std::to_string(cov.range_min_m) + " - " + std::to_string(cov.range_max_m));
  stat.add("image coverage", cov.image_coverage);
  for (size_t i = 0; i < cov.advice.size(); ++i)
    stat.add(calibrator_status::kAdvicePrefix + std::to_string(i + 1), cov.advice[i]);
  if (last_solution_) {
    stat.add("last solve", std::string(methodName(last_solution_->method)) + " with " +
                               std::to_string(last_solution_->views_used) + " views");
    if (last_solution_->mlre_px) stat.add("last MLRE (px)", *last_solution_->mlre_px);
    stat.add("last plane RMS (mm)", last_solution_->plane_rms_mm);
    if (!last_solution_->observability.well_conditioned)
      stat.add("weak direction", last_solution_->observability.weakest_description);
  }
}

}  // namespace board_calib

PLUGINLIB_EXPORT_CLASS(board_calib::CalibratorNodelet, nodelet::Nodelet)
