// Private Ceres cost functors of the MSG graph. Every pose is an Eigen quaternion (x, y, z, w;
// EigenQuaternionManifold) q and a translation t with p_reference = q * p_sensor + t. Every
// residual is whitened (divided by its 1 sigma) so one robust loss scale applies to all.
#pragma once

#include <ceres/ceres.h>

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace board_calib {
namespace multi_sensor {
namespace detail {

template <typename T>
using Vec3 = Eigen::Matrix<T, 3, 1>;

// Plane to plane between sensors a and b for one board pose. Plane {n . x = d} of a sensor maps
// into the reference frame as {(R n) . x = d + (R n) . t}; both images must coincide. c_a, c_b
// are each sensor's board point (boardPoint: where its plane is best
// determined, on the plane), and the offsets are compared at their midpoint in the reference
// frame, p = (R_a c_a + t_a + R_b c_b + t_b) / 2:
//   r[0..2] = (R_a n_a - R_b n_b) / sigma_n
//   r[3]    = ((N_a . (p - t_a) - d_a) - (N_b . (p - t_b) - d_b)) / sigma_d,   N = R n
// (with c_a = c_b = 0 it is m . (t_b - t_a) + d_b - d_a, m = (N_a + N_b) / 2: the offsets
// compared at the origin, where each plane's normal error is multiplied by the board distance).
class PlanePairCost {
 public:
  PlanePairCost(const Eigen::Vector3d& n_a, double d_a, const Eigen::Vector3d& c_a,
                const Eigen::Vector3d& n_b, double d_b, const Eigen::Vector3d& c_b, double sigma_n,
                double sigma_d)
      : n_a_(n_a),
        n_b_(n_b),
        c_a_(c_a),
        c_b_(c_b),
        d_a_(d_a),
        d_b_(d_b),
        inv_sigma_n_(1.0 / sigma_n),
        inv_sigma_d_(1.0 / sigma_d) {}

  template <typename T>
  bool operator()(const T* const qa, const T* const ta, const T* const qb, const T* const tb,
                  T* r) const {
    const Eigen::Map<const Eigen::Quaternion<T>> q_a(qa), q_b(qb);
    const Eigen::Map<const Vec3<T>> t_a(ta), t_b(tb);
    const Vec3<T> na = q_a * n_a_.cast<T>();
    const Vec3<T> nb = q_b * n_b_.cast<T>();
    const Vec3<T> rn = (na - nb) * T(inv_sigma_n_);
    const Vec3<T> p = (q_a * c_a_.cast<T>() + t_a + q_b * c_b_.cast<T>() + t_b) * T(0.5);
    r[0] = rn[0];
    r[1] = rn[1];
    r[2] = rn[2];
    r[3] = ((na.dot(p - t_a) - T(d_a_)) - (nb.dot(p - t_b) - T(d_b_))) * T(inv_sigma_d_);
    return true;
  }

  static ceres::CostFunction* Create(const Eigen::Vector3d& n_a, double d_a,
                                     const Eigen::Vector3d& c_a, const Eigen::Vector3d& n_b,
                                     double d_b, const Eigen::Vector3d& c_b, double sigma_n,
                                     double sigma_d) {
    return new ceres::AutoDiffCostFunction<PlanePairCost, 4, 4, 3, 4, 3>(
        new PlanePairCost(n_a, d_a, c_a, n_b, d_b, c_b, sigma_n, sigma_d));
  }

 private:
  const Eigen::Vector3d n_a_, n_b_, c_a_, c_b_;
  const double d_a_, d_b_;
  const double inv_sigma_n_, inv_sigma_d_;
};

// A pattern corner X (board frame) seen by camera c at undistorted pixel u, through the free
// board pose b = (q_b, t_b) of that board pose (one 7-vector: quaternion x y z w, translation):
//   p_c = q_c^-1 * (q_b * X + t_b - t_c),   r = (pi_K(p_c) - u) / sigma_px
// Corners of several cameras sharing one board pose tie the cameras (a bundle adjustment).
class CornerCost {
 public:
  CornerCost(const Eigen::Vector3d& board_point, const Eigen::Vector2d& pixel,
             const Eigen::Matrix3d& K, double sigma_px, double min_depth_m)
      : X_(board_point),
        u_(pixel),
        fx_(K(0, 0)),
        fy_(K(1, 1)),
        cx_(K(0, 2)),
        cy_(K(1, 2)),
        skew_(K(0, 1)),
        inv_sigma_(1.0 / sigma_px),
        min_depth_(min_depth_m) {}

  template <typename T>
  bool operator()(const T* const qc, const T* const tc, const T* const board, T* r) const {
    const Eigen::Map<const Eigen::Quaternion<T>> q_c(qc), q_b(board);
    const Eigen::Map<const Vec3<T>> t_c(tc), t_b(board + 4);
    const Vec3<T> p = q_c.conjugate() * (q_b * X_.cast<T>() + t_b - t_c);
    if (p[2] < T(min_depth_)) return false;  // behind the camera: reject the step
    const T x = p[0] / p[2], y = p[1] / p[2];
    r[0] = (T(fx_) * x + T(skew_) * y + T(cx_) - T(u_.x())) * T(inv_sigma_);
    r[1] = (T(fy_) * y + T(cy_) - T(u_.y())) * T(inv_sigma_);
    return true;
  }

  static ceres::CostFunction* Create(const Eigen::Vector3d& board_point,
                                     const Eigen::Vector2d& pixel, const Eigen::Matrix3d& K,
                                     double sigma_px, double min_depth_m) {
    return new ceres::AutoDiffCostFunction<CornerCost, 2, 4, 3, 7>(
        new CornerCost(board_point, pixel, K, sigma_px, min_depth_m));
  }

 private:
  const Eigen::Vector3d X_;
  const Eigen::Vector2d u_;
  const double fx_, fy_, cx_, cy_, skew_;
  const double inv_sigma_;
  const double min_depth_;
};

// PBPC line term: a LiDAR edge point Q must lie on the plane through camera c's centre spanned
// by the matching image line l (unit normal N = K^T l / |K^T l|, camera frame):
//   r = N . (q_c^-1 * (q_l * Q + t_l - t_c)) * w       [w = 1 / (sigma sqrt(points on the edge))]
class LineCost {
 public:
  LineCost(const Eigen::Vector3d& lidar_point, const Eigen::Vector3d& plane_normal, double weight)
      : Q_(lidar_point), N_(plane_normal), w_(weight) {}

  template <typename T>
  bool operator()(const T* const qc, const T* const tc, const T* const ql, const T* const tl,
                  T* r) const {
    const Eigen::Map<const Eigen::Quaternion<T>> q_c(qc), q_l(ql);
    const Eigen::Map<const Vec3<T>> t_c(tc), t_l(tl);
    const Vec3<T> p = q_c.conjugate() * (q_l * Q_.cast<T>() + t_l - t_c);
    r[0] = N_.cast<T>().dot(p) * T(w_);
    return true;
  }

  static ceres::CostFunction* Create(const Eigen::Vector3d& lidar_point,
                                     const Eigen::Vector3d& plane_normal, double weight) {
    return new ceres::AutoDiffCostFunction<LineCost, 1, 4, 3, 4, 3>(
        new LineCost(lidar_point, plane_normal, weight));
  }

 private:
  const Eigen::Vector3d Q_, N_;
  const double w_;
};

}  // namespace detail
}  // namespace multi_sensor
}  // namespace board_calib
