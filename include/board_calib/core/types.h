// Basic geometric types shared by every part of the ROS-free core.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <array>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace board_calib {

using Points3 = std::vector<Eigen::Vector3d>;
using Points2 = std::vector<Eigen::Vector2d>;

/// Plane {x : normal . x = offset}. Convention across the package: the unit normal points away
/// from the observing sensor (towards the board's back, i.e. the board frame's +z), so `offset`
/// is the positive perpendicular distance from the sensor origin in metres.
struct Plane {
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();
  double offset = 0.0;  ///< m

  double signedDistance(const Eigen::Vector3d& p) const { return normal.dot(p) - offset; }
  /// The same plane expressed in another frame: p_new = T * p_old.
  Plane transformed(const Eigen::Isometry3d& new_T_old) const {
    Plane out;
    out.normal = new_T_old.linear() * normal;
    out.offset = offset + out.normal.dot(new_T_old.translation());
    return out;
  }
};

/// Board edges named by where they lie as the sensor sees the board held as a diamond
/// (image u right / v down; for a LiDAR: "up" is the sensor's +z, "right" is seen from the
/// sensor). Index order is used in arrays of four edges everywhere in the package.
enum EdgeIndex : int { kUpperLeft = 0, kUpperRight = 1, kLowerRight = 2, kLowerLeft = 3 };
constexpr int kNumEdges = 4;
const char* edgeName(int edge);  // "UL", "UR", "LR", "LL"

/// A value or the reason there is none. The core never logs; it returns reasons.
template <typename T>
class Expected {
 public:
  Expected(T value) : value_(std::move(value)) {}  // NOLINT: implicit by design
  static Expected failure(std::string reason) {
    Expected e;
    e.error_ = std::move(reason);
    return e;
  }
  bool ok() const { return value_.has_value(); }
  explicit operator bool() const { return ok(); }
  const T& value() const { return *value_; }
  T& value() { return *value_; }
  const T& operator*() const { return *value_; }
  T& operator*() { return *value_; }
  const T* operator->() const { return &*value_; }
  T* operator->() { return &*value_; }
  const std::string& error() const { return error_; }

 private:
  Expected() = default;
  std::optional<T> value_;
  std::string error_;
};

/// Success or a reason, for operations without a value.
struct Status {
  bool ok = true;
  std::string reason;
  static Status success() { return {}; }
  static Status failure(std::string why) { return {false, std::move(why)}; }
  explicit operator bool() const { return ok; }
};

}  // namespace board_calib
