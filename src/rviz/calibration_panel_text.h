// Coloured rich text for the calibration panel's labels (shared by its two source files).
#pragma once

#include <QString>

namespace board_calib {

inline QString colouredText(const QString& text, const char* colour) {
  return QString("<span style=\"color:%1\">%2</span>").arg(colour, text.toHtmlEscaped());
}

}  // namespace board_calib
