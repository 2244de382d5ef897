#include "calibration_panel.h"

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
// The calibrator publishes its status every second: three missed periods mean it is gone.
constexpr double kStatusStaleS = 3.0;
constexpr int kTickMs = 500;
// A view whose residual exceeds this multiple of the median over the views is highlighted
// (relative to the session's own spread, so it holds for any sensor and resolution).
constexpr double kOutlierFactor = 3.0;
// Test hook: when this variable names a file, the panel writes what it shows there (JSON),
// with the screen position of every button, so a headless test can click and check.
constexpr const char* kStateFileVariable = "BOARD_CALIB_PANEL_STATE_FILE";

QString colouredText(const QString& text, const char* colour) {
  return QString("<span style=\"color:%1\">%2</span>").arg(colour, text.toHtmlEscaped());
}

const char* levelColour(int level) {
  switch (level) {
    case diagnostic_msgs::DiagnosticStatus::OK: return "#1a7f37";
    case diagnostic_msgs::DiagnosticStatus::WARN: return "#b35900";
    case diagnostic_msgs::DiagnosticStatus::ERROR: return "#c62828";
    default: return "#666666";
  }
}

const char* verdictColour(const std::string& verdict) {
  if (verdict == "good") return "#1a7f37";
  if (verdict == "doubtful") return "#b35900";
  if (verdict == "failed") return "#c62828";
  return "#666666";
}

QString number(double value, int decimals) {
  return std::isfinite(value) ? QString::number(value, 'f', decimals) : QString("-");
}

double median(std::vector<double> values) {
  values.erase(
      std::remove_if(values.begin(), values.end(), [](double v) { return !std::isfinite(v); }),
      values.end());
  if (values.empty()) return std::nan("");
  std::nth_element(values.begin(), values.begin() + values.size() / 2, values.end());
  return values[values.size() / 2];
}

QLabel* wrappingLabel(const QString& text = QString()) {
  auto* label = new QLabel(text);
  label->setWordWrap(true);
  label->setTextInteractionFlags(Qt::TextSelectableByMouse);
  return label;
}

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

  auto* status_box = new QGroupBox("Status");
  auto* status_grid = new QGridLayout(status_box);
  summary_label_ = wrappingLabel();
  views_label_ = wrappingLabel();
  lidar_label_ = wrappingLabel();
  camera_label_ = wrappingLabel();
  motion_label_ = wrappingLabel();
  advice_label_ = wrappingLabel();
  event_label_ = wrappingLabel();
  int row = 0;
  status_grid->addWidget(summary_label_, row++, 0, 1, 2);
  for (auto [name, label] : {std::pair{"Views", views_label_},
                             {"LiDAR board", lidar_label_},
                             {"Camera board", camera_label_},
                             {"Board", motion_label_},
                             {"Next pose", advice_label_},
                             {"Last event", event_label_}}) {
    status_grid->addWidget(new QLabel(name), row, 0, Qt::AlignTop);
    status_grid->addWidget(label, row++, 1);
  }
  status_grid->setColumnStretch(1, 1);

  capture_button_ = new QPushButton("Capture");
  capture_button_->setToolTip("~capture: take the newest synchronised pair as a view now");
  discard_button_ = new QPushButton("Discard last");
  discard_button_->setToolTip("~drop_view with the newest view id");
  drop_button_ = new QPushButton("Drop view");
  drop_spin_ = new QSpinBox;
  drop_spin_->setRange(0, 99999);
  drop_spin_->setToolTip("view id (click a row of the view list to pick it)");
  calibrate_button_ = new QPushButton("Calibrate");
  method_combo_ = new QComboBox;
  method_combo_->addItems({"pbpc", "ppc", "msg", "all"});
  method_combo_->setToolTip("~calibrate method; all: every method side by side, the best one kept");
  reset_button_ = new QPushButton("Reset");
  reset_button_->setToolTip("~reset: forget every view and the estimate");
  session_path_edit_ = new QLineEdit;
  session_path_edit_->setPlaceholderText("session file (path on the calibrator's machine)");
  save_button_ = new QPushButton("Save");
  load_button_ = new QPushButton("Load");
  reply_label_ = wrappingLabel();

  auto* actions_box = new QGroupBox("Session");
  auto* actions = new QGridLayout(actions_box);
  actions->addWidget(capture_button_, 0, 0);
  actions->addWidget(discard_button_, 0, 1, 1, 2);
  actions->addWidget(reset_button_, 0, 3);
  actions->addWidget(drop_button_, 1, 0);
  actions->addWidget(drop_spin_, 1, 1);
  actions->addWidget(calibrate_button_, 1, 2);
  actions->addWidget(method_combo_, 1, 3);
  actions->addWidget(session_path_edit_, 2, 0, 1, 2);
  actions->addWidget(save_button_, 2, 2);
  actions->addWidget(load_button_, 2, 3);
  actions->addWidget(reply_label_, 3, 0, 1, 4);

  auto* result_box = new QGroupBox("Last solve");
  auto* result_layout = new QVBoxLayout(result_box);
  verdict_label_ = wrappingLabel();
  result_label_ = wrappingLabel();
  views_table_ = new QTableWidget(0, 3);
  views_table_->setHorizontalHeaderLabels({"view", "MLRE px", "plane RMS mm"});
  views_table_->horizontalHeader()->setMinimumSectionSize(30);
  views_table_->verticalHeader()->setVisible(false);
  views_table_->verticalHeader()->setDefaultSectionSize(views_table_->fontMetrics().height() + 6);
  views_table_->horizontalHeader()->setSectionResizeMode(QHeaderView::Stretch);
  views_table_->setEditTriggers(QAbstractItemView::NoEditTriggers);
  views_table_->setSelectionBehavior(QAbstractItemView::SelectRows);
  views_table_->setSelectionMode(QAbstractItemView::SingleSelection);
  views_table_->setMinimumHeight(6 * views_table_->verticalHeader()->defaultSectionSize());
  result_layout->addWidget(verdict_label_);
  result_layout->addWidget(result_label_);
  result_layout->addWidget(views_table_, 1);

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
  for (QLayout* l : std::initializer_list<QLayout*>{status_grid, actions, result_layout}) {
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

void CalibrationPanel::showReply(const QString& action, bool ok, const QString& message) {
  reply_label_->setText(colouredText(action + ": " + message, ok ? "#1a7f37" : "#c62828"));
  if (ok)
    ROS_INFO_STREAM("calibration panel: " << action.toStdString() << ": " << message.toStdString());
  else
    ROS_WARN_STREAM("calibration panel: " << action.toStdString() << ": " << message.toStdString());
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

void CalibrationPanel::showStatus() {
  const bool fresh =
      status_.level >= 0 && (ros::WallTime::now() - status_.received).toSec() < kStatusStaleS;
  if (!fresh) {
    const QString why = status_.level < 0
                            ? "no status from %1 on /diagnostics yet (is the calibrator running?)"
                            : "no status from %1 for a while (calibrator stopped?)";
    summary_label_->setText(colouredText(why.arg(QString::fromStdString(ns_)), levelColour(-1)));
  } else {
    summary_label_->setText(
        QString("<b>%1</b>").arg(colouredText(status_.summary, levelColour(status_.level))));
  }
  views_label_->setText(QString::number(status_.view_ids.size()));
  const auto found = [](const QString& state) {
    if (state.isEmpty()) return QString("-");
    return state == "found" ? colouredText(state, levelColour(0))
                            : colouredText(state, levelColour(1));
  };
  lidar_label_->setText(found(status_.lidar));
  camera_label_->setText(found(status_.camera));
  motion_label_->setText(status_.motion.isEmpty() ? "-" : status_.motion.toHtmlEscaped());
  advice_label_->setText(status_.advice.isEmpty() ? "-" : status_.advice.join("\n"));
  event_label_->setText(status_.event.isEmpty() ? "-" : status_.event);
}

void CalibrationPanel::showResult() {
  // Residual per view id from the last result.
  std::vector<double> mlre, plane;
  const auto residuals = [this](int id) -> std::pair<double, double> {
    if (!result_) return {std::nan(""), std::nan("")};
    const auto& r = *result_;
    for (size_t i = 0; i < r.view_ids.size(); ++i) {
      if (r.view_ids[i] != id) continue;
      return {i < r.view_mlre_px.size() ? r.view_mlre_px[i] : std::nan(""),
              i < r.view_plane_rms_mm.size() ? r.view_plane_rms_mm[i] : std::nan("")};
    }
    return {std::nan(""), std::nan("")};
  };
  for (int id : status_.view_ids) {
    const auto [m, p] = residuals(id);
    mlre.push_back(m);
    plane.push_back(p);
  }
  const double mlre_median = median(mlre), plane_median = median(plane);
  views_table_->setRowCount(static_cast<int>(status_.view_ids.size()));
  for (size_t i = 0; i < status_.view_ids.size(); ++i) {
    const int row = static_cast<int>(i);
    const auto set = [&](int column, const QString& text, bool outlier) {
      auto* item = new QTableWidgetItem(text);
      if (outlier) {
        item->setForeground(QColor("#c62828"));
        item->setToolTip(QString("more than %1 x the median over the views").arg(kOutlierFactor));
      }
      views_table_->setItem(row, column, item);
    };
    set(0, QString::number(status_.view_ids[i]), false);
    set(1, number(mlre[i], 2), std::isfinite(mlre[i]) && mlre[i] > kOutlierFactor * mlre_median);
    set(2, number(plane[i], 1),
        std::isfinite(plane[i]) && plane[i] > kOutlierFactor * plane_median);
  }

  if (!result_) {
    verdict_label_->setText(colouredText("no solve yet", "#666666"));
    result_label_->setText("");
    return;
  }
  const auto& r = *result_;
  if (r.verdict.empty()) {
    const char* verdict = r.success ? "" : "failed";
    verdict_label_->setText(colouredText(
        r.success ? "solved (no verdict in this result)" : "failed", verdictColour(verdict)));
  } else {
    const QString verdict =
        colouredText(QString::fromStdString(r.verdict).toUpper(), verdictColour(r.verdict));
    verdict_label_->setText(
        QString("<b>%1</b>: %2")
            .arg(verdict, QString::fromStdString(r.verdict_reason).toHtmlEscaped()));
  }
  if (!r.success) {
    result_label_->setText(QString::fromStdString(r.method + ": " + r.reason).toHtmlEscaped());
    return;
  }
  const double sigma_t_mm =
      1000.0 * std::sqrt(r.stddev_translation_m[0] * r.stddev_translation_m[0] +
                         r.stddev_translation_m[1] * r.stddev_translation_m[1] +
                         r.stddev_translation_m[2] * r.stddev_translation_m[2]);
  const double sigma_r_deg = std::sqrt(r.stddev_rotation_deg[0] * r.stddev_rotation_deg[0] +
                                       r.stddev_rotation_deg[1] * r.stddev_rotation_deg[1] +
                                       r.stddev_rotation_deg[2] * r.stddev_rotation_deg[2]);
  const auto& t = r.camera_T_lidar.translation;
  result_label_->setText(QString("%1, %2 views: MLRE %3 px, plane RMS %4 mm, 1σ %5 mm / %6°<br>"
                                 "t = [%7, %8, %9] m")
                             .arg(QString::fromStdString(r.method))
                             .arg(r.views_used)
                             .arg(number(r.mlre_px, 2), number(r.plane_rms_mm, 1),
                                  number(sigma_t_mm, 1), number(sigma_r_deg, 2), number(t.x, 3),
                                  number(t.y, 3), number(t.z, 3)));
}

void CalibrationPanel::writeStateFile() const {
  QJsonObject state;
  state["tick"] = static_cast<qint64>(++state_writes_);  // advances only while the GUI thread runs
  state["namespace"] = QString::fromStdString(ns_);
  const auto text = [](const QLabel* label) {
    QTextDocument doc;  // labels hold rich text; the test reads what the user reads
    doc.setHtml(label->text());
    return doc.toPlainText();
  };
  state["summary"] = text(summary_label_);
  state["views"] = text(views_label_);
  state["lidar_board"] = text(lidar_label_);
  state["camera_board"] = text(camera_label_);
  state["board"] = text(motion_label_);
  state["advice"] = text(advice_label_);
  state["last_event"] = text(event_label_);
  state["reply"] = text(reply_label_);
  state["verdict"] = text(verdict_label_);
  state["result"] = text(result_label_);
  state["calibrate_button"] = calibrate_button_->text();
  state["method"] = method_combo_->currentText();
  state["drop_view_id"] = drop_spin_->value();
  QJsonArray rows;
  for (int row = 0; row < views_table_->rowCount(); ++row) {
    QJsonArray cells;
    for (int column = 0; column < views_table_->columnCount(); ++column) {
      const QTableWidgetItem* item = views_table_->item(row, column);
      cells.append(item ? item->text() : QString());
    }
    rows.append(cells);
  }
  state["views_table"] = rows;
  // Screen centres of the widgets a test clicks (global X coordinates), and the panel's box.
  QJsonObject widgets;
  const auto centre = [](const QWidget* w) {
    const QPoint p = w->mapToGlobal(w->rect().center());
    return QJsonArray{p.x(), p.y(),
                      w->isVisible() && w->visibleRegion().contains(w->rect().center())};
  };
  widgets["namespace"] = centre(namespace_edit_);
  widgets["capture"] = centre(capture_button_);
  widgets["discard_last"] = centre(discard_button_);
  widgets["drop_view"] = centre(drop_button_);
  widgets["drop_view_id"] = centre(drop_spin_);
  widgets["calibrate"] = centre(calibrate_button_);
  widgets["method"] = centre(method_combo_);
  widgets["reset"] = centre(reset_button_);
  widgets["session_file"] = centre(session_path_edit_);
  widgets["save"] = centre(save_button_);
  widgets["load"] = centre(load_button_);
  for (int row = 0; row < views_table_->rowCount(); ++row) {
    const QRect cell = views_table_->visualRect(views_table_->model()->index(row, 0));
    const QPoint p = views_table_->viewport()->mapToGlobal(cell.center());
    widgets[QString("view_row_%1").arg(row)] = QJsonArray{
        p.x(), p.y(),
        cell.isValid() && views_table_->viewport()->visibleRegion().contains(cell.center())};
  }
  state["widgets"] = widgets;
  const QPoint origin = mapToGlobal(QPoint(0, 0));
  state["panel"] = QJsonArray{origin.x(), origin.y(), width(), height()};

  QSaveFile file(QString::fromStdString(state_file_));  // atomic: the reader never sees half a file
  if (file.open(QIODevice::WriteOnly)) {
    file.write(QJsonDocument(state).toJson());
    file.commit();
  }
}

}  // namespace board_calib

PLUGINLIB_EXPORT_CLASS(board_calib::CalibrationPanel, rviz::Panel)
