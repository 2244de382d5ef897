// Comparing what a session saw before with this image's quadrilaterals and lines (the static
// scene of ImageBoardTracker, the expected board of a second chance).
#include "detection_internal.h"

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

namespace board_calib {
namespace image_detection {

double meanSidePx(const std::array<Eigen::Vector2d, kNumEdges>& corners) {
  double perimeter = 0;
  for (int k = 0; k < kNumEdges; ++k) perimeter += (corners[(k + 1) % 4] - corners[k]).norm();
  return perimeter / kNumEdges;
}

double worstCornerOffset(const std::array<Eigen::Vector2d, kNumEdges>& corners,
                         const std::array<Eigen::Vector2d, kNumEdges>& reference) {
  double worst = 0;
  for (const auto& c : corners) {
    double nearest = std::numeric_limits<double>::infinity();
    for (const auto& e : reference) nearest = std::min(nearest, (c - e).norm());
    worst = std::max(worst, nearest);
  }
  return worst;
}

double shareInside(const std::array<Eigen::Vector2d, kNumEdges>& inner,
                   const std::array<Eigen::Vector2d, kNumEdges>& outer) {
  std::vector<cv::Point2f> a, b, overlap;
  for (int k = 0; k < kNumEdges; ++k) {
    a.emplace_back(static_cast<float>(inner[k].x()), static_cast<float>(inner[k].y()));
    b.emplace_back(static_cast<float>(outer[k].x()), static_cast<float>(outer[k].y()));
    // As floats: a corner beyond float range would be infinite for OpenCV.
    if (!std::isfinite(a[k].x) || !std::isfinite(a[k].y) || !std::isfinite(b[k].x) ||
        !std::isfinite(b[k].y))
      return 0.0;
  }
  const double area = std::abs(cv::contourArea(a));
  if (!(area > 0) || !cv::isContourConvex(a) || !cv::isContourConvex(b)) return 0.0;
  return cv::intersectConvexConvex(a, b, overlap, true) / area;
}

double expectedOffset(const std::array<Eigen::Vector2d, kNumEdges>& corners,
                      const ExpectedBoard& expected) {
  if (!expected.inside) return worstCornerOffset(corners, expected.corners_px);
  // Outside the quadrilateral: the largest distance beyond any of its sides (0 inside). The
  // corners are in the image's cyclic order either way round.
  const auto& q = expected.corners_px;
  Eigen::Vector2d centre = Eigen::Vector2d::Zero();
  for (const auto& c : q) centre += 0.25 * c;
  double worst = 0;
  for (const auto& c : corners)
    for (size_t k = 0; k < q.size(); ++k) {
      const Eigen::Vector2d d = q[(k + 1) % q.size()] - q[k];
      Eigen::Vector2d n(d.y(), -d.x());
      if (!(n.norm() > 0)) continue;
      n.normalize();
      if (n.dot(centre - q[k]) > 0) n = -n;  // outward
      worst = std::max(worst, n.dot(c - q[k]));
    }
  return worst;
}

bool sameLine(const std::array<Eigen::Vector2d, 2>& x, const std::array<Eigen::Vector2d, 2>& y,
              double tolerance_px) {
  const bool x_longer = (x[1] - x[0]).squaredNorm() >= (y[1] - y[0]).squaredNorm();
  const auto& longer = x_longer ? x : y;
  const auto& shorter = x_longer ? y : x;
  const double length = (longer[1] - longer[0]).norm();
  if (!(length > 0)) return false;
  const Eigen::Vector2d dir = (longer[1] - longer[0]) / length;
  double t_lo = 1e18, t_hi = -1e18;
  for (const Eigen::Vector2d& p : shorter) {
    if (std::abs(dir.x() * (p - longer[0]).y() - dir.y() * (p - longer[0]).x()) > tolerance_px)
      return false;
    const double t = dir.dot(p - longer[0]);
    t_lo = std::min(t_lo, t);
    t_hi = std::max(t_hi, t);
  }
  return t_hi >= 0 && t_lo <= length;
}

}  // namespace image_detection
}  // namespace board_calib
