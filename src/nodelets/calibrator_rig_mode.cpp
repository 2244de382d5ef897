// Rig mode of the calibrator nodelet (see calibrator_rig_mode.h).
#include "calibrator_rig_mode.h"

#include "calibrator_options.h"

#include <board_calib/Calibrate.h>
#include <board_calib/CalibrationResult.h>
#include <board_calib/CalibratorConfig.h>
#include <board_calib/DropView.h>
#include <board_calib/SessionFile.h>
#include <board_calib/calibrator_status.h>
#include <board_calib/conversions.h>
#include <board_calib/core/file_io.h>
#include <board_calib/core/msg_graph/msg_graph.h>
#include <board_calib/core/pipeline/rig_calibration.h>
#include <board_calib/core/pipeline/rig_report.h>
#include <board_calib/core/result_io.h>
#include <board_calib/core/rig/rig_config.h>
#include <board_calib/core/rig/rig_session.h>
#include <board_calib/core/rig/rig_summary.h>

#include <diagnostic_updater/diagnostic_updater.h>
#include <dynamic_reconfigure/server.h>
#include <std_srvs/Trigger.h>
#include <tf2_ros/static_transform_broadcaster.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <future>
#include <iomanip>
#include <mutex>
#include <optional>
#include <sstream>

namespace board_calib {

namespace {
constexpr char kLog[] = "calibrator";
}  // namespace

struct RigCalibratorMode::Impl {
  ros::NodeHandle nh, pnh;
  RigConfig rig;
  Target target;
  int reference = 0;
  std::string rig_file;
  std::mutex mutex;        // guards session, last_event, last_solution
  std::mutex solve_mutex;  // one solve at a time
  std::unique_ptr<multi_sensor::RigSession> session;
  std::string last_event = "waiting for features";
  std::optional<multi_sensor::MsgSolution> last_solution;
  std::string child_frame_suffix;
  std::string output_dir;
  bool broadcast_tf = true;
  std::string autosave_path;                     // empty: autosave off
  std::vector<ros::WallTime> last_message_wall;  // per sensor, for "silent" in diagnostics
  static constexpr double kSilentS = 2.0;  // s of wall time without features: the stream stopped

  std::vector<ros::Subscriber> subscribers;
  ros::Publisher result_pub;
  std::vector<ros::ServiceServer> services;
  std::unique_ptr<tf2_ros::StaticTransformBroadcaster> tf_broadcaster;
  std::unique_ptr<dynamic_reconfigure::Server<CalibratorConfig>> reconfigure_server;
  std::unique_ptr<diagnostic_updater::Updater> diagnostics;
  ros::WallTimer diagnostics_timer;

  void report(const SessionEvent& e, const std::string& source) {
    if (e.kind == SessionEvent::Kind::kAccepted) {
      last_event = source + ": " + e.message;
      ROS_INFO_STREAM_NAMED(kLog, "calibrator: captured " << e.message << "; "
                                                          << session->poses().size()
                                                          << " board poses");
      autosave();
    } else if (e.kind == SessionEvent::Kind::kRejected) {
      last_event = source + ": " + e.message;
      ROS_WARN_STREAM_THROTTLE_NAMED(2.0, kLog, "calibrator: " << source << ": " << e.message);
    } else if (e.message.find("already saw") != std::string::npos) {
      last_event = source + ": " + e.message;
      ROS_INFO_STREAM_THROTTLE_NAMED(5.0, kLog, "calibrator: " << e.message);
    }
  }

  // Called with mutex held after every change of the captured poses (see the pair mode).
  void autosave() {
    if (autosave_path.empty()) return;
    const Status st = session->save(autosave_path);
    if (!st)
      ROS_WARN_STREAM_THROTTLE_NAMED(10.0, kLog, "calibrator: autosave failed: " << st.reason);
  }

  // Resumes an autosave after a respawn in the same roslaunch run (same /run_id) or, with
  // ~resume, of an earlier run (the rig's sensors must match); else moves it aside.
  void resumeAutosave(bool resume) {
    std::string run_id;
    ros::param::get("/run_id", run_id);
    const std::string run_id_path = autosave_path + ".run_id";
    std::error_code error;
    const bool exists = std::filesystem::exists(autosave_path, error);
    const auto previous_run = readTextFile(run_id_path, "autosave run id");
    const bool respawned = previous_run && !run_id.empty() && *previous_run == run_id;
    (void)writeFileAtomic(run_id_path, run_id);
    if (!exists) return;
    Status st = resume || respawned
                    ? session->load(autosave_path)
                    : Status::failure("it is from an earlier run (set ~resume true to resume it)");
    if (st) {
      ROS_INFO_STREAM_NAMED(
          kLog, "calibrator: found an autosaved rig session in "
                    << autosave_path << ": resumed " << session->poses().size()
                    << " board poses (~reset drops them; set ~resume false to start empty)");
      return;
    }
    const std::string aside =
        autosave_path + "." + std::to_string(static_cast<long long>(ros::WallTime::now().sec));
    std::filesystem::rename(autosave_path, aside, error);
    ROS_WARN_STREAM_NAMED(
        kLog, "calibrator: found an autosaved rig session in "
                  << autosave_path << ", not resumed: " << st.reason << "; "
                  << (error ? "could not move it aside (" + error.message() + "), autosave is off"
                            : "kept as " + aside));
    if (error) autosave_path.clear();
  }

  void onCamera(int k, const CameraBoardConstPtr& m) {
    std::lock_guard<std::mutex> lock(mutex);
    last_message_wall[k] = ros::WallTime::now();
    report(session->addCamera(k, fromMsg(*m)), rig.cameras[k].name);
  }

  void onLidar(int k, const LidarBoardConstPtr& m) {
    std::lock_guard<std::mutex> lock(mutex);
    last_message_wall[k] = ros::WallTime::now();
    const size_t i = static_cast<size_t>(k) - rig.cameras.size();
    report(session->addLidar(k, fromMsg(*m)), rig.lidars[i].name);
  }

  void reconfigure(CalibratorConfig& c, uint32_t) {
    // The rig file's stamp_tolerance_s stays in force: sync_tolerance is a pair-mode setting.
    std::lock_guard<std::mutex> lock(mutex);
    const multi_sensor::RigSessionOptions o = rigSessionOptionsFromConfig(c, session->options());
    if (const std::string why = o.validate(); !why.empty()) {
      ROS_WARN_STREAM_NAMED(kLog, "calibrator: rejected reconfiguration: " << why);
      return;
    }
    session->setOptions(o);
  }

  std::string writeOutputs(const ResultFile& file, const multi_sensor::MsgSolution& s) {
    if (output_dir.empty()) return "";
    std::error_code error;
    std::filesystem::create_directories(output_dir, error);
    if (error) {
      ROS_ERROR_STREAM_NAMED(kLog,
                             "calibrator: cannot create " << output_dir << ": " << error.message());
      return "";
    }
    const std::string base = output_dir + "/msg_rig";
    const Status st = writeResultFile(base + "_result.yaml", file);
    if (!st) {
      ROS_ERROR_STREAM_NAMED(kLog, "calibrator: " << st.reason);
      return "";
    }
    // One static_transform_publisher per sensor, ready to paste into a bring-up launch file.
    std::ostringstream launch;
    launch << std::setprecision(9) << "<launch>\n"
           << "  <!-- Needs tf2_ros's static_transform_publisher (ROS Noetic; Debian's ROS "
              "packages lack it: there run\n"
           << "       roslaunch board_calib publish_calibration.launch "
              "result_file:=msg_rig_result.yaml) -->\n";
    const std::string& parent = s.sensors[s.reference_sensor].frame;
    for (size_t k = 0; k < s.sensors.size(); ++k) {
      if (static_cast<int>(k) == s.reference_sensor) continue;
      const auto& e = s.sensors[k];
      const Eigen::Vector3d t = e.reference_T_sensor.translation();
      const Eigen::Quaterniond q(e.reference_T_sensor.linear());
      launch << "  <node pkg=\"tf2_ros\" type=\"static_transform_publisher\" name=\"board_calib_"
             << e.frame << "\" args=\"" << t.x() << " " << t.y() << " " << t.z() << " " << q.x()
             << " " << q.y() << " " << q.z() << " " << q.w() << " " << parent << " "
             << e.frame + child_frame_suffix << "\"/>\n";
    }
    launch << "</launch>\n";
    const Status snippet = writeFileAtomic(base + "_static_transforms.launch", launch.str());
    if (!snippet) ROS_ERROR_STREAM_NAMED(kLog, "calibrator: " << snippet.reason);
    return base + "_result.yaml";
  }

  // The same report folder as calibrate_bag --config --report, in ~output_dir/report (figures per
  // pair from the captured features; the projections draw the live overlays).
  std::string writeReport(const multi_sensor::MsgProblem& problem,
                          const multi_sensor::MsgSolution& solution, const ResultFile& file) {
    if (output_dir.empty()) return "";
    RigReportInputs inputs;
    inputs.source = "live session, rig `" + rig_file + "`";
    {
      std::lock_guard<std::mutex> lock(mutex);
      for (const auto& h : session->health())
        inputs.input_lines.push_back("`" + h.name + "` (" + h.frame + "): board in " +
                                     std::to_string(h.counts.found) + "/" +
                                     std::to_string(h.counts.messages) + " frames, in " +
                                     std::to_string(h.pose_ids.size()) + " poses");
    }
    const std::string dir = output_dir + "/report";
    const Status st = writeRigReport(dir, rig, problem, solution, file, inputs);
    if (!st) {
      ROS_ERROR_STREAM_NAMED(kLog, "calibrator: rig report: " << st.reason);
      return "";
    }
    return dir + "/report.md";
  }

  // One static transform per sensor from the reference sensor's frame.
  void broadcastPoses(const multi_sensor::MsgSolution& solution) {
    std::vector<geometry_msgs::TransformStamped> tfs;
    for (size_t k = 0; k < solution.sensors.size(); ++k) {
      if (static_cast<int>(k) == solution.reference_sensor) continue;
      geometry_msgs::TransformStamped tf;
      tf.header.stamp = ros::Time::now();
      tf.header.frame_id = solution.sensors[static_cast<size_t>(solution.reference_sensor)].frame;
      tf.child_frame_id = solution.sensors[k].frame + child_frame_suffix;
      tf.transform = toTransformMsg(solution.sensors[k].reference_T_sensor);
      tfs.push_back(tf);
    }
    tf_broadcaster->sendTransform(tfs);
  }

  // A failed result for inspection, under a name no tool mistakes for a calibration.
  std::string writeFailed(const ResultFile& file) {
    if (output_dir.empty()) return "";
    std::error_code error;
    std::filesystem::create_directories(output_dir, error);
    const std::string path = failedResultPath(output_dir + "/msg_rig_result.yaml");
    const Status st =
        error ? Status::failure("cannot create " + output_dir) : writeResultFile(path, file);
    if (!st) ROS_ERROR_STREAM_NAMED(kLog, "calibrator: " << st.reason);
    return st ? path : "";
  }

  bool calibrate(Calibrate::Request& req, Calibrate::Response& res) {
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
          kLog,
          "calibrator: rig mode initialises from the pairwise solutions; the guess is ignored");
    multi_sensor::MsgProblem problem;
    std::vector<std::string> problems;  // sensors that take part in no pose, and why
    {
      std::lock_guard<std::mutex> lock(mutex);
      report(session->flush(), "calibrate");
      problem = session->problem(reference);
      problems = session->problems();
    }
    for (const auto& p : problems) ROS_WARN_STREAM_NAMED(kLog, "calibrator: " << p);
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
      ROS_WARN_STREAM_NAMED(kLog, "calibrator: " << res.message);
      return true;
    }
    const ResultFile& file = run.result;
    res.message = rigSolutionSummary(rig, solution, file) + rigVerdictSummary(run);
    for (const auto& p : problems) res.message += "warning: " + p + "\n";
    if (run.failed()) {
      // Never broadcast, never over the good file: kept for inspection only.
      res.success = false;
      const std::string written = writeFailed(file);
      if (!written.empty())
        res.message += "FAILED result written for inspection to " + written + "\n";
      ROS_ERROR_STREAM_NAMED(kLog, "calibrator: calibration failed: " << run.reason << "\n"
                                                                      << res.message);
      return true;
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
    ROS_INFO_STREAM_NAMED(kLog, "calibrator:\n" << res.message);

    if (broadcast_tf) broadcastPoses(solution);
    const std::string written = writeOutputs(file, solution);
    if (!written.empty()) res.message += "result written to " + written + "\n";
    const std::string report = writeReport(run.problem, solution, file);
    if (!report.empty()) res.message += "report written to " + report + "\n";
    std::lock_guard<std::mutex> lock(mutex);
    last_solution = solution;
    return true;
  }

  bool capture(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res) {
    std::lock_guard<std::mutex> lock(mutex);
    const SessionEvent e = session->captureNow();
    report(e, "capture");
    res.success = e.kind == SessionEvent::Kind::kAccepted;
    res.message = e.message;
    return true;
  }

  bool reset(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res) {
    std::lock_guard<std::mutex> lock(mutex);
    const size_t dropped = session->poses().size();
    session->reset();
    last_solution.reset();
    res.success = true;
    res.message = "rig session reset (" + std::to_string(dropped) + " board poses dropped)";
    autosave();
    ROS_INFO_STREAM_NAMED(kLog, "calibrator: " << res.message);
    return true;
  }

  bool save(SessionFile::Request& req, SessionFile::Response& res) {
    std::lock_guard<std::mutex> lock(mutex);
    session->flush();
    const Status st = session->save(req.path);
    res.success = st.ok;
    res.views = static_cast<uint32_t>(session->poses().size());
    res.message =
        st.ok ? "saved " + std::to_string(res.views) + " board poses to " + req.path : st.reason;
    return true;
  }

  bool load(SessionFile::Request& req, SessionFile::Response& res) {
    std::lock_guard<std::mutex> lock(mutex);
    const Status st = session->load(req.path);
    res.success = st.ok;
    res.views = static_cast<uint32_t>(session->poses().size());
    res.message =
        st.ok ? "loaded " + std::to_string(res.views) + " board poses from " + req.path : st.reason;
    if (st.ok) autosave();
    return true;
  }

  bool drop(DropView::Request& req, DropView::Response& res) {
    std::lock_guard<std::mutex> lock(mutex);
    const Status st = session->dropPose(static_cast<int>(req.view_id));
    res.success = st.ok;
    res.message = st.ok ? "board pose " + std::to_string(req.view_id) + " dropped" : st.reason;
    if (st.ok) autosave();
    return true;
  }

  // Eager subscriptions: the calibrator must see every feature to capture poses. Returns the
  // resolved topics, for the start-up log.
  std::string subscribeFeatures() {
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

  // One sensor in words: does it see the board now, which poses it joined, or why none.
  std::string sensorLine(const multi_sensor::RigSensorHealth& h, double silent_s) const {
    std::ostringstream v;
    if (h.counts.messages == 0)
      v << "no features yet";
    else if (silent_s > kSilentS)
      v << "silent for " << std::fixed << std::setprecision(0) << silent_s << " s";
    else if (h.counts.board_now)
      v << "sees the board now";
    else
      v << "no board now: " << h.counts.last_reason;
    v << "; " << h.counts.found << "/" << h.counts.messages << " frames with the board";
    if (h.pose_ids.empty()) {
      v << "; in no pose: " << h.why_no_pose;
    } else {
      v << "; in " << h.pose_ids.size() << " poses:";
      for (int id : h.pose_ids) v << " " << id;
    }
    return v.str();
  }

  // The pair mode's keys (calibrator_status.h), so the rviz panel reads either mode; the LiDAR
  // and camera rows list every sensor of that kind, one key per sensor has the details.
  void diagnose(diagnostic_updater::DiagnosticStatusWrapper& stat) {
    namespace keys = calibrator_status;
    std::lock_guard<std::mutex> lock(mutex);
    using diagnostic_msgs::DiagnosticStatus;
    const std::vector<std::string> problems = session->problems();
    const std::vector<multi_sensor::RigSensorHealth> health = session->health();
    const size_t poses = session->poses().size();
    if (!problems.empty())
      stat.summary(DiagnosticStatus::WARN, problems.front());
    else if (poses < 3)
      stat.summary(DiagnosticStatus::WARN,
                   "collecting board poses (" + std::to_string(poses) + ")");
    else
      stat.summary(DiagnosticStatus::OK, std::to_string(poses) + " board poses collected");
    stat.add(keys::kServices, pnh.getNamespace());
    stat.add("rig", rig_file);
    stat.add(keys::kViews, poses);
    std::string ids;
    for (const auto& p : session->poses())
      ids += (ids.empty() ? "" : " ") + std::to_string(p.observation.id);
    stat.add(keys::kViewIds, ids);
    const ros::WallTime now = ros::WallTime::now();
    std::string seen_now, lidars, cameras;
    for (size_t k = 0; k < health.size(); ++k) {
      const auto& h = health[k];
      const double silent_s =
          last_message_wall[k].isZero() ? 0.0 : (now - last_message_wall[k]).toSec();
      const bool now_seen = h.counts.board_now && silent_s <= kSilentS;
      if (now_seen) seen_now += (seen_now.empty() ? "" : ", ") + h.name;
      const bool camera = session->sensors()[k].kind == multi_sensor::SensorKind::kCamera;
      std::string& row = camera ? cameras : lidars;
      row += (row.empty() ? "" : "; ") + h.name + ": " +
             (now_seen                 ? "found"
              : h.counts.messages == 0 ? "no message"
                                       : "not found");
      stat.add("sensor " + h.name + " (" + h.frame + ")", sensorLine(h, silent_s));
    }
    stat.add("board seen now by", seen_now.empty() ? "no sensor" : seen_now);
    stat.add(keys::kLidarBoard, lidars);
    stat.add(keys::kCameraBoard, cameras);
    for (size_t i = 0; i < problems.size(); ++i)
      stat.add("problem " + std::to_string(i + 1), problems[i]);
    stat.add(keys::kLastEvent, last_event);
    if (last_solution) {
      stat.add("last solve", std::to_string(last_solution->poses_used) + " board poses");
      stat.add("loop consistency (deg / mm)",
               std::to_string(last_solution->loop_rotation_max_deg) + " / " +
                   std::to_string(last_solution->loop_translation_max_mm));
    }
  }
};

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
      ROS_INFO_STREAM_NAMED(kLog, "calibrator: loaded " << m.session->poses().size()
                                                        << " board poses from " << session_file);
    else
      ROS_ERROR_STREAM_NAMED(kLog, "calibrator: " << st.reason);
  }
  bool autosave_enabled = true, resume = false;
  pnh.param("autosave", autosave_enabled, true);
  pnh.param("resume", resume, false);
  if (autosave_enabled && !m.output_dir.empty()) {
    std::error_code dir_error;
    std::filesystem::create_directories(m.output_dir, dir_error);
    if (dir_error) {
      ROS_ERROR_STREAM_NAMED(kLog, "calibrator: cannot create "
                                       << m.output_dir << " (" << dir_error.message()
                                       << "): board poses are not autosaved");
    } else {
      m.autosave_path = m.output_dir + "/autosave_rig_session.yaml";
      m.resumeAutosave(resume);
    }
  }

  m.result_pub = nh.advertise<CalibrationResult>("calibration_result", 1, true);
  m.tf_broadcaster = std::make_unique<tf2_ros::StaticTransformBroadcaster>();
  m.reconfigure_server = std::make_unique<dynamic_reconfigure::Server<CalibratorConfig>>(pnh);
  m.reconfigure_server->setCallback(
      [&m](CalibratorConfig& c, uint32_t level) { m.reconfigure(c, level); });
  m.services.push_back(pnh.advertiseService("calibrate", &Impl::calibrate, &m));
  m.services.push_back(pnh.advertiseService("capture", &Impl::capture, &m));
  m.services.push_back(pnh.advertiseService("reset", &Impl::reset, &m));
  m.services.push_back(pnh.advertiseService("save_session", &Impl::save, &m));
  m.services.push_back(pnh.advertiseService("load_session", &Impl::load, &m));
  m.services.push_back(pnh.advertiseService("drop_view", &Impl::drop, &m));
  m.diagnostics = std::make_unique<diagnostic_updater::Updater>(nh, pnh);
  m.diagnostics->setHardwareID(calibrator_status::kHardwareId);
  m.diagnostics->add(calibrator_status::kStatusName,
                     [&m](diagnostic_updater::DiagnosticStatusWrapper& s) { m.diagnose(s); });
  // Wall time and force_update: with a replayed bag the sim clock stops at its end, and
  // Updater::update() paces itself by that clock, so health would freeze just when it is read.
  m.diagnostics_timer = nh.createWallTimer(
      ros::WallDuration(1.0), [&m](const ros::WallTimerEvent&) { m.diagnostics->force_update(); });

  const std::string topics = m.subscribeFeatures();
  ROS_INFO_STREAM_NAMED(kLog, "calibrator: rig mode (" << rig_file << "): " << rig->cameras.size()
                                                       << " camera(s), " << rig->lidars.size()
                                                       << " LiDAR(s), reference " << reference
                                                       << "; waiting for" << topics);
  return mode;
}

}  // namespace board_calib
