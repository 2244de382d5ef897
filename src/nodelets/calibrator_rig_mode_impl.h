// Rig mode of the calibrator nodelet: its state and members (private to the nodelet library),
// defined in calibrator_rig_mode.cpp (start-up, feature callbacks, the solve) and
// calibrator_rig_mode_services.cpp (session services, autosave, files, diagnostics).
#pragma once

#include "calibrator_rig_mode.h"

#include <board_calib/Calibrate.h>
#include <board_calib/CalibrationResult.h>
#include <board_calib/CalibratorConfig.h>
#include <board_calib/DropView.h>
#include <board_calib/SessionFile.h>
#include <board_calib/conversions.h>
#include <board_calib/core/msg_graph/msg_graph.h>
#include <board_calib/core/pipeline/rig_calibration.h>
#include <board_calib/core/result_io.h>
#include <board_calib/core/rig/rig_config.h>
#include <board_calib/core/rig/rig_session.h>

#include <diagnostic_updater/diagnostic_updater.h>
#include <dynamic_reconfigure/server.h>
#include <std_srvs/Trigger.h>
#include <tf2_ros/static_transform_broadcaster.h>

#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

namespace board_calib {

constexpr char kRigLog[] = "calibrator";

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

  // Start-up (calibrator_rig_mode.cpp).
  void startAutosave();
  void advertise();
  void publishRun(const RigCalibration& run, const std::vector<std::string>& problems,
                  Calibrate::Response* res);
  void report(const SessionEvent& e, const std::string& source);
  // Called with mutex held after every change of the captured poses (see the pair mode).
  void autosave();
  // Resumes an autosave after a respawn in the same roslaunch run (same /run_id) or, with
  // ~resume, of an earlier run (the rig's sensors must match); else moves it aside.
  void resumeAutosave(bool resume);
  void onCamera(int k, const CameraBoardConstPtr& m);
  void onLidar(int k, const LidarBoardConstPtr& m);
  void reconfigure(CalibratorConfig& c, uint32_t);
  std::string writeOutputs(const ResultFile& file, const multi_sensor::MsgSolution& s);
  // The same report folder as calibrate_bag --config --report, in ~output_dir/report (figures per
  // pair from the captured features; the projections draw the live overlays).
  std::string writeReport(const multi_sensor::MsgProblem& problem,
                          const multi_sensor::MsgSolution& solution, const ResultFile& file);
  // One static transform per sensor from the reference sensor's frame.
  void broadcastPoses(const multi_sensor::MsgSolution& solution);
  // A failed result for inspection, under a name no tool mistakes for a calibration.
  std::string writeFailed(const ResultFile& file);
  bool calibrate(Calibrate::Request& req, Calibrate::Response& res);
  bool capture(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res);
  bool reset(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res);
  bool save(SessionFile::Request& req, SessionFile::Response& res);
  bool load(SessionFile::Request& req, SessionFile::Response& res);
  bool drop(DropView::Request& req, DropView::Response& res);
  // Eager subscriptions: the calibrator must see every feature to capture poses. Returns the
  // resolved topics, for the start-up log.
  std::string subscribeFeatures();
  // One sensor in words: does it see the board now, which poses it joined, or why none.
  std::string sensorLine(const multi_sensor::RigSensorHealth& h, double silent_s) const;
  // The pair mode's keys (calibrator_status.h), so the rviz panel reads either mode; the LiDAR
  // and camera rows list every sensor of that kind, one key per sensor has the details.
  void diagnose(diagnostic_updater::DiagnosticStatusWrapper& stat);
};

}  // namespace board_calib
