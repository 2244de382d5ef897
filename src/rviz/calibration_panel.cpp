#include "calibration_panel.h"
#include "calibration_panel_text.h"

#include <board_calib/Calibrate.h>
#include <board_calib/DropView.h>
#include <board_calib/SessionFile.h>
#include <board_calib/calibrator_status.h>
#include <ros/names.h>
#include <std_srvs/Trigger.h>
#include <pluginlib/class_list_macros.hpp>

#include <QComboBox>
#include <QGridLayout>
#include <QGroupBox>
#include <QHBoxLayout>
#include <QHeaderView>
#include <QJsonArray>
#include <QJsonDocument>
#include <QJsonObject>
#include <QLabel>
#include <QLineEdit>
#include <QPushButton>
#include <QSaveFile>
#include <QScrollArea>
#include <QSpinBox>
#include <QTableWidget>
#include <QTextDocument>
#include <QTimer>
#include <QVBoxLayout>

#include <algorithm>
#include <cmath>
#include <cstdlib>

namespace board_calib {
namespace {

namespace keys = calibrator_status;

constexpr const char* kDefaultNamespace = "/calibrator";
constexpr int kTickMs = 500;
// Test hook: when this variable names a file, the panel writes what it shows there (JSON),
// with the screen position of every button, so a headless test can click and check.
constexpr const char* kStateFileVariable = "BOARD_CALIB_PANEL_STATE_FILE";

}  // namespace

CalibrationPanel::CalibrationPanel(QWidget* parent) : rviz::Panel(parent) {
  if (const char* path = std::getenv(kStateFileVariable)) state_file_ = path;

  namespace_edit_ = new QLineEdit(kDefaultNamespace);
  namespace_edit_->setToolTip(
      "the calibrator's private namespace: its services live there, its "
      "calibration_result in the parent namespace");
  auto* ns_row = new QHBoxLayout;
  ns_row->addWidget(new QLabel("Calibrator"));
  ns_row->addWidget(namespace_edit_);

  QGroupBox* status_box = buildStatusBox();
  QGroupBox* actions_box = buildSessionBox();
  QGroupBox* result_box = buildResultBox();

  // Everything scrolls inside the dock, so the panel never forces rviz's window taller than
  // the screen.
  auto* content = new QWidget;
  auto* content_layout = new QVBoxLayout(content);
  content_layout->setContentsMargins(4, 4, 4, 4);
  // Buttons above the live status: status text that re-wraps never moves them under the mouse.
  content_layout->addLayout(ns_row);
  content_layout->addWidget(actions_box);
  content_layout->addWidget(status_box);
  content_layout->addWidget(result_box, 1);
  for (QGroupBox* box : {status_box, actions_box, result_box}) {
    QLayout* l = box->layout();
    l->setContentsMargins(6, 4, 6, 4);
    l->setSpacing(3);
  }
  auto* scroll = new QScrollArea;
  scroll->setWidget(content);
  scroll->setWidgetResizable(true);
  scroll->setHorizontalScrollBarPolicy(
      Qt::ScrollBarAlwaysOff);  // widgets shrink to the dock's width
  scroll->setFrameShape(QFrame::NoFrame);
  auto* layout = new QVBoxLayout(this);
  layout->setContentsMargins(0, 0, 0, 0);
  layout->addWidget(scroll);

  connect(namespace_edit_, &QLineEdit::editingFinished, this, &CalibrationPanel::onNamespaceEdited);
  connect(capture_button_, &QPushButton::clicked, this, &CalibrationPanel::onCapture);
  connect(discard_button_, &QPushButton::clicked, this, &CalibrationPanel::onDiscardLast);
  connect(drop_button_, &QPushButton::clicked, this, &CalibrationPanel::onDropView);
  connect(calibrate_button_, &QPushButton::clicked, this, &CalibrationPanel::onCalibrate);
  connect(reset_button_, &QPushButton::clicked, this, &CalibrationPanel::onReset);
  connect(save_button_, &QPushButton::clicked, this, &CalibrationPanel::onSaveSession);
  connect(load_button_, &QPushButton::clicked, this, &CalibrationPanel::onLoadSession);
  connect(views_table_, &QTableWidget::cellClicked, this, &CalibrationPanel::onViewClicked);
  connect(method_combo_, QOverload<int>::of(&QComboBox::currentIndexChanged), this,
          [this] { Q_EMIT configChanged(); });
  connect(session_path_edit_, &QLineEdit::editingFinished, this,
          [this] { Q_EMIT configChanged(); });

  tick_timer_ = new QTimer(this);
  connect(tick_timer_, &QTimer::timeout, this, &CalibrationPanel::onTick);
  jobs_ = std::make_unique<JobQueue>();
  solve_jobs_ = std::make_unique<JobQueue>();
  showStatus();
  showResult();
}

CalibrationPanel::~CalibrationPanel() = default;

void CalibrationPanel::onInitialize() {
  connectTo(namespace_edit_->text());
  tick_timer_->start(kTickMs);
}

void CalibrationPanel::load(const rviz::Config& config) {
  rviz::Panel::load(config);
  QString value;
  if (config.mapGetString("Calibrator", &value) && !value.isEmpty())
    namespace_edit_->setText(value);
  if (config.mapGetString("Method", &value)) {
    const int index = method_combo_->findText(value);
    if (index >= 0) method_combo_->setCurrentIndex(index);
  }
  if (config.mapGetString("Session File", &value)) session_path_edit_->setText(value);
  connectTo(namespace_edit_->text());
}

void CalibrationPanel::save(rviz::Config config) const {
  rviz::Panel::save(config);
  config.mapSetValue("Calibrator", namespace_edit_->text());
  config.mapSetValue("Method", method_combo_->currentText());
  config.mapSetValue("Session File", session_path_edit_->text());
}

void CalibrationPanel::onNamespaceEdited() {
  if (namespace_edit_->text().trimmed().toStdString() == ns_) return;
  connectTo(namespace_edit_->text());
  Q_EMIT configChanged();
}

void CalibrationPanel::connectTo(const QString& ns_text) {
  std::string ns = ns_text.trimmed().toStdString();
  std::string error;
  if (ns.empty() || !ros::names::validate(ns, error)) {
    showReply("namespace", false, "invalid calibrator namespace \"" + ns_text + "\"");
    return;
  }
  ns = ros::names::resolve(ns);  // relative names resolve in rviz's namespace
  if (ns == ns_ && diagnostics_sub_) return;
  ns_ = ns;
  status_ = Status{};
  result_.reset();
  diagnostics_sub_ = nh_.subscribe("/diagnostics", 10, &CalibrationPanel::onDiagnostics, this);
  // The calibrator advertises calibration_result in its node namespace, the parent of its
  // private one.
  const std::string result_topic =
      ros::names::append(ros::names::parentNamespace(ns_), "calibration_result");
  result_sub_ = nh_.subscribe(result_topic, 1, &CalibrationPanel::onResult, this);
  showStatus();
  showResult();
}

void CalibrationPanel::onDiagnostics(const diagnostic_msgs::DiagnosticArrayConstPtr& msg) {
  const std::string suffix = std::string(": ") + keys::kStatusName;
  for (const auto& s : msg->status) {
    if (s.hardware_id != keys::kHardwareId) continue;
    const bool named = s.name == keys::kStatusName ||
                       (s.name.size() >= suffix.size() &&
                        s.name.compare(s.name.size() - suffix.size(), suffix.size(), suffix) == 0);
    if (!named) continue;
    // Several calibrators may run: take the one whose services live in our namespace.
    const auto services =
        std::find_if(s.values.begin(), s.values.end(),
                     [](const diagnostic_msgs::KeyValue& kv) { return kv.key == keys::kServices; });
    if (services != s.values.end() && services->value != ns_) continue;

    Status status;
    status.level = s.level;
    status.summary = QString::fromStdString(s.message);
    status.received = ros::WallTime::now();
    for (const auto& kv : s.values) {
      const QString value = QString::fromStdString(kv.value);
      if (kv.key == keys::kLidarBoard)
        status.lidar = value;
      else if (kv.key == keys::kCameraBoard)
        status.camera = value;
      else if (kv.key == keys::kBoardMotion)
        status.motion = value;
      else if (kv.key == keys::kLastEvent)
        status.event = value;
      else if (kv.key.rfind(keys::kAdvicePrefix, 0) == 0)
        status.advice << value;
      else if (kv.key == keys::kViewIds) {
        for (const QString& id : value.split(' ', Qt::SkipEmptyParts))
          status.view_ids.push_back(id.toInt());
      }
    }
    status_ = status;
    showStatus();
    showResult();  // the view list follows the kept views
    return;
  }
}

void CalibrationPanel::onResult(const CalibrationResultConstPtr& msg) {
  result_ = *msg;
  showResult();
}

void CalibrationPanel::onTick() {
  showStatus();  // notices a calibrator that went silent
  if (!state_file_.empty()) writeStateFile();
}

template <class Srv>
void CalibrationPanel::callService(const char* service, Srv srv,
                                   std::function<void(bool, const Srv&)> on_reply) {
  const std::string name = ros::names::append(ns_, service);
  reply_label_->setText(colouredText(
      QString("%1: calling %2 ...").arg(service, QString::fromStdString(name)), "#666666"));
  // A solve may take a while: it gets its own worker so Capture or Save still answer meanwhile.
  JobQueue& queue = std::string(service) == "calibrate" ? *solve_jobs_ : *jobs_;
  queue.post([this, name, srv, on_reply]() mutable {
    const bool reached = ros::service::call(name, srv);
    QMetaObject::invokeMethod(
        this, [on_reply, reached, srv]() { on_reply(reached, srv); }, Qt::QueuedConnection);
  });
}

QString CalibrationPanel::noService(const char* service) const {
  return QString::fromStdString("cannot call " + ros::names::append(ns_, service) +
                                " (calibrator not running?)");
}

void CalibrationPanel::onCapture() {
  callService<std_srvs::Trigger>("capture", {}, [this](bool reached, const std_srvs::Trigger& srv) {
    if (!reached) return showReply("capture", false, noService("capture"));
    showReply("capture", srv.response.success, QString::fromStdString(srv.response.message));
  });
}

void CalibrationPanel::dropView(int view_id) {
  DropView srv;
  srv.request.view_id = static_cast<uint32_t>(view_id);
  callService<DropView>("drop_view", srv, [this](bool reached, const DropView& done) {
    if (!reached) return showReply("drop view", false, noService("drop_view"));
    showReply("drop view", done.response.success, QString::fromStdString(done.response.message));
  });
}

void CalibrationPanel::onDiscardLast() {
  if (status_.view_ids.empty()) return showReply("discard last", false, "no views to discard");
  // Ids grow with every capture, so the newest view has the largest id.
  dropView(*std::max_element(status_.view_ids.begin(), status_.view_ids.end()));
}

void CalibrationPanel::onDropView() { dropView(drop_spin_->value()); }

void CalibrationPanel::onCalibrate() {
  if (calibrating_) return;
  Calibrate srv;
  srv.request.method = method_combo_->currentText().toStdString();
  calibrating_ = true;
  calibrate_button_->setEnabled(false);
  calibrate_button_->setText("Calibrating...");
  callService<Calibrate>("calibrate", srv, [this](bool reached, const Calibrate& done) {
    calibrating_ = false;
    calibrate_button_->setEnabled(true);
    calibrate_button_->setText("Calibrate");
    if (!reached) return showReply("calibrate", false, noService("calibrate"));
    // The reply carries the result even when the solve failed (then nothing is published).
    if (!done.response.result.method.empty()) {
      result_ = done.response.result;
      showResult();
    }
    const QString first_line = QString::fromStdString(done.response.message).section('\n', 0, 0);
    showReply("calibrate " + QString::fromStdString(done.request.method), done.response.success,
              first_line);
  });
}

void CalibrationPanel::onReset() {
  callService<std_srvs::Trigger>("reset", {}, [this](bool reached, const std_srvs::Trigger& srv) {
    if (!reached) return showReply("reset", false, noService("reset"));
    if (srv.response.success) {
      result_.reset();  // the calibrator forgot its estimate; its latched result is stale
      showResult();
    }
    showReply("reset", srv.response.success, QString::fromStdString(srv.response.message));
  });
}

void CalibrationPanel::onSaveSession() {
  SessionFile srv;
  srv.request.path = session_path_edit_->text().trimmed().toStdString();
  if (srv.request.path.empty())
    return showReply("save session", false, "enter a session file path first");
  callService<SessionFile>("save_session", srv, [this](bool reached, const SessionFile& done) {
    if (!reached) return showReply("save session", false, noService("save_session"));
    showReply("save session", done.response.success, QString::fromStdString(done.response.message));
  });
}

void CalibrationPanel::onLoadSession() {
  SessionFile srv;
  srv.request.path = session_path_edit_->text().trimmed().toStdString();
  if (srv.request.path.empty())
    return showReply("load session", false, "enter a session file path first");
  callService<SessionFile>("load_session", srv, [this](bool reached, const SessionFile& done) {
    if (!reached) return showReply("load session", false, noService("load_session"));
    if (done.response.success) {
      result_.reset();  // residuals of the previous views no longer apply
      showResult();
    }
    showReply("load session", done.response.success, QString::fromStdString(done.response.message));
  });
}

void CalibrationPanel::onViewClicked(int row, int) {
  if (const QTableWidgetItem* item = views_table_->item(row, 0))
    drop_spin_->setValue(item->text().toInt());
}

}  // namespace board_calib

PLUGINLIB_EXPORT_CLASS(board_calib::CalibrationPanel, rviz::Panel)
