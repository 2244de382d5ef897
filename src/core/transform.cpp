#include <board_calib/core/transform.h>

#include <Eigen/SVD>

#include <cmath>

namespace board_calib {

Eigen::Isometry3d makeTransform(const Eigen::Vector3d& t, const Eigen::Vector4d& q) {
  Eigen::Quaterniond quat(q[3], q[0], q[1], q[2]);
  quat.normalize();
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = quat.toRotationMatrix();
  T.translation() = t;
  return T;
}

Eigen::Isometry3d makeTransform(const Eigen::Matrix3d& R, const Eigen::Vector3d& t) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = R;
  T.translation() = t;
  return T;
}

Eigen::Vector4d quaternionXyzw(const Eigen::Isometry3d& T) {
  Eigen::Quaterniond q(T.rotation());
  q.normalize();
  if (q.w() < 0) q.coeffs() *= -1.0;
  return {q.x(), q.y(), q.z(), q.w()};
}

std::array<double, 16> rowMajor(const Eigen::Isometry3d& T) {
  std::array<double, 16> out{};
  const Eigen::Matrix4d m = T.matrix();
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c) out[r * 4 + c] = m(r, c);
  return out;
}

Expected<Eigen::Isometry3d> fromRowMajor(const std::vector<double>& v) {
  if (v.size() != 12 && v.size() != 16)
    return Expected<Eigen::Isometry3d>::failure(
        "a transform matrix needs 12 (3x4) or 16 (4x4) numbers, got " + std::to_string(v.size()));
  Eigen::Matrix3d R;
  Eigen::Vector3d t;
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) R(r, c) = v[r * 4 + c];
    t[r] = v[r * 4 + 3];
  }
  constexpr double kOrthonormalTolerance = 1e-4;
  if (!R.allFinite() || !t.allFinite() ||
      (R * R.transpose() - Eigen::Matrix3d::Identity()).norm() > kOrthonormalTolerance ||
      R.determinant() < 0)
    return Expected<Eigen::Isometry3d>::failure(
        "the rotation part of the matrix is not a rotation");
  // Re-orthonormalise so round-tripped text keeps an exact rotation.
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(R, Eigen::ComputeFullU | Eigen::ComputeFullV);
  return makeTransform(Eigen::Matrix3d(svd.matrixU() * svd.matrixV().transpose()), t);
}

double rotationErrorDeg(const Eigen::Isometry3d& a, const Eigen::Isometry3d& b) {
  const Eigen::AngleAxisd aa(Eigen::Matrix3d(a.rotation().transpose() * b.rotation()));
  return std::abs(aa.angle()) * kDegPerRad;
}

double angleBetweenDeg(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return std::acos(std::clamp(a.normalized().dot(b.normalized()), -1.0, 1.0)) * kDegPerRad;
}

double translationErrorM(const Eigen::Isometry3d& a, const Eigen::Isometry3d& b) {
  return (a.translation() - b.translation()).norm();
}

Eigen::Vector3d rollPitchYaw(const Eigen::Matrix3d& R) {
  const double pitch = std::asin(std::clamp(-R(2, 0), -1.0, 1.0));
  const double roll = std::atan2(R(2, 1), R(2, 2));
  const double yaw = std::atan2(R(1, 0), R(0, 0));
  return {roll, pitch, yaw};
}

Eigen::Matrix3d fromRollPitchYaw(const Eigen::Vector3d& rpy) {
  return (Eigen::AngleAxisd(rpy[2], Eigen::Vector3d::UnitZ()) *
          Eigen::AngleAxisd(rpy[1], Eigen::Vector3d::UnitY()) *
          Eigen::AngleAxisd(rpy[0], Eigen::Vector3d::UnitX()))
      .toRotationMatrix();
}

Eigen::Matrix3d expSO3(const Eigen::Vector3d& w) {
  const double angle = w.norm();
  if (angle < 1e-12) return Eigen::Matrix3d::Identity();
  return Eigen::AngleAxisd(angle, w / angle).toRotationMatrix();
}

Eigen::Vector3d logSO3(const Eigen::Matrix3d& R) {
  const Eigen::AngleAxisd aa(R);
  return aa.axis() * aa.angle();
}

Eigen::Isometry3d perturb(const Eigen::Isometry3d& T, double sigma_rot, double sigma_trans,
                          std::mt19937& rng) {
  std::normal_distribution<double> nr(0.0, sigma_rot), nt(0.0, sigma_trans);
  const Eigen::Vector3d w(nr(rng), nr(rng), nr(rng));
  const Eigen::Vector3d dt(nt(rng), nt(rng), nt(rng));
  Eigen::Isometry3d delta = makeTransform(expSO3(w), dt);
  return delta * T;
}

Expected<Eigen::Matrix3d> rotationAligning(const std::vector<Eigen::Vector3d>& from,
                                           const std::vector<Eigen::Vector3d>& to,
                                           const std::vector<double>& weights,
                                           double min_relative_second) {
  if (to.size() != from.size() || (!weights.empty() && weights.size() != from.size()))
    return Expected<Eigen::Matrix3d>::failure("rotationAligning: sizes differ");
  Eigen::Matrix3d H = Eigen::Matrix3d::Zero();
  for (size_t i = 0; i < from.size(); ++i)
    H += (weights.empty() ? 1.0 : weights[i]) * from[i] * to[i].transpose();
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(H, Eigen::ComputeFullU | Eigen::ComputeFullV);
  const Eigen::Vector3d sv = svd.singularValues();
  if (!(sv(0) > 0.0) || !(sv(1) > min_relative_second * sv(0)))
    return Expected<Eigen::Matrix3d>::failure("the directions do not fix a rotation");
  Eigen::Matrix3d D = Eigen::Matrix3d::Identity();
  D(2, 2) = (svd.matrixV() * svd.matrixU().transpose()).determinant() < 0 ? -1.0 : 1.0;
  return Eigen::Matrix3d(svd.matrixV() * D * svd.matrixU().transpose());
}

}  // namespace board_calib
