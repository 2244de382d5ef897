// The calibration panel's widgets and what they show: the layout of its three boxes, the status
// and the last solve, the replies, and the test hook's state file (see calibration_panel.h).
#include "calibration_panel.h"
#include "calibration_panel_text.h"

#include <board_calib/calibrator_status.h>
#include <board_calib/core/common/statistics.h>

#include <QComboBox>
#include <QGridLayout>
#include <QGroupBox>
#include <QHeaderView>
#include <QJsonArray>
#include <QJsonDocument>
#include <QJsonObject>
#include <QLabel>
#include <QLineEdit>
#include <QPushButton>
#include <QSaveFile>
#include <QSpinBox>
#include <QTableWidget>
#include <QTextDocument>
#include <QVBoxLayout>

#include <algorithm>
#include <cmath>

namespace board_calib {
namespace {

// The calibrator publishes its status every second: three missed periods mean it is gone.
constexpr double kStatusStaleS = 3.0;
// A view whose residual exceeds this multiple of the median over the views is highlighted
// (relative to the session's own spread, so it holds for any sensor and resolution).
constexpr double kOutlierFactor = 3.0;

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

// Median of the finite values; NaN for none (no view is then an outlier).
double finiteMedian(std::vector<double> values) {
  values.erase(
      std::remove_if(values.begin(), values.end(), [](double v) { return !std::isfinite(v); }),
      values.end());
  return values.empty() ? std::nan("") : medianOf(std::move(values));
}

QLabel* wrappingLabel(const QString& text = QString()) {
  auto* label = new QLabel(text);
  label->setWordWrap(true);
  label->setTextInteractionFlags(Qt::TextSelectableByMouse);
  return label;
}

}  // namespace

QGroupBox* CalibrationPanel::buildStatusBox() {
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

  return status_box;
}

QGroupBox* CalibrationPanel::buildSessionBox() {
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

  return actions_box;
}

QGroupBox* CalibrationPanel::buildResultBox() {
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

  return result_box;
}

void CalibrationPanel::showReply(const QString& action, bool ok, const QString& message) {
  reply_label_->setText(colouredText(action + ": " + message, ok ? "#1a7f37" : "#c62828"));
  if (ok)
    ROS_INFO_STREAM("calibration panel: " << action.toStdString() << ": " << message.toStdString());
  else
    ROS_WARN_STREAM("calibration panel: " << action.toStdString() << ": " << message.toStdString());
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
  const double mlre_median = finiteMedian(mlre), plane_median = finiteMedian(plane);
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
