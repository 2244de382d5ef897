// Small helpers the core modules share for the words and figures they return.
#pragma once

#include <sstream>
#include <string>

namespace board_calib {

/// `value` with `precision` digits after the point ("12.35").
inline std::string formatFixed(double value, int precision = 2) {
  std::ostringstream s;
  s.setf(std::ios::fixed);
  s.precision(precision);
  s << value;
  return s.str();
}

}  // namespace board_calib
