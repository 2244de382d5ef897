#include <board_calib/core/camera_model.h>

#include <algorithm>
#include <sstream>

namespace board_calib {

const char* distortionModelName(DistortionModel model) {
  switch (model) {
    case DistortionModel::kNone: return "none";
    case DistortionModel::kPlumbBob: return "plumb_bob";
    case DistortionModel::kRationalPolynomial: return "rational_polynomial";
    case DistortionModel::kEquidistant: return "equidistant";
  }
  return "unknown";
}

Expected<DistortionModel> parseDistortionModel(const std::string& name) {
  if (name.empty() || name == "none") return DistortionModel::kNone;
  if (name == "plumb_bob") return DistortionModel::kPlumbBob;
  if (name == "rational_polynomial") return DistortionModel::kRationalPolynomial;
  if (name == "equidistant" || name == "fisheye") return DistortionModel::kEquidistant;
  return Expected<DistortionModel>::failure(
      "unknown distortion model '" + name +
      "' (supported: plumb_bob, rational_polynomial, equidistant)");
}

Expected<CameraModel> CameraModel::create(const CameraIntrinsics& in) {
  std::ostringstream why;
  if (in.width <= 0 || in.height <= 0) {
    why << "image size " << in.width << "x" << in.height << " is not positive";
  } else if (!(in.fx > 0) || !(in.fy > 0) || !std::isfinite(in.fx) || !std::isfinite(in.fy)) {
    why << "focal lengths fx=" << in.fx << " fy=" << in.fy
        << " are not positive (uncalibrated camera?)";
  } else if (!std::isfinite(in.cx) || !std::isfinite(in.cy)) {
    why << "principal point is not finite";
  } else {
    size_t max_coeffs = 0;
    switch (in.model) {
      case DistortionModel::kNone: max_coeffs = 8; break;  // tolerate zeros
      case DistortionModel::kPlumbBob: max_coeffs = 5; break;
      case DistortionModel::kRationalPolynomial: max_coeffs = 8; break;
      case DistortionModel::kEquidistant: max_coeffs = 4; break;
    }
    if (in.coeffs.size() > max_coeffs) {
      why << distortionModelName(in.model) << " takes at most " << max_coeffs
          << " coefficients, got " << in.coeffs.size();
    } else if (in.model == DistortionModel::kNone &&
               std::any_of(in.coeffs.begin(), in.coeffs.end(), [](double c) { return c != 0.0; })) {
      why << "distortion coefficients given without a distortion model";
    } else if (std::any_of(in.coeffs.begin(), in.coeffs.end(),
                           [](double c) { return !std::isfinite(c); })) {
      why << "distortion coefficients are not finite";
    }
  }
  if (!why.str().empty()) return Expected<CameraModel>::failure(why.str());
  return CameraModel(in);
}

CameraModel::CameraModel(const CameraIntrinsics& in) : in_(in) {
  for (size_t i = 0; i < in.coeffs.size() && i < 8; ++i) k_[i] = in.coeffs[i];
  // Bounding box of the image border in undistorted pixels, sampled along the border.
  ubox_[0] = ubox_[1] = std::numeric_limits<double>::max();
  ubox_[2] = ubox_[3] = std::numeric_limits<double>::lowest();
  constexpr int kSamples = 32;
  for (int i = 0; i <= kSamples; ++i) {
    const double s = static_cast<double>(i) / kSamples;
    const Eigen::Vector2d border[4] = {{s * in_.width, 0.0},
                                       {s * in_.width, double(in_.height)},
                                       {0.0, s * in_.height},
                                       {double(in_.width), s * in_.height}};
    for (const auto& b : border) {
      const Eigen::Vector2d u = undistortPixel(b);
      ubox_[0] = std::min(ubox_[0], u.x());
      ubox_[1] = std::min(ubox_[1], u.y());
      ubox_[2] = std::max(ubox_[2], u.x());
      ubox_[3] = std::max(ubox_[3], u.y());
    }
  }
}

Eigen::Matrix3d CameraModel::K() const {
  Eigen::Matrix3d k;
  k << in_.fx, 0, in_.cx, 0, in_.fy, in_.cy, 0, 0, 1;
  return k;
}

bool CameraModel::projectUndistorted(const Eigen::Vector3d& p, Eigen::Vector2d* pixel) const {
  if (!(p.z() > 0)) return false;
  *pixel = {in_.fx * p.x() / p.z() + in_.cx, in_.fy * p.y() / p.z() + in_.cy};
  return true;
}

Eigen::Vector2d CameraModel::undistortNormalized(const Eigen::Vector2d& raw) const {
  const Eigen::Vector2d target((raw.x() - in_.cx) / in_.fx, (raw.y() - in_.cy) / in_.fy);
  if (in_.model == DistortionModel::kNone) return target;
  // Gauss-Newton on distort(x) = target with a numeric Jacobian, starting at the target;
  // converges to ~1e-14 in a handful of steps for realistic lenses.
  Eigen::Vector2d x = target;
  constexpr int kMaxIterations = 50;
  constexpr double kStep = 1e-7;
  for (int it = 0; it < kMaxIterations; ++it) {
    Eigen::Vector2d f = x;
    distortNormalized(x.x(), x.y(), &f.x(), &f.y());
    const Eigen::Vector2d r = f - target;
    if (r.squaredNorm() < 1e-28) break;
    Eigen::Matrix2d J;
    for (int k = 0; k < 2; ++k) {
      Eigen::Vector2d xp = x;
      xp[k] += kStep;
      Eigen::Vector2d fp = xp;
      distortNormalized(xp.x(), xp.y(), &fp.x(), &fp.y());
      J.col(k) = (fp - f) / kStep;
    }
    const double det = J.determinant();
    if (!std::isfinite(det) || std::abs(det) < 1e-12) break;
    x -= J.inverse() * r;
  }
  return x;
}

Eigen::Vector2d CameraModel::undistortPixel(const Eigen::Vector2d& raw) const {
  const Eigen::Vector2d n = undistortNormalized(raw);
  return {in_.fx * n.x() + in_.cx, in_.fy * n.y() + in_.cy};
}

Eigen::Vector2d CameraModel::distortPixel(const Eigen::Vector2d& u) const {
  const double x = (u.x() - in_.cx) / in_.fx, y = (u.y() - in_.cy) / in_.fy;
  double xd = x, yd = y;
  distortNormalized(x, y, &xd, &yd);
  return {in_.fx * xd + in_.cx, in_.fy * yd + in_.cy};
}

Eigen::Vector3d CameraModel::unprojectRay(const Eigen::Vector2d& raw) const {
  const Eigen::Vector2d n = undistortNormalized(raw);
  return Eigen::Vector3d(n.x(), n.y(), 1.0).normalized();
}

bool CameraModel::isVisible(const Eigen::Vector3d& p, double margin_px,
                            Eigen::Vector2d* raw_out) const {
  // A ray through an undistorted pixel (z = 1, the image searches' case) needs no division by z:
  // the same values, x / 1 being x.
  const bool unit_depth = p.z() == 1.0;
  Eigen::Vector2d u;
  if (unit_depth)
    u = {in_.fx * p.x() + in_.cx, in_.fy * p.y() + in_.cy};
  else if (!projectUndistorted(p, &u))
    return false;
  if (u.x() < ubox_[0] - margin_px || u.x() > ubox_[2] + margin_px ||
      u.y() < ubox_[1] - margin_px || u.y() > ubox_[3] + margin_px)
    return false;
  Eigen::Vector2d raw = Eigen::Vector2d::Zero();
  if (unit_depth) {
    distortNormalized(p.x(), p.y(), &raw.x(), &raw.y());
    raw = {in_.fx * raw.x() + in_.cx, in_.fy * raw.y() + in_.cy};
  } else {
    project(p, &raw);
  }
  if (raw_out) *raw_out = raw;
  return raw.x() >= -margin_px && raw.y() >= -margin_px && raw.x() < in_.width + margin_px &&
         raw.y() < in_.height + margin_px;
}

}  // namespace board_calib
