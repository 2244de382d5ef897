// Line segments by region growing on the level-line field: the LSD algorithm (Grompone von Gioi
// et al., IPOL 2012) as OpenCV runs it with LSD_REFINE_NONE (no refinement, no NFA test), written
// for speed: a counting sort of the seeds (OpenCV sorts every pixel, defined or not), unit
// vectors instead of angles (no atan2, cos and sin per region pixel) and single-precision fields.
// On the rs16_plain frames at 640 px it returns ~98 % of OpenCV's segments to 0.01 px (the rest
// differ where seeds of equal gradient bin are taken in another order) in a fifth of the time
// (docs/BENCHMARKS.md, session 7).
#include "line_internal.h"

#include <algorithm>
#include <cmath>

namespace board_calib {
namespace image_detection {
namespace {

constexpr double kAngleToleranceRad = CV_PI * 22.5 / 180.0;  // LSD's tau: region pixels agree
constexpr int kGradientBins = 1024;          // LSD's pseudo-ordering of the seeds by gradient
constexpr double kNumberOfTestsBase = 11.0;  // LSD: 11 widths per rectangle in its test count

// Per pixel of the 2x2 gradient (its centre at x + 0.5, y + 0.5): the level-line direction as a
// unit vector, the gradient norm, and whether it may still join a region.
struct LevelLines {
  int w = 0, h = 0;
  std::vector<float> ux, uy, norm;
  std::vector<unsigned char> free;  // gradient above the quantization noise, in no region yet
  float max_norm = 0;
  int defined = 0;
};

LevelLines levelLines(const cv::Mat& gray, double quantization) {
  LevelLines f;
  f.w = gray.cols;
  f.h = gray.rows;
  const size_t n = static_cast<size_t>(f.w) * f.h;
  f.ux.assign(n, 0.f);
  f.uy.assign(n, 0.f);
  f.norm.assign(n, 0.f);
  f.free.assign(n, 0);
  // A gradient below this is the quantization error's: its direction is undefined.
  const double min_norm = quantization / std::sin(kAngleToleranceRad);
  for (int y = 0; y + 1 < f.h; ++y) {
    const uchar* r0 = gray.ptr<uchar>(y);
    const uchar* r1 = gray.ptr<uchar>(y + 1);
    for (int x = 0; x + 1 < f.w; ++x) {
      const int da = r1[x + 1] - r0[x], bc = r0[x + 1] - r1[x];
      const int gx = da + bc, gy = da - bc;
      const double norm = 0.5 * std::sqrt(static_cast<double>(gx * gx + gy * gy));
      const size_t i = static_cast<size_t>(y) * f.w + x;
      f.norm[i] = static_cast<float>(norm);
      if (norm <= min_norm) continue;
      // The level line runs across the gradient: direction (-gy, gx).
      f.ux[i] = static_cast<float>(-0.5 * gy / norm);
      f.uy[i] = static_cast<float>(0.5 * gx / norm);
      f.free[i] = 1;
      ++f.defined;
      f.max_norm = std::max(f.max_norm, f.norm[i]);
    }
  }
  return f;
}

// The defined pixels, strongest gradient bin first (row-major inside a bin).
std::vector<int> seedOrder(const LevelLines& f) {
  const double bin_per_norm = f.max_norm > 0 ? (kGradientBins - 1) / f.max_norm : 0.0;
  std::vector<int> start(kGradientBins + 1, 0);
  auto bin = [&](size_t i) {
    return kGradientBins - 1 - static_cast<int>(f.norm[i] * bin_per_norm);
  };
  for (size_t i = 0; i < f.free.size(); ++i)
    if (f.free[i]) ++start[bin(i) + 1];
  for (int b = 0; b < kGradientBins; ++b) start[b + 1] += start[b];
  std::vector<int> order(f.defined);
  for (size_t i = 0; i < f.free.size(); ++i)
    if (f.free[i]) order[start[bin(i)]++] = static_cast<int>(i);
  return order;
}

// The 8-connected free pixels whose direction agrees with the region's (the normalized sum of
// its pixels' directions, updated as each joins) within the tolerance; they leave `free`.
// Returns the region's direction.
Eigen::Vector2d growRegion(int seed, LevelLines* f, std::vector<int>* region) {
  const float cos_tolerance = static_cast<float>(std::cos(kAngleToleranceRad));
  region->assign(1, seed);
  f->free[seed] = 0;
  double sx = f->ux[seed], sy = f->uy[seed];
  float rx = f->ux[seed], ry = f->uy[seed];
  for (size_t r = 0; r < region->size(); ++r) {
    const int px = (*region)[r] % f->w, py = (*region)[r] / f->w;
    const int x0 = std::max(px - 1, 0), x1 = std::min(px + 1, f->w - 1);
    const int y0 = std::max(py - 1, 0), y1 = std::min(py + 1, f->h - 1);
    for (int y = y0; y <= y1; ++y)
      for (int x = x0; x <= x1; ++x) {
        const int i = y * f->w + x;
        if (!f->free[i] || f->ux[i] * rx + f->uy[i] * ry < cos_tolerance) continue;
        f->free[i] = 0;
        region->push_back(i);
        sx += f->ux[i];
        sy += f->uy[i];
        const double s = std::hypot(sx, sy);
        rx = static_cast<float>(sx / s);
        ry = static_cast<float>(sy / s);
      }
  }
  return {rx, ry};
}

// The region's segment: through its gradient-weighted centroid along its axis of least inertia,
// between its extreme pixels (x1, y1, x2, y2 with pixel centres at integers, as OpenCV's LSD).
cv::Vec4f regionSegment(const LevelLines& f, const std::vector<int>& region,
                        const Eigen::Vector2d& direction) {
  double cx = 0, cy = 0, sum = 0;
  for (const int i : region) {
    cx += (i % f.w) * static_cast<double>(f.norm[i]);
    cy += (i / f.w) * static_cast<double>(f.norm[i]);
    sum += f.norm[i];
  }
  cx /= sum;
  cy /= sum;
  double ixx = 0, iyy = 0, ixy = 0;
  for (const int i : region) {
    const double dx = i % f.w - cx, dy = i / f.w - cy, m = f.norm[i];
    ixx += dy * dy * m;
    iyy += dx * dx * m;
    ixy -= dx * dy * m;
  }
  const double lambda = 0.5 * (ixx + iyy - std::sqrt((ixx - iyy) * (ixx - iyy) + 4.0 * ixy * ixy));
  const double theta =
      std::abs(ixx) > std::abs(iyy) ? std::atan2(lambda - ixx, ixy) : std::atan2(ixy, lambda - iyy);
  Eigen::Vector2d d(std::cos(theta), std::sin(theta));
  if (d.dot(direction) < 0) d = -d;  // along the level lines, as LSD orients its segments
  double lo = 0, hi = 0;
  for (const int i : region) {
    const double l = (i % f.w - cx) * d.x() + (i / f.w - cy) * d.y();
    lo = std::min(lo, l);
    hi = std::max(hi, l);
  }
  constexpr double kCentre = 0.5;  // the 2x2 gradient sits between the pixel centres
  return {
      static_cast<float>(cx + lo * d.x() + kCentre), static_cast<float>(cy + lo * d.y() + kCentre),
      static_cast<float>(cx + hi * d.x() + kCentre), static_cast<float>(cy + hi * d.y() + kCentre)};
}

}  // namespace

std::vector<cv::Vec4f> lineSegments(const cv::Mat& gray, double quantization) {
  std::vector<cv::Vec4f> out;
  if (gray.cols < 2 || gray.rows < 2 || gray.type() != CV_8UC1 || !(quantization > 0)) return out;
  LevelLines f = levelLines(gray, quantization);
  // LSD's smallest region that can be meaningful: -log10(number of tests) / log10(p), p the
  // chance that a pixel's direction agrees by accident.
  const double log_tests =
      5.0 * (std::log10(static_cast<double>(f.w)) + std::log10(static_cast<double>(f.h))) / 2.0 +
      std::log10(kNumberOfTestsBase);
  const size_t min_region =
      static_cast<size_t>(-log_tests / std::log10(kAngleToleranceRad / CV_PI));
  std::vector<int> region;
  for (const int seed : seedOrder(f)) {
    if (!f.free[seed]) continue;
    const Eigen::Vector2d direction = growRegion(seed, &f, &region);
    if (region.size() >= min_region) out.push_back(regionSegment(f, region, direction));
  }
  return out;
}

}  // namespace image_detection
}  // namespace board_calib
