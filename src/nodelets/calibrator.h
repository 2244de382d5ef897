// Calibrator nodelet (pair mode; see calibrator.cpp): the class shared by its two source files,
// calibrator.cpp (start-up, feature callbacks, the solve) and calibrator_services.cpp (session
// services, autosave, output files, diagnostics). Private to the nodelet library.
#pragma once

#include "calibrator_rig_mode.h"

#include <board_calib/Calibrate.h>
#include <board_calib/CalibrationResult.h>
#include <board_calib/CalibratorConfig.h>
#include <board_calib/DropView.h>
#include <board_calib/SessionFile.h>
#include <board_calib/conversions.h>
#include <board_calib/core/pipeline/pair_calibration.h>
#include <board_calib/core/session/session.h>

#include <diagnostic_updater/diagnostic_updater.h>
#include <dynamic_reconfigure/server.h>
#include <nodelet/nodelet.h>
#include <ros/ros.h>
#include <std_srvs/Trigger.h>
#include <tf2_ros/static_transform_broadcaster.h>

#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

namespace board_calib {

class CalibratorNodelet : public nodelet::Nodelet {
 private:
  void onInit() override;
  void startAutosave(ros::NodeHandle& pnh);
  void advertise(ros::NodeHandle& nh, ros::NodeHandle& pnh);
  void onLidar(const LidarBoardConstPtr& msg);
  void onCamera(const CameraBoardConstPtr& msg);
  void report(const SessionEvent& event, const char* source);
  void reconfigure(CalibratorConfig& config, uint32_t level);
  bool calibrate(Calibrate::Request& req, Calibrate::Response& res);
  bool calibrateChecked(Calibrate::Request& req, Calibrate::Response& res);
  void publishRun(const PairCalibration& run, const std::vector<View>& views, const Target& target,
                  const std::string& camera_frame, const std::string& lidar_frame,
                  Calibrate::Response* res);
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

}  // namespace board_calib
