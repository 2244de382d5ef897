// Small helpers the core modules share for the words and figures they return.
#pragma once

#include <algorithm>
#include <sstream>
#include <string>
#include <vector>

namespace board_calib {

/// `value` with `precision` digits after the point ("12.35").
inline std::string formatFixed(double value, int precision = 2) {
  std::ostringstream s;
  s.setf(std::ios::fixed);
  s.precision(precision);
  s << value;
  return s.str();
}

/// Median (the upper one for an even count); 0 for none.
inline double medianOf(std::vector<double> values) {
  if (values.empty()) return 0.0;
  std::nth_element(values.begin(), values.begin() + values.size() / 2, values.end());
  return values[values.size() / 2];
}

}  // namespace board_calib
