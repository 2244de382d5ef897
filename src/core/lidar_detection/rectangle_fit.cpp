// The declared rectangle fitted to a sparse board's per-line extremes (scan_segments.h).
#include "scan_segments.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace board_calib {
namespace lidar_detail {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kAngleStepCoarse = kPi / 180.0;  // 1 deg, then refined
constexpr double kAngleStepFine = kPi / 1800.0;
constexpr int kAssignRounds = 4;  // side assignment and centre updates

}  // namespace

namespace {

// The declared rectangle at one angle: its data in the rotated frame (x along the width).
struct RectangleAtAngle {
  RectangleAtAngle(double angle, double width, double height)
      : c(std::cos(angle)), s(std::sin(angle)), half(width / 2, height / 2) {}
  Eigen::Vector2d rot(const Eigen::Vector2d& p) const {
    return Eigen::Vector2d(c * p.x() + s * p.y(), -s * p.x() + c * p.y());
  }
  double c, s;
  Eigen::Vector2d half;
};

// Moves the centre (within [c_lo, c_hi]) so the extremes, moved out by their insets, lie on
// the sides that own them; returns the sum of squared boundary residuals.
double fitCentre(const RectangleAtAngle& r, const Points2& extremes,
                 const std::vector<double>& insets, const Eigen::Vector2d& c_lo,
                 const Eigen::Vector2d& c_hi, Eigen::Vector2d* centre) {
  const Eigen::Vector2d& half = r.half;
  // Inset of an extreme perpendicular to a side: its inset along u times |u . side normal|.
  const double inset_x = std::abs(r.c), inset_y = std::abs(r.s);
  double cost = 0.0;
  for (int round = 0; round < kAssignRounds; ++round) {
    Eigen::Vector2d sum = Eigen::Vector2d::Zero();
    Eigen::Vector2i n = Eigen::Vector2i::Zero();
    cost = 0.0;
    for (size_t k = 0; k < extremes.size(); ++k) {
      const Eigen::Vector2d q = r.rot(extremes[k]);
      const double b = k < insets.size() ? insets[k] : 0.0;
      const Eigen::Vector2d& m = *centre;
      // Distances to the four sides (positive inside); the nearest side owns the extreme.
      const double d[4] = {m.x() + half.x() - q.x(), q.x() - (m.x() - half.x()),
                           m.y() + half.y() - q.y(), q.y() - (m.y() - half.y())};
      int side = 0;
      for (int j = 1; j < 4; ++j)
        if (std::abs(d[j]) < std::abs(d[side])) side = j;
      const int axis = side / 2;
      const double inset = b * (axis == 0 ? inset_x : inset_y);
      const double residual = d[side] - inset;
      cost += residual * residual;
      // The centre coordinate that puts this extreme exactly at its inset.
      const double want = side == 0   ? q.x() + inset - half.x()
                          : side == 1 ? q.x() - inset + half.x()
                          : side == 2 ? q.y() + inset - half.y()
                                      : q.y() - inset + half.y();
      sum[axis] += want;
      ++n[axis];
    }
    for (int a = 0; a < 2; ++a)
      if (n[a] > 0) (*centre)[a] = std::clamp(sum[a] / n[a], c_lo[a], c_hi[a]);
  }
  return cost;
}

// Cost of the rectangle at `angle` (infinite when no centre keeps every board point inside);
// fills `fit` when given.
double evaluateRectangle(const Points2& board, const Points2& extremes,
                         const std::vector<double>& insets, double width, double height,
                         double inside_tol_m, double angle, RectangleFit* fit) {
  const RectangleAtAngle r(angle, width, height);
  Eigen::Vector2d lo = Eigen::Vector2d::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
  for (const auto& p : board) {
    const Eigen::Vector2d q = r.rot(p);
    lo = lo.cwiseMin(q);
    hi = hi.cwiseMax(q);
  }
  // Centres that keep every board point inside (within the tolerance).
  const Eigen::Vector2d c_lo = hi - r.half - Eigen::Vector2d::Constant(inside_tol_m);
  const Eigen::Vector2d c_hi = lo + r.half + Eigen::Vector2d::Constant(inside_tol_m);
  if ((c_lo.array() > c_hi.array()).any()) return std::numeric_limits<double>::infinity();
  Eigen::Vector2d centre = 0.5 * (c_lo + c_hi);
  const double cost = fitCentre(r, extremes, insets, c_lo, c_hi, &centre);
  if (!fit) return cost;
  fit->ok = true;
  fit->angle = angle;
  const Eigen::Matrix2d back = (Eigen::Matrix2d() << r.c, -r.s, r.s, r.c).finished();  // -> uv
  fit->centre = back * centre;
  fit->rms_m = extremes.empty() ? 0.0 : std::sqrt(cost / extremes.size());
  double worst = 0.0;
  for (const auto& p : board) {
    const Eigen::Vector2d q = r.rot(p) - centre;
    worst = std::max({worst, std::abs(q.x()) - r.half.x(), std::abs(q.y()) - r.half.y()});
  }
  fit->worst_outside_m = worst;
  const double sx[4] = {1, -1, -1, 1}, sy[4] = {1, 1, -1, -1};
  for (int j = 0; j < 4; ++j)
    fit->corners[j] = back * (centre + Eigen::Vector2d(sx[j] * r.half.x(), sy[j] * r.half.y()));
  return cost;
}

}  // namespace

RectangleFit fitRectangle(const Points2& board, const Points2& extremes,
                          const std::vector<double>& insets, double width, double height,
                          double inside_tol_m) {
  RectangleFit best;
  if (board.empty()) return best;
  auto cost = [&](double angle) {
    return evaluateRectangle(board, extremes, insets, width, height, inside_tol_m, angle, nullptr);
  };
  double best_cost = std::numeric_limits<double>::infinity();
  double best_angle = 0.0;
  // Coarse over half a turn (a rectangle repeats), then fine around the best.
  for (double a = 0.0; a < kPi; a += kAngleStepCoarse) {
    const double c = cost(a);
    if (c < best_cost) {
      best_cost = c;
      best_angle = a;
    }
  }
  if (!std::isfinite(best_cost)) return best;
  for (double a = best_angle - kAngleStepCoarse; a <= best_angle + kAngleStepCoarse;
       a += kAngleStepFine) {
    const double c = cost(a);
    if (c < best_cost) {
      best_cost = c;
      best_angle = a;
    }
  }
  evaluateRectangle(board, extremes, insets, width, height, inside_tol_m, best_angle, &best);
  return best;
}

}  // namespace lidar_detail
}  // namespace board_calib
