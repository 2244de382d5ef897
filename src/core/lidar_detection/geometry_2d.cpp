#include "geometry_2d.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace board_calib {
namespace lidar_detail {
namespace {

double cross(const Eigen::Vector2d& o, const Eigen::Vector2d& a, const Eigen::Vector2d& b) {
  return (a.x() - o.x()) * (b.y() - o.y()) - (a.y() - o.y()) * (b.x() - o.x());
}

// Total least squares line through the flagged points.
bool leastSquaresLine(const Points2& points, const std::vector<bool>& use, Eigen::Vector2d* point,
                      Eigen::Vector2d* direction) {
  Eigen::Vector2d mean = Eigen::Vector2d::Zero();
  int n = 0;
  for (size_t i = 0; i < points.size(); ++i)
    if (use[i]) {
      mean += points[i];
      ++n;
    }
  if (n < 2) return false;
  mean /= n;
  Eigen::Matrix2d cov = Eigen::Matrix2d::Zero();
  for (size_t i = 0; i < points.size(); ++i)
    if (use[i]) {
      const Eigen::Vector2d d = points[i] - mean;
      cov += d * d.transpose();
    }
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> es(cov);
  *point = mean;
  *direction = es.eigenvectors().col(1).normalized();
  return true;
}

}  // namespace

Points2 convexHull(Points2 points) {
  if (points.size() < 3) return points;
  std::sort(points.begin(), points.end(), [](const Eigen::Vector2d& a, const Eigen::Vector2d& b) {
    return a.x() < b.x() || (a.x() == b.x() && a.y() < b.y());
  });
  Points2 hull(2 * points.size());
  size_t k = 0;
  for (size_t i = 0; i < points.size(); ++i) {
    while (k >= 2 && cross(hull[k - 2], hull[k - 1], points[i]) <= 0) --k;
    hull[k++] = points[i];
  }
  for (size_t i = points.size() - 1, t = k + 1; i > 0; --i) {
    while (k >= t && cross(hull[k - 2], hull[k - 1], points[i - 1]) <= 0) --k;
    hull[k++] = points[i - 1];
  }
  hull.resize(k - 1);
  return hull;
}

double polygonArea(const Points2& polygon) {
  double area = 0.0;
  for (size_t i = 0; i < polygon.size(); ++i) {
    const auto& a = polygon[i];
    const auto& b = polygon[(i + 1) % polygon.size()];
    area += a.x() * b.y() - a.y() * b.x();
  }
  return std::abs(area) / 2.0;
}

Eigen::Vector2d minAreaRectangle(const Points2& hull) {
  if (hull.size() < 3) return Eigen::Vector2d::Zero();
  double best_area = std::numeric_limits<double>::infinity();
  Eigen::Vector2d best = Eigen::Vector2d::Zero();
  // The optimal rectangle has a side collinear with a hull edge.
  for (size_t i = 0; i < hull.size(); ++i) {
    Eigen::Vector2d e = hull[(i + 1) % hull.size()] - hull[i];
    if (e.norm() < 1e-12) continue;
    e.normalize();
    const Eigen::Vector2d f(-e.y(), e.x());
    double min_e = std::numeric_limits<double>::infinity(), max_e = -min_e, min_f = min_e,
           max_f = -min_e;
    for (const auto& p : hull) {
      min_e = std::min(min_e, p.dot(e));
      max_e = std::max(max_e, p.dot(e));
      min_f = std::min(min_f, p.dot(f));
      max_f = std::max(max_f, p.dot(f));
    }
    const double area = (max_e - min_e) * (max_f - min_f);
    if (area < best_area) {
      best_area = area;
      best = {std::max(max_e - min_e, max_f - min_f), std::min(max_e - min_e, max_f - min_f)};
    }
  }
  return best;
}

LineFit2D fitLineRobust(const Points2& points, double inlier_threshold, int iterations,
                        std::mt19937& rng) {
  LineFit2D fit;
  const int n = static_cast<int>(points.size());
  if (n < 2) return fit;
  std::vector<bool> best_inliers(n, true);
  if (n > 2) {
    int best_count = -1;
    double best_cost = std::numeric_limits<double>::infinity();
    std::uniform_int_distribution<int> pick(0, n - 1);
    // Few points: try every pair; many: random pairs.
    const bool exhaustive = n * (n - 1) / 2 <= iterations;
    const int trials = exhaustive ? n * (n - 1) / 2 : iterations;
    int ea = 0, eb = 1;
    std::vector<bool> inliers(n);
    for (int t = 0; t < trials; ++t) {
      int a, b;
      if (exhaustive) {
        a = ea;
        b = eb;
        if (++eb == n) {
          ++ea;
          eb = ea + 1;
        }
      } else {
        a = pick(rng);
        b = pick(rng);
        if (a == b) continue;
      }
      Eigen::Vector2d d = points[b] - points[a];
      if (d.norm() < 1e-9) continue;
      d.normalize();
      int count = 0;
      double cost = 0.0;
      for (int i = 0; i < n; ++i) {
        const Eigen::Vector2d r = points[i] - points[a];
        const double dist = std::abs(r.x() * d.y() - r.y() * d.x());
        inliers[i] = dist < inlier_threshold;
        if (inliers[i]) {
          ++count;
          cost += dist * dist;
        }
      }
      // Most inliers; ties broken by the smaller squared residual.
      if (count > best_count || (count == best_count && cost < best_cost)) {
        best_count = count;
        best_cost = cost;
        best_inliers = inliers;
      }
    }
  }
  if (!leastSquaresLine(points, best_inliers, &fit.point, &fit.direction)) return fit;
  // One re-selection of inliers around the least-squares line, then the final fit.
  std::vector<bool> refined(n);
  int count = 0;
  for (int i = 0; i < n; ++i) {
    refined[i] = fit.distance(points[i]) < inlier_threshold;
    count += refined[i];
  }
  if (count >= 2 && leastSquaresLine(points, refined, &fit.point, &fit.direction))
    best_inliers = refined;
  fit.inlier = best_inliers;
  fit.num_inliers = 0;
  double sum_sq = 0.0;
  for (int i = 0; i < n; ++i)
    if (fit.inlier[i]) {
      ++fit.num_inliers;
      sum_sq += std::pow(fit.distance(points[i]), 2);
    }
  fit.rms = fit.num_inliers > 0 ? std::sqrt(sum_sq / fit.num_inliers) : 0.0;
  fit.ok = fit.num_inliers >= 2;
  return fit;
}

bool intersectLines(const LineFit2D& a, const LineFit2D& b, Eigen::Vector2d* out) {
  // a.point + s a.dir = b.point + t b.dir
  Eigen::Matrix2d m;
  m.col(0) = a.direction;
  m.col(1) = -b.direction;
  const double det = m.determinant();
  if (std::abs(det) < 1e-6) return false;
  const Eigen::Vector2d st = m.inverse() * (b.point - a.point);
  *out = a.point + st.x() * a.direction;
  return true;
}

}  // namespace lidar_detail
}  // namespace board_calib
