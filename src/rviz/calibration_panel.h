// rviz panel that drives a calibrator nodelet through its topics and services only: live status
// from /diagnostics, the latched calibration_result, buttons for the ~ services (called on a
// worker thread; replies are posted back to the GUI thread).
#pragma once

#ifndef Q_MOC_RUN
#include <board_calib/CalibrationResult.h>
#include <diagnostic_msgs/DiagnosticArray.h>
#include <ros/ros.h>
#include <rviz/panel.h>

#include "job_queue.h"
#endif

#include <QString>

#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

class QComboBox;
class QGroupBox;
class QLabel;
class QLineEdit;
class QPushButton;
class QSpinBox;
class QTableWidget;
class QTimer;

namespace board_calib {

class CalibrationPanel : public rviz::Panel {
  Q_OBJECT

 public:
  explicit CalibrationPanel(QWidget* parent = nullptr);
  ~CalibrationPanel() override;

  void onInitialize() override;
  void load(const rviz::Config& config) override;
  void save(rviz::Config config) const override;

 private Q_SLOTS:
  void onNamespaceEdited();
  void onCapture();
  void onDiscardLast();
  void onDropView();
  void onCalibrate();
  void onReset();
  void onSaveSession();
  void onLoadSession();
  void onViewClicked(int row, int column);
  void onTick();

 private:
  void connectTo(const QString& ns);
  void onDiagnostics(const diagnostic_msgs::DiagnosticArrayConstPtr& msg);
  void onResult(const CalibrationResultConstPtr& msg);

  /// Calls NAMESPACE/service on the worker thread, then on_reply(reached, srv) on the GUI thread.
  template <class Srv>
  void callService(const char* service, Srv srv, std::function<void(bool, const Srv&)> on_reply);
  void showReply(const QString& action, bool ok, const QString& message);
  QString noService(const char* service) const;
  void dropView(int view_id);

  QGroupBox* buildStatusBox();  // calibration_panel_view.cpp
  QGroupBox* buildSessionBox();
  QGroupBox* buildResultBox();
  void showStatus();
  void showResult();
  void writeStateFile() const;  // test hook, see BOARD_CALIB_PANEL_STATE_FILE in the .cpp

  // Settings (saved in the rviz config).
  QLineEdit* namespace_edit_;
  QComboBox* method_combo_;
  QLineEdit* session_path_edit_;
  // Status.
  QLabel* summary_label_;
  QLabel* views_label_;
  QLabel* lidar_label_;
  QLabel* camera_label_;
  QLabel* motion_label_;
  QLabel* advice_label_;
  QLabel* event_label_;
  // Actions.
  QPushButton* capture_button_;
  QPushButton* discard_button_;
  QPushButton* drop_button_;
  QSpinBox* drop_spin_;
  QPushButton* calibrate_button_;
  QPushButton* reset_button_;
  QPushButton* save_button_;
  QPushButton* load_button_;
  QLabel* reply_label_;
  // Result.
  QTableWidget* views_table_;
  QLabel* verdict_label_;
  QLabel* result_label_;
  QTimer* tick_timer_;

  std::string ns_;  // the calibrator's private namespace, e.g. /calibrator
  ros::NodeHandle nh_;
  ros::Subscriber diagnostics_sub_, result_sub_;

  // Latest calibrator status (GUI thread only: rviz spins the global queue there).
  struct Status {
    int level = -1;  // diagnostic_msgs::DiagnosticStatus level, -1 before any status
    QString summary, lidar, camera, motion, event;
    QStringList advice;
    std::vector<int> view_ids;
    ros::WallTime received;
  } status_;
  std::optional<CalibrationResult> result_;
  bool calibrating_ = false;
  std::string state_file_;
  mutable long state_writes_ = 0;

  // Last: joined first on destruction, before the widgets their replies update.
  std::unique_ptr<JobQueue> solve_jobs_;  // ~calibrate
  std::unique_ptr<JobQueue> jobs_;        // every other service
};

}  // namespace board_calib
