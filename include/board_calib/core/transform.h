// Rigid-transform helpers. Naming: T_a_b maps points from frame b into frame a
// (p_a = T_a_b * p_b).
#pragma once

#include <board_calib/core/types.h>

#include <random>

namespace board_calib {

/// From translation (m) and quaternion (x, y, z, w); the quaternion is normalised.
Eigen::Isometry3d makeTransform(const Eigen::Vector3d& translation,
                                const Eigen::Vector4d& quat_xyzw);
Eigen::Isometry3d makeTransform(const Eigen::Matrix3d& rotation,
                                const Eigen::Vector3d& translation);
/// Quaternion as (x, y, z, w) with w >= 0.
Eigen::Vector4d quaternionXyzw(const Eigen::Isometry3d& transform);
/// The 4x4 matrix row-major (16 numbers).
std::array<double, 16> rowMajor(const Eigen::Isometry3d& transform);
/// From 12 or 16 row-major numbers (3x4 or 4x4); fails if the rotation is not orthonormal.
Expected<Eigen::Isometry3d> fromRowMajor(const std::vector<double>& values);

/// Angle of the relative rotation between two transforms, degrees.
double rotationErrorDeg(const Eigen::Isometry3d& a, const Eigen::Isometry3d& b);
/// Angle between two directions (need not be unit), degrees.
double angleBetweenDeg(const Eigen::Vector3d& a, const Eigen::Vector3d& b);
/// Norm of the translation difference, m.
double translationErrorM(const Eigen::Isometry3d& a, const Eigen::Isometry3d& b);
/// Roll, pitch, yaw (rad) of a rotation about fixed x, y, z axes (R = Rz(yaw) Ry(pitch) Rx(roll)).
Eigen::Vector3d rollPitchYaw(const Eigen::Matrix3d& rotation);
Eigen::Matrix3d fromRollPitchYaw(const Eigen::Vector3d& rpy);
/// Rotation vector (axis * angle, rad) <-> rotation matrix.
Eigen::Matrix3d expSO3(const Eigen::Vector3d& rotation_vector);
Eigen::Vector3d logSO3(const Eigen::Matrix3d& rotation);

/// The rotation R minimising sum_i w_i |to_i - R from_i|^2 (Kabsch; never a reflection); all
/// weights 1 when `weights` is empty. Fails when the pairs do not fix a rotation: the second
/// singular value of sum_i w_i from_i to_i^T is at most `min_relative_second` of the first (one
/// direction only, or nothing); a negative `min_relative_second` fails only on nothing.
Expected<Eigen::Matrix3d> rotationAligning(const std::vector<Eigen::Vector3d>& from,
                                           const std::vector<Eigen::Vector3d>& to,
                                           const std::vector<double>& weights,
                                           double min_relative_second);

/// A perturbation drawn as a rotation vector ~ N(0, sigma_rot_rad) per axis and a
/// translation ~ N(0, sigma_trans_m) per axis, applied as T_perturbed = delta * T.
Eigen::Isometry3d perturb(const Eigen::Isometry3d& transform, double sigma_rot_rad,
                          double sigma_trans_m, std::mt19937& rng);

constexpr double kDegPerRad = 57.29577951308232;
constexpr double kRadPerDeg = 1.0 / kDegPerRad;

}  // namespace board_calib
