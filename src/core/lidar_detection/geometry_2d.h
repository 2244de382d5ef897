// Small 2D / 3D geometry helpers of the LiDAR detector (private to the module).
#pragma once

#include <board_calib/core/types.h>

#include <Eigen/Eigenvalues>

#include <random>
#include <vector>

namespace board_calib {
namespace lidar_detail {

/// Running sums for a least-squares plane (additive: regions merge by adding).
struct PlaneStats {
  int n = 0;
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  Eigen::Matrix3d scatter = Eigen::Matrix3d::Zero();  ///< sum of p p^T

  void add(const Eigen::Vector3d& p) {
    ++n;
    sum += p;
    scatter.noalias() += p * p.transpose();
  }
  void add(const PlaneStats& o) {
    n += o.n;
    sum += o.sum;
    scatter += o.scatter;
  }
  Eigen::Vector3d mean() const {
    return n > 0 ? Eigen::Vector3d(sum / n) : Eigen::Vector3d::Zero();
  }
  Eigen::Matrix3d covariance() const {
    if (n == 0) return Eigen::Matrix3d::Zero();
    const Eigen::Vector3d c = mean();
    return scatter / n - c * c.transpose();
  }
};

/// Eigen decomposition of a covariance: eigenvalues ascending, normal = smallest eigenvector.
struct PlaneFit {
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  Eigen::Vector3d eigenvalues = Eigen::Vector3d::Zero();  ///< ascending, m^2
  Eigen::Matrix3d axes = Eigen::Matrix3d::Identity();     ///< columns: eigenvectors, ascending
  Eigen::Vector3d normal() const { return axes.col(0); }
  double offset() const { return normal().dot(centroid); }
};

inline PlaneFit fitPlane(const PlaneStats& s) {
  PlaneFit f;
  f.centroid = s.mean();
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es;
  es.computeDirect(s.covariance());
  f.eigenvalues = es.eigenvalues().cwiseMax(0.0);
  f.axes = es.eigenvectors();
  return f;
}

/// Convex hull (counter-clockwise, no collinear points); fewer than 3 input points give them back.
Points2 convexHull(Points2 points);
double polygonArea(const Points2& polygon);

/// Minimum-area enclosing rectangle of a convex polygon: sides (larger first), m.
Eigen::Vector2d minAreaRectangle(const Points2& hull);

/// A 2D line fitted robustly (RANSAC on pairs, then least squares on the inliers).
struct LineFit2D {
  bool ok = false;
  Eigen::Vector2d point = Eigen::Vector2d::Zero();
  Eigen::Vector2d direction = Eigen::Vector2d::UnitX();  ///< unit
  std::vector<bool> inlier;
  int num_inliers = 0;
  double rms = 0.0;  ///< RMS distance of the inliers, m
  double distance(const Eigen::Vector2d& p) const {
    const Eigen::Vector2d d = p - point;
    return std::abs(d.x() * direction.y() - d.y() * direction.x());
  }
};
LineFit2D fitLineRobust(const Points2& points, double inlier_threshold, int iterations,
                        std::mt19937& rng);

/// Intersection of two 2D lines; false when (nearly) parallel.
bool intersectLines(const LineFit2D& a, const LineFit2D& b, Eigen::Vector2d* out);

}  // namespace lidar_detail
}  // namespace board_calib
