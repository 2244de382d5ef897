// Calibrator nodelet, pair mode: the session services, the autosave, the output files and the
// diagnostics (see calibrator.h).
#include "calibrator.h"

#include <board_calib/calibrator_status.h>
#include <board_calib/core/file_io.h>
#include <board_calib/core/pipeline/calibration_files.h>
#include <board_calib/core/pipeline/pair_report.h>
#include <board_calib/core/report/report.h>

namespace board_calib {

constexpr double kAutosaveWarnPeriodS = 10.0;

// A starting calibrator finds an autosave. A respawn within the same roslaunch run (same
// /run_id: the manager crashed) always resumes it; one of an earlier run only with ~resume
// (yesterday's views may come from another mounting). Otherwise, or for another board, the file
// is moved aside under a dated name: it is never overwritten unseen.
void CalibratorNodelet::resumeAutosave(bool resume) {
  std::string run_id;
  ros::param::get("/run_id", run_id);
  const AutosaveRun run = checkAutosaveRun(autosave_path_, run_id);
  if (!run.exists) return;
  PairSession found(session_->target(), session_->options());
  const Status st = found.load(autosave_path_);
  std::string not_resumed;
  if (!st)
    not_resumed = st.reason;
  else if (targetToYaml(found.target()) != targetToYaml(session_->target()))
    not_resumed = std::string("it was recorded with another board (") +
                  targetTypeName(found.target().type) + ")";
  else if (!resume && !run.respawned)
    not_resumed = "it is from an earlier run (set ~resume true to resume it)";
  if (not_resumed.empty() && session_->load(autosave_path_)) {
    NODELET_INFO_STREAM("calibrator: found an autosaved session in "
                        << autosave_path_ << ": resumed " << session_->views().size() << " views"
                        << (run.respawned ? " after a restart" : "") << " (~reset drops them)");
    return;
  }
  const auto aside =
      moveAutosaveAside(autosave_path_, static_cast<long long>(ros::WallTime::now().sec));
  NODELET_WARN_STREAM("calibrator: found an autosaved session in "
                      << autosave_path_ << " with " << found.views().size()
                      << " views, not resumed: " << not_resumed << "; "
                      << (aside ? "kept as " + *aside : aside.error() + ", autosave is off"));
  if (!aside) autosave_path_.clear();
}

// Called with mutex_ held, after every change of the kept views.
void CalibratorNodelet::autosave() {
  if (autosave_path_.empty()) return;
  const Status st = session_->save(autosave_path_);
  if (!st)
    NODELET_WARN_STREAM_THROTTLE(kAutosaveWarnPeriodS,
                                 "calibrator: autosave failed: " << st.reason);
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
  const auto path = writeFailedCalibrationFile(output_dir_, file.method, file);
  if (!path) NODELET_ERROR_STREAM("calibrator: " << path.error());
  return path ? *path : "";
}

std::string CalibratorNodelet::writeOutputs(const ResultFile& file) {
  if (output_dir_.empty()) return "";
  const std::string child = child_frame_.empty() ? file.camera_frame : child_frame_;
  std::vector<std::string> warnings;
  const auto path = writeCalibrationFiles(
      output_dir_, file.method, file,
      {{"_static_transform.launch", staticTransformLaunchSnippet(file, child)},
       {"_urdf_joint.xml", urdfJointSnippet(file, child)}},
      &warnings);
  for (const auto& w : warnings) NODELET_ERROR_STREAM("calibrator: " << w);
  if (!path) NODELET_ERROR_STREAM("calibrator: " << path.error());
  return path ? *path : "";
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
