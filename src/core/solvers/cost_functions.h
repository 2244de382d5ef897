// Private Ceres cost functors of the solvers. The pose is an Eigen quaternion (x, y, z, w;
// EigenQuaternionManifold) q and a translation t with p_target = q * p_source + t.
#pragma once

#include <ceres/ceres.h>

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace board_calib {
namespace solvers_detail {

// The point-to-plane terms of a whole cluster (one view's board points against its camera
// plane, or one edge's points against its back-projected plane) in closed form. With weights
// w_m, W = sum w_m, mean mu and scatter S = sum w_m (P_m - mu)(P_m - mu)^T = sum_k a_k a_k^T
// (a_k = sqrt(lambda_k) v_k), the cluster's cost is exactly
//   sum_m w_m (n . (R P_m + t) - s d)^2 = W (n . (R mu + t) - s d)^2 + sum_k (n . R a_k)^2,
// so four residuals replace hundreds (PPC: n_i, d_i the camera plane; PBPC: n = K^T l / |K^T l|
// and d = 0, the plane through the camera centre and the image line, so r is in metres): r_0 =
// sqrt(W) (n . (q * mu + t) - s d), r_k = n . (q * a_k).
class ClusterPlaneCost {
 public:
  ClusterPlaneCost(const Eigen::Vector3d& normal, double offset, double sqrt_weight,
                   const Eigen::Vector3d& mean, const Eigen::Matrix3d& axes)
      : normal_(normal), offset_(offset), sqrt_weight_(sqrt_weight), mean_(mean), axes_(axes) {}

  template <typename T>
  bool operator()(const T* const q_ptr, const T* const t_ptr, T* residual) const {
    return evaluate(q_ptr, t_ptr, T(1.0), residual);
  }

  template <typename T>
  bool evaluate(const T* const q_ptr, const T* const t_ptr, const T& scale, T* residual) const {
    const Eigen::Map<const Eigen::Quaternion<T>> q(q_ptr);
    const Eigen::Map<const Eigen::Matrix<T, 3, 1>> t(t_ptr);
    const Eigen::Matrix<T, 3, 1> n = normal_.cast<T>();
    residual[0] = T(sqrt_weight_) * (n.dot(q * mean_.cast<T>() + t) - scale * T(offset_));
    for (int k = 0; k < 3; ++k) residual[k + 1] = n.dot(q * axes_.col(k).cast<T>().eval());
    return true;
  }

  static ceres::CostFunction* Create(const Eigen::Vector3d& normal, double offset,
                                     double sqrt_weight, const Eigen::Vector3d& mean,
                                     const Eigen::Matrix3d& axes) {
    return new ceres::AutoDiffCostFunction<ClusterPlaneCost, 4, 4, 3>(
        new ClusterPlaneCost(normal, offset, sqrt_weight, mean, axes));
  }

 private:
  const Eigen::Vector3d normal_;
  const double offset_;
  const double sqrt_weight_;
  const Eigen::Vector3d mean_;
  const Eigen::Matrix3d axes_;
};

// The same with the offset factor s as a third parameter block.
class ScaledClusterPlaneCost {
 public:
  explicit ScaledClusterPlaneCost(const ClusterPlaneCost& inner) : inner_(inner) {}

  template <typename T>
  bool operator()(const T* const q_ptr, const T* const t_ptr, const T* const scale,
                  T* residual) const {
    return inner_.evaluate(q_ptr, t_ptr, scale[0], residual);
  }

  static ceres::CostFunction* Create(const Eigen::Vector3d& normal, double offset,
                                     double sqrt_weight, const Eigen::Vector3d& mean,
                                     const Eigen::Matrix3d& axes) {
    return new ceres::AutoDiffCostFunction<ScaledClusterPlaneCost, 4, 4, 3, 1>(
        new ScaledClusterPlaneCost(ClusterPlaneCost(normal, offset, sqrt_weight, mean, axes)));
  }

 private:
  const ClusterPlaneCost inner_;
};

// MSG pairwise normal alignment: the plane normal seen by b, rotated into a, must equal the
// normal seen by a:
//   r = w (n_a - q * n_b)            [dimensionless, whitened to metres by w]
class NormalAlignmentCost {
 public:
  NormalAlignmentCost(const Eigen::Vector3d& normal_a, const Eigen::Vector3d& normal_b,
                      double weight)
      : normal_a_(normal_a), normal_b_(normal_b), weight_(weight) {}

  template <typename T>
  bool operator()(const T* const q_ptr, T* residual) const {
    const Eigen::Map<const Eigen::Quaternion<T>> q(q_ptr);
    const Eigen::Matrix<T, 3, 1> r = T(weight_) * (normal_a_.cast<T>() - q * normal_b_.cast<T>());
    residual[0] = r[0];
    residual[1] = r[1];
    residual[2] = r[2];
    return true;
  }

  static ceres::CostFunction* Create(const Eigen::Vector3d& normal_a,
                                     const Eigen::Vector3d& normal_b, double weight) {
    return new ceres::AutoDiffCostFunction<NormalAlignmentCost, 3, 4>(
        new NormalAlignmentCost(normal_a, normal_b, weight));
  }

 private:
  const Eigen::Vector3d normal_a_;
  const Eigen::Vector3d normal_b_;
  const double weight_;
};

// MSG pairwise plane distance, measured at the boards. c_a and c_b are points of the board in
// each sensor's frame where that sensor's plane is best determined (camera: the centre of the
// PnP data; LiDAR: the centroid of the board points), each on its own plane. The gap between
// plane a and plane b mapped into a, {(q n_b) . x = d_b + (q n_b) . t}, is taken at their
// midpoint p = (c_a + q c_b + t) / 2:
//   r = w ((n_a . p - d_a) - ((q n_b) . (p - t) - d_b))      [m, w = 1 unless whitened per view]
// = m . t + d_b - d_a + (n_a - q n_b) . (c_a + q c_b) / 2,   m = (n_a + q n_b) / 2.
// At the origin (c_a = c_b = 0) it is the offset difference m . t + d_b - d_a, whose error is
// each plane's normal error times the board distance; at the boards it is the two planes'
// offset errors there, independent of the normal errors that the normal term already carries.
class PlaneGapCost {
 public:
  PlaneGapCost(const Eigen::Vector3d& normal_a, double offset_a, const Eigen::Vector3d& point_a,
               const Eigen::Vector3d& normal_b, double offset_b, const Eigen::Vector3d& point_b,
               double weight)
      : normal_a_(normal_a),
        point_a_(point_a),
        normal_b_(normal_b),
        point_b_(point_b),
        offset_a_(offset_a),
        offset_b_(offset_b),
        weight_(weight) {}

  template <typename T>
  bool operator()(const T* const q_ptr, const T* const t_ptr, T* residual) const {
    residual[0] = gap(q_ptr, t_ptr, T(1.0));
    return true;
  }

  // The a-side (camera) plane offset and board point multiplied by a free scale: a camera whose
  // board geometry comes from a declared board size (or a focal length) that is off sees every
  // board at a common factor of its true distance.
  template <typename T>
  bool operator()(const T* const q_ptr, const T* const t_ptr, const T* const s_ptr,
                  T* residual) const {
    residual[0] = gap(q_ptr, t_ptr, s_ptr[0]);
    return true;
  }

  static ceres::CostFunction* Create(const Eigen::Vector3d& normal_a, double offset_a,
                                     const Eigen::Vector3d& point_a,
                                     const Eigen::Vector3d& normal_b, double offset_b,
                                     const Eigen::Vector3d& point_b, double weight = 1.0) {
    return new ceres::AutoDiffCostFunction<PlaneGapCost, 1, 4, 3>(
        new PlaneGapCost(normal_a, offset_a, point_a, normal_b, offset_b, point_b, weight));
  }

  // Blocks q, t and the camera-side scale.
  static ceres::CostFunction* CreateScaled(const Eigen::Vector3d& normal_a, double offset_a,
                                           const Eigen::Vector3d& point_a,
                                           const Eigen::Vector3d& normal_b, double offset_b,
                                           const Eigen::Vector3d& point_b, double weight = 1.0) {
    return new ceres::AutoDiffCostFunction<PlaneGapCost, 1, 4, 3, 1>(
        new PlaneGapCost(normal_a, offset_a, point_a, normal_b, offset_b, point_b, weight));
  }

 private:
  template <typename T>
  T gap(const T* const q_ptr, const T* const t_ptr, const T& s) const {
    const Eigen::Map<const Eigen::Quaternion<T>> q(q_ptr);
    const Eigen::Map<const Eigen::Matrix<T, 3, 1>> t(t_ptr);
    const Eigen::Matrix<T, 3, 1> na = normal_a_.cast<T>();
    const Eigen::Matrix<T, 3, 1> nb = q * normal_b_.cast<T>();
    const Eigen::Matrix<T, 3, 1> p = (point_a_.cast<T>() * s + q * point_b_.cast<T>() + t) * T(0.5);
    return T(weight_) * ((na.dot(p) - T(offset_a_) * s) - (nb.dot(p - t) - T(offset_b_)));
  }

  const Eigen::Vector3d normal_a_, point_a_, normal_b_, point_b_;
  const double offset_a_, offset_b_;
  const double weight_;
};

}  // namespace solvers_detail
}  // namespace board_calib
