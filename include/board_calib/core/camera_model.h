// Camera intrinsics and distortion, matching sensor_msgs/CameraInfo conventions (plumb_bob,
// rational_polynomial, equidistant). "Undistorted pixels" throughout the package means the
// ideal pinhole image with the same K (no rectification, no new camera matrix).
#pragma once

#include <board_calib/core/types.h>

#include <cmath>
#include <string>
#include <vector>

namespace board_calib {

enum class DistortionModel { kNone, kPlumbBob, kRationalPolynomial, kEquidistant };
const char* distortionModelName(DistortionModel model);
/// Parses a CameraInfo distortion_model string ("" means none).
Expected<DistortionModel> parseDistortionModel(const std::string& name);

/// ROS-free mirror of the parts of sensor_msgs/CameraInfo the core needs.
struct CameraIntrinsics {
  int width = 0;                          ///< px
  int height = 0;                         ///< px
  double fx = 0, fy = 0, cx = 0, cy = 0;  ///< px
  DistortionModel model = DistortionModel::kNone;
  /// plumb_bob: k1 k2 p1 p2 [k3]; rational_polynomial: k1 k2 p1 p2 k3 k4 k5 k6;
  /// equidistant: k1 k2 k3 k4.
  std::vector<double> coeffs;
};

/// Same calibration (a camera model built for one serves the other).
inline bool operator==(const CameraIntrinsics& a, const CameraIntrinsics& b) {
  return a.width == b.width && a.height == b.height && a.fx == b.fx && a.fy == b.fy &&
         a.cx == b.cx && a.cy == b.cy && a.model == b.model && a.coeffs == b.coeffs;
}
inline bool operator!=(const CameraIntrinsics& a, const CameraIntrinsics& b) { return !(a == b); }

class CameraModel {
 public:
  CameraModel() = default;
  /// Validates the intrinsics (positive size and focal lengths, coefficient count) first.
  static Expected<CameraModel> create(const CameraIntrinsics& intrinsics);

  const CameraIntrinsics& intrinsics() const { return in_; }
  int width() const { return in_.width; }
  int height() const { return in_.height; }
  Eigen::Matrix3d K() const;

  /// Distorts normalised image coordinates (x/z, y/z); templated so Ceres can differentiate.
  template <typename T>
  void distortNormalized(const T& x, const T& y, T* xd, T* yd) const;

  /// Projects a camera-frame point to raw (distorted) pixels. Returns false behind the camera.
  template <typename T>
  bool project(const T* p_camera, T* pixel) const {
    if (!(p_camera[2] > T(0))) return false;
    const T x = p_camera[0] / p_camera[2], y = p_camera[1] / p_camera[2];
    T xd = x, yd = y;
    distortNormalized(x, y, &xd, &yd);
    pixel[0] = T(in_.fx) * xd + T(in_.cx);
    pixel[1] = T(in_.fy) * yd + T(in_.cy);
    return true;
  }
  bool project(const Eigen::Vector3d& p_camera, Eigen::Vector2d* pixel) const {
    return project(p_camera.data(), pixel->data());
  }
  /// Pinhole projection without distortion (undistorted pixels).
  bool projectUndistorted(const Eigen::Vector3d& p_camera, Eigen::Vector2d* pixel) const;

  /// Raw pixel -> normalised undistorted coordinates (iterative inverse of the distortion).
  Eigen::Vector2d undistortNormalized(const Eigen::Vector2d& raw_pixel) const;
  /// Raw pixel -> undistorted pixel (same K).
  Eigen::Vector2d undistortPixel(const Eigen::Vector2d& raw_pixel) const;
  /// Undistorted pixel -> raw pixel.
  Eigen::Vector2d distortPixel(const Eigen::Vector2d& undistorted_pixel) const;
  /// Unit viewing ray (camera frame, z > 0) through a raw pixel.
  Eigen::Vector3d unprojectRay(const Eigen::Vector2d& raw_pixel) const;
  /// True if a camera-frame point lies in front of the camera and projects inside the image.
  /// Culls by the undistorted ray first, so far off-axis points cannot fold back through the
  /// distortion polynomial into the image. `raw`, when given, receives the projected raw pixel
  /// whenever the ray passed the cull (callers that sample there need not distort again).
  bool isVisible(const Eigen::Vector3d& p_camera, double margin_px = 0.0,
                 Eigen::Vector2d* raw = nullptr) const;

 private:
  explicit CameraModel(const CameraIntrinsics& in);
  CameraIntrinsics in_;
  double k_[8] = {0, 0, 0, 0, 0, 0, 0, 0};  // coefficients padded with zeros
  // Undistorted-pixel bounding box of the image (for culling), computed once.
  double ubox_[4] = {0, 0, 0, 0};
};

template <typename T>
void CameraModel::distortNormalized(const T& x, const T& y, T* xd, T* yd) const {
  using std::atan;
  using std::sqrt;
  *xd = x;  // identity unless a model below applies
  *yd = y;
  switch (in_.model) {
    case DistortionModel::kNone:
      *xd = x;
      *yd = y;
      return;
    case DistortionModel::kPlumbBob:
    case DistortionModel::kRationalPolynomial: {
      const T r2 = x * x + y * y, r4 = r2 * r2, r6 = r4 * r2;
      T radial = T(1) + T(k_[0]) * r2 + T(k_[1]) * r4 + T(k_[4]) * r6;
      if (in_.model == DistortionModel::kRationalPolynomial)
        radial = radial / (T(1) + T(k_[5]) * r2 + T(k_[6]) * r4 + T(k_[7]) * r6);
      const T p1(k_[2]), p2(k_[3]);
      *xd = x * radial + T(2) * p1 * x * y + p2 * (r2 + T(2) * x * x);
      *yd = y * radial + p1 * (r2 + T(2) * y * y) + T(2) * p2 * x * y;
      return;
    }
    case DistortionModel::kEquidistant: {
      const T r2 = x * x + y * y;
      // Below ~1e-10 the map is the identity to double precision; avoid 0/0 in derivatives.
      if (r2 < T(1e-20)) {
        *xd = x;
        *yd = y;
        return;
      }
      const T r = sqrt(r2);
      const T theta = atan(r), t2 = theta * theta, t4 = t2 * t2, t6 = t4 * t2, t8 = t4 * t4;
      const T theta_d =
          theta * (T(1) + T(k_[0]) * t2 + T(k_[1]) * t4 + T(k_[2]) * t6 + T(k_[3]) * t8);
      const T scale = theta_d / r;
      *xd = x * scale;
      *yd = y * scale;
      return;
    }
  }
}

}  // namespace board_calib
