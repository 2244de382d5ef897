// Rig mode of the calibrator nodelet: the session services, the autosave, the output files and
// the diagnostics (see calibrator_rig_mode_impl.h).
#include "calibrator_rig_mode_impl.h"

#include "calibrator_options.h"

#include <board_calib/calibrator_status.h>
#include <board_calib/core/pipeline/calibration_files.h>
#include <board_calib/core/pipeline/rig_report.h>

#include <iomanip>
#include <sstream>

namespace board_calib {

void RigCalibratorMode::Impl::report(const SessionEvent& e, const std::string& source) {
  if (e.kind == SessionEvent::Kind::kAccepted) {
    last_event = source + ": " + e.message;
    ROS_INFO_STREAM_NAMED(kRigLog, "calibrator: captured " << e.message << "; "
                                                           << session->poses().size()
                                                           << " board poses");
    autosave();
  } else if (e.kind == SessionEvent::Kind::kRejected) {
    last_event = source + ": " + e.message;
    ROS_WARN_STREAM_THROTTLE_NAMED(2.0, kRigLog, "calibrator: " << source << ": " << e.message);
  } else if (e.message.find("already saw") != std::string::npos) {
    last_event = source + ": " + e.message;
    ROS_INFO_STREAM_THROTTLE_NAMED(5.0, kRigLog, "calibrator: " << e.message);
  }
}

// Called with mutex held after every change of the captured poses (see the pair mode).
void RigCalibratorMode::Impl::autosave() {
  if (autosave_path.empty()) return;
  const Status st = session->save(autosave_path);
  if (!st)
    ROS_WARN_STREAM_THROTTLE_NAMED(10.0, kRigLog, "calibrator: autosave failed: " << st.reason);
}

// Resumes an autosave after a respawn in the same roslaunch run (same /run_id) or, with
// ~resume, of an earlier run (the rig's sensors must match); else moves it aside.
void RigCalibratorMode::Impl::resumeAutosave(bool resume) {
  std::string run_id;
  ros::param::get("/run_id", run_id);
  const AutosaveRun run = checkAutosaveRun(autosave_path, run_id);
  if (!run.exists) return;
  Status st = resume || run.respawned
                  ? session->load(autosave_path)
                  : Status::failure("it is from an earlier run (set ~resume true to resume it)");
  if (st) {
    ROS_INFO_STREAM_NAMED(
        kRigLog, "calibrator: found an autosaved rig session in "
                     << autosave_path << ": resumed " << session->poses().size()
                     << " board poses (~reset drops them; set ~resume false to start empty)");
    return;
  }
  const auto aside =
      moveAutosaveAside(autosave_path, static_cast<long long>(ros::WallTime::now().sec));
  ROS_WARN_STREAM_NAMED(kRigLog,
                        "calibrator: found an autosaved rig session in "
                            << autosave_path << ", not resumed: " << st.reason << "; "
                            << (aside ? "kept as " + *aside : aside.error() + ", autosave is off"));
  if (!aside) autosave_path.clear();
}

void RigCalibratorMode::Impl::reconfigure(CalibratorConfig& c, uint32_t) {
  // The rig file's stamp_tolerance_s stays in force: sync_tolerance is a pair-mode setting.
  std::lock_guard<std::mutex> lock(mutex);
  const multi_sensor::RigSessionOptions o = rigSessionOptionsFromConfig(c, session->options());
  if (const std::string why = o.validate(); !why.empty()) {
    ROS_WARN_STREAM_NAMED(kRigLog, "calibrator: rejected reconfiguration: " << why);
    return;
  }
  session->setOptions(o);
}

std::string RigCalibratorMode::Impl::writeOutputs(const ResultFile& file,
                                                  const multi_sensor::MsgSolution& s) {
  if (output_dir.empty()) return "";
  std::vector<std::string> warnings;
  const auto path = writeCalibrationFiles(
      output_dir, "msg_rig", file,
      {{"_static_transforms.launch", rigStaticTransformsLaunch(s, child_frame_suffix)}}, &warnings);
  for (const auto& w : warnings) ROS_ERROR_STREAM_NAMED(kRigLog, "calibrator: " << w);
  if (!path) ROS_ERROR_STREAM_NAMED(kRigLog, "calibrator: " << path.error());
  return path ? *path : "";
}

// The same report folder as calibrate_bag --config --report, in ~output_dir/report (figures per
// pair from the captured features; the projections draw the live overlays).
std::string RigCalibratorMode::Impl::writeReport(const multi_sensor::MsgProblem& problem,
                                                 const multi_sensor::MsgSolution& solution,
                                                 const ResultFile& file) {
  if (output_dir.empty()) return "";
  RigReportInputs inputs;
  inputs.source = "live session, rig `" + rig_file + "`";
  // The detector nodelets send board features, not frames: no raw image reaches rig mode.
  inputs.overlays_note =
      "No overlays in a live report: the calibrator receives board features, not images. The "
      "projection nodelets draw the live overlays; `calibrate_bag --config ... --report` on a "
      "recording of the session writes them here.";
  {
    std::lock_guard<std::mutex> lock(mutex);
    inputs.input_lines = rigHealthLines(session->health());
  }
  const std::string dir = output_dir + "/report";
  const Status st = writeRigReport(dir, rig, problem, solution, file, inputs);
  if (!st) {
    ROS_ERROR_STREAM_NAMED(kRigLog, "calibrator: rig report: " << st.reason);
    return "";
  }
  return dir + "/report.md";
}

// One static transform per sensor from the reference sensor's frame.
void RigCalibratorMode::Impl::broadcastPoses(const multi_sensor::MsgSolution& solution) {
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
std::string RigCalibratorMode::Impl::writeFailed(const ResultFile& file) {
  if (output_dir.empty()) return "";
  const auto path = writeFailedCalibrationFile(output_dir, "msg_rig", file);
  if (!path) ROS_ERROR_STREAM_NAMED(kRigLog, "calibrator: " << path.error());
  return path ? *path : "";
}

bool RigCalibratorMode::Impl::capture(std_srvs::Trigger::Request&,
                                      std_srvs::Trigger::Response& res) {
  std::lock_guard<std::mutex> lock(mutex);
  const SessionEvent e = session->captureNow();
  report(e, "capture");
  res.success = e.kind == SessionEvent::Kind::kAccepted;
  res.message = e.message;
  return true;
}

bool RigCalibratorMode::Impl::reset(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res) {
  std::lock_guard<std::mutex> lock(mutex);
  const size_t dropped = session->poses().size();
  session->reset();
  last_solution.reset();
  res.success = true;
  res.message = "rig session reset (" + std::to_string(dropped) + " board poses dropped)";
  autosave();
  ROS_INFO_STREAM_NAMED(kRigLog, "calibrator: " << res.message);
  return true;
}

bool RigCalibratorMode::Impl::save(SessionFile::Request& req, SessionFile::Response& res) {
  std::lock_guard<std::mutex> lock(mutex);
  session->flush();
  const Status st = session->save(req.path);
  res.success = st.ok;
  res.views = static_cast<uint32_t>(session->poses().size());
  res.message =
      st.ok ? "saved " + std::to_string(res.views) + " board poses to " + req.path : st.reason;
  return true;
}

bool RigCalibratorMode::Impl::load(SessionFile::Request& req, SessionFile::Response& res) {
  std::lock_guard<std::mutex> lock(mutex);
  const Status st = session->load(req.path);
  res.success = st.ok;
  res.views = static_cast<uint32_t>(session->poses().size());
  res.message =
      st.ok ? "loaded " + std::to_string(res.views) + " board poses from " + req.path : st.reason;
  if (st.ok) autosave();
  return true;
}

bool RigCalibratorMode::Impl::drop(DropView::Request& req, DropView::Response& res) {
  std::lock_guard<std::mutex> lock(mutex);
  const Status st = session->dropPose(static_cast<int>(req.view_id));
  res.success = st.ok;
  res.message = st.ok ? "board pose " + std::to_string(req.view_id) + " dropped" : st.reason;
  if (st.ok) autosave();
  return true;
}

// One sensor in words: does it see the board now, which poses it joined, or why none.
std::string RigCalibratorMode::Impl::sensorLine(const multi_sensor::RigSensorHealth& h,
                                                double silent_s) const {
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
void RigCalibratorMode::Impl::diagnose(diagnostic_updater::DiagnosticStatusWrapper& stat) {
  namespace keys = calibrator_status;
  std::lock_guard<std::mutex> lock(mutex);
  using diagnostic_msgs::DiagnosticStatus;
  const std::vector<std::string> problems = session->problems();
  const std::vector<multi_sensor::RigSensorHealth> health = session->health();
  const size_t poses = session->poses().size();
  if (!problems.empty())
    stat.summary(DiagnosticStatus::WARN, problems.front());
  else if (poses < 3)
    stat.summary(DiagnosticStatus::WARN, "collecting board poses (" + std::to_string(poses) + ")");
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

}  // namespace board_calib
