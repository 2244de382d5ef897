// Order statistics the core modules share.
#pragma once

#include <algorithm>
#include <vector>

namespace board_calib {

/// What the median of an even count is.
enum class EvenMedian {
  kUpper,        ///< the upper middle value: a robust scale stays an observed residual
  kMeanOfMiddle  ///< the mean of the two middle values: with two entries, neither one decides
};

/// Median of `values`; 0 for none.
inline double medianOf(std::vector<double> values, EvenMedian even = EvenMedian::kUpper) {
  if (values.empty()) return 0.0;
  const auto mid = values.begin() + static_cast<std::ptrdiff_t>(values.size() / 2);
  std::nth_element(values.begin(), mid, values.end());
  if (even == EvenMedian::kUpper || values.size() % 2 == 1) return *mid;
  return 0.5 * (*mid + *std::max_element(values.begin(), mid));
}

}  // namespace board_calib
