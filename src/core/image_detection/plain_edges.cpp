// Plain board, sub-pixel edges: the strongest gradient along the edge normal at samples along
// a side's current line, in raw pixels; the line is fitted to those peaks after undistortion (a
// straight edge is only straight there), robustly, in passes of narrowing search.
#include "plain_internal.h"

#include <board_calib/core/common/statistics.h>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/LU>

#include <algorithm>
#include <cmath>

namespace board_calib {
namespace image_detection {
namespace {

constexpr double kProfileStepPx = 0.5;  // spacing of intensity samples along the edge normal
constexpr double kWeakPeakFraction =
    0.3;  // a gradient peak below this fraction of the median is an outlier
constexpr double kMadToSigma = 1.4826;
constexpr int kFinePasses = 2;
constexpr int kRobustIterations = 3;
constexpr double kRobustSigmas = 3.0;  // inlier band of the refit, in robust sigmas
constexpr size_t kMinNoiseSteps = 5;   // neighbour differences that measure a side's noise
constexpr double kMaxCornerExclusionFraction = 0.15;  // of a side, skipped at each end
constexpr double kMaxSamplesPerSide =
    240;  // more add nothing to a line fit (errors ~1/sqrt(n) are already ~0.02 px)
constexpr double kPolarityWindowSteps =
    8;  // edge polarity is a majority over +-this many samples ...
// px: an edge peak whose one-pixel gradient is below the threshold still counts when the step
// across +-this much of it reaches the threshold (times one pixel). The Basler board's edges are
// blurred (sigma ~1.7 px): a 12-level faint board peaks at ~3 levels per px, below the 4 floor,
// and its step across +-1.5 px is ~8 levels. Measured on the augmented real frames: 197 -> 203 of
// 252 (low contrast 5 -> 11 of 21), worst edge 2.1 px, blanked frames none; at +-2 px a side
// 6.6 px off; the mono street's single frames take 2 other objects of 192 (0 without).
constexpr double kSoftEdgeHalfPx = 1.5;
constexpr double kPolarityWindowFraction =
    0.1;  // ... or this fraction of the side, whichever is longer
// A board's edge is straight; a held board bows a little (ImageBoardDetectorOptions::
// max_edge_bow_fraction, 1.5 %). Measured on the augmented real frames (6 draws, ~5000 edges of
// found boards): edges within 1 px of the reference bowed by at most 1.1 % of their span beyond
// 3 standard errors (0.4 % on near boards), while a printed disc's tangents bowed 11-13 % (raw
// sagitta over span), a far side running on along a same-colour leg 6-8 % and one a hand pulled
// 9.6 px off at its end 3 % (2.7 px over 88 px).
constexpr double kBowSigmas = 3.0;
// px: a scene line running on past a corner continues the side's fitted line this closely (the
// same straight edge: a window frame, a ceiling grid). A held board's bow does not enter (the
// line is fitted to the side itself), so the edge inlier band would only admit scene edges that
// merely point the same way (the floor line near a board side's extension refused a true
// board). Measured on the augmented real frames: at 1 px a scene rectangle of the wide-angle
// office passed (its lines bend that much under the lens model), at 1.5-2 px none, and 3 true
// boards came back (of 43 missed at 3 px).
constexpr double kRunOnTolerancePx = 2.0;
// Positions on each side of one whose profiles the second look at a side averages (refineOnce):
// +-6 px on a short side (2 px steps), up to +-11 px on a 900 px one. Measured on the augmented
// real frames, draws 14, 5, 6, 7 and 2-4: 228, 225, 219, 223 and 223, 223, 222 boards of 252
// (227, 223, 218, 224 and 221, 223, 220 before), none wrong, worst edge no larger. Accepting the
// averaged line without the first look's agreement took a far office board with a side along a
// leg on draw 5; preferring it over an agreeing valid first look left a side 36.8 px off at its
// end there; at +-6 positions a found side ran 3.7 px off.
constexpr int kAlongPositions = 3;

bool insideImage(const cv::Mat& gray, const Eigen::Vector2d& p, double margin) {
  return p.x() >= margin && p.y() >= margin && p.x() <= gray.cols - 1 - margin &&
         p.y() <= gray.rows - 1 - margin;
}

// Orients lines by the inside point and records them (RefinedSide).
struct Orienter {
  const Eigen::Vector2d& inside;
  std::vector<Eigen::Vector3d>* oriented;
  Eigen::Vector3d through(const Eigen::Vector2d& p, const Eigen::Vector2d& q) const {
    oriented->push_back(lineThrough(p, q, inside));
    return oriented->back();
  }
};

// Strictly on the inner side of every line: lineThrough orients each of them the same way with p
// (its sign test is this one's, negated when it flipped the line).
bool insideAll(const std::vector<Eigen::Vector3d>& lines, const Eigen::Vector2d& p) {
  for (const auto& l : lines)
    if (!(l.head<2>().dot(p) + l.z() < 0)) return false;
  return true;
}

// Total least squares line through points (undistorted px).
Eigen::Vector3d fitLine(const Points2& pts, const std::vector<bool>& use, const Orienter& orient) {
  Eigen::Vector2d mean = Eigen::Vector2d::Zero();
  int n = 0;
  for (size_t i = 0; i < pts.size(); ++i)
    if (use[i]) {
      mean += pts[i];
      ++n;
    }
  mean /= std::max(1, n);
  Eigen::Matrix2d cov = Eigen::Matrix2d::Zero();
  for (size_t i = 0; i < pts.size(); ++i)
    if (use[i]) cov += (pts[i] - mean) * (pts[i] - mean).transpose();
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig(cov);
  const Eigen::Vector2d dir = eig.eigenvectors().col(1);
  return orient.through(mean, mean + dir);
}

// Sign of the intensity change walking outward. It may change along one side (the background
// is brighter than the board behind one stretch and darker behind another), so it is a local
// majority: the first pass takes the strongest change of either sign, then each stretch of the
// side keeps the sign most of its samples showed (an opposite edge beside it is clutter).
struct LocalPolarity {
  std::vector<double> t;  // first-pass samples along the side (sorted) ...
  std::vector<int> sum;   // ... and the prefix sums of their signs
  double window = 0;
  int at(double s) const {
    if (t.empty()) return 0;
    const size_t lo = std::lower_bound(t.begin(), t.end(), s - window) - t.begin();
    const size_t hi = std::upper_bound(t.begin(), t.end(), s + window) - t.begin();
    const int total = sum[hi] - sum[lo];
    return total > 0 ? 1 : (total < 0 ? -1 : 0);
  }
};

// Gradient peaks of one pass along the side a + t dir (undistorted px).
struct EdgeSamples {
  Points2 pts_u, pts_raw;
  std::vector<double> strength;
  std::vector<int> signs;
  std::vector<double> ts;
  int positions = 0;  // sample positions whose narrow search lies inside the image
  double step = 0;
};

// Strongest gradient of the wanted polarity (0: either) in one intensity profile across the edge;
// false when none stands out of the noise. `offset` is in profile steps from the centre. `g` is
// scratch of the profile's size (reused along the side: no allocation per position).
bool profilePeak(const std::vector<double>& profile, double polarity, double min_gradient,
                 std::vector<double>& g, double* offset, double* strength, int* sign) {
  const int steps = static_cast<int>(profile.size() / 2);
  int best_k = 0;
  double best_g = 0;
  std::fill(g.begin(), g.end(), 0.0);
  for (int k = 1; k + 1 < static_cast<int>(profile.size()); ++k) {
    // Derivative across one full pixel (samples at +-0.5 px): robust to noise, unbiased.
    const double raw_g = (profile[k + 1] - profile[k - 1]) / (2 * kProfileStepPx);
    g[k] = polarity != 0.0 ? polarity * raw_g : std::abs(raw_g);
    if (g[k] > best_g) {
      best_g = g[k];
      best_k = k;
    }
  }
  if (best_k <= 1 || best_k + 2 >= static_cast<int>(profile.size())) return false;
  if (best_g < min_gradient) {
    // A soft edge spreads its step: judged by the step across the peak's neighbourhood against
    // what a crisp edge at the threshold changes across one pixel (the same noise: two samples).
    const int w = static_cast<int>(std::lround(kSoftEdgeHalfPx / kProfileStepPx));
    const int lo = std::max(0, best_k - w);
    const int hi = std::min(static_cast<int>(profile.size()) - 1, best_k + w);
    const double step = profile[hi] - profile[lo];
    if ((polarity != 0.0 ? polarity * step : std::abs(step)) < min_gradient) return false;
  }
  const double gm = g[best_k - 1], g0 = g[best_k], gp = g[best_k + 1];
  const double denom = gm - 2 * g0 + gp;
  const double delta = denom < 0 ? std::clamp(0.5 * (gm - gp) / denom, -0.5, 0.5) : 0.0;
  *offset = best_k - steps + delta;
  *strength = best_g;
  *sign = profile[best_k + 1] > profile[best_k - 1] ? 1 : -1;
  return true;
}

}  // namespace

double cornerExclusionPx(const ImageBoardDetectorOptions& o, double side_px) {
  return std::min(o.corner_exclusion_px, kMaxCornerExclusionFraction * side_px);
}

namespace {

// The intensity profiles across a side at its sample positions, in order: the first pass of a
// side's two fits (refineOnce) samples the same coarse line, so the second reuses them.
struct SideProfiles {
  struct Position {
    double t;
    Eigen::Vector2d x, d;  // raw pixel on the line, unit normal there
  };
  std::vector<Position> positions;
  std::vector<double> samples;  // `size` per position
  size_t size = 0;
  bool filled = false;
};

// `along` > 0: each position's profile is the mean of the profiles within +-along positions of
// it (a texture across the side, such as wood grain or stripes meeting the edge, averages out;
// the straight edge does not). `shared`: the profiles along this very line (a, b, n, half), filled
// by the first call and read by later ones.
EdgeSamples searchPeaks(const cv::Mat& gray, const CameraModel& camera, const CoarseEdge& coarse,
                        const Eigen::Vector2d& a, const Eigen::Vector2d& b,
                        const Eigen::Vector2d& n, double half, const LocalPolarity* polarity,
                        const ImageBoardDetectorOptions& o, double min_gradient, int along = 0,
                        SideProfiles* shared = nullptr) {
  using Position = SideProfiles::Position;
  EdgeSamples s;
  const int steps = static_cast<int>(std::ceil(half / kProfileStepPx)) + 1;
  const size_t size = 2 * steps + 1;
  const double len = (b - a).norm();
  const Eigen::Vector2d dir = (b - a) / std::max(len, 1e-9);
  std::vector<double> profile(size), gradient(size);
  const double exclusion = cornerExclusionPx(o, len);
  // Long sides need no more samples than a line fit can use.
  s.step = std::max(o.sample_step_px, len / kMaxSamplesPerSide);
  const double t_end = len - (coarse.b_corner ? exclusion : 0.0);
  auto keepPeak = [&](const std::vector<double>& across, const Position& pos) {
    const double sign_wanted = polarity ? polarity->at(pos.t) : 0.0;
    double offset = 0, strength = 0;
    int sign = 0;
    if (!profilePeak(across, sign_wanted, min_gradient, gradient, &offset, &strength, &sign))
      return;
    const Eigen::Vector2d edge_raw = pos.x + (offset * kProfileStepPx) * pos.d;
    if (!insideImage(gray, edge_raw, o.border_margin_px)) return;
    s.pts_raw.push_back(edge_raw);
    s.pts_u.push_back(camera.undistortPixel(edge_raw));
    s.strength.push_back(strength);
    s.signs.push_back(sign);
    s.ts.push_back(pos.t);
  };
  SideProfiles own;  // stored only with `along` and nothing shared
  SideProfiles& stored = shared ? *shared : own;
  const bool store = shared || along > 0;
  if (!(stored.filled && stored.size == size)) {
    stored = SideProfiles{};
    for (double t = coarse.a_corner ? exclusion : 0.0; t <= t_end; t += s.step) {
      const Eigen::Vector2d xu = a + t * dir;
      const Eigen::Vector2d x = camera.distortPixel(xu);
      Eigen::Vector2d d = camera.distortPixel(xu + n) - x;
      d.normalize();
      // A profile the image border cuts is flat past it (no edge there); the position counts
      // when the image holds the narrow search around the line.
      const double inner = std::min(half, o.fine_search_px) + kProfileStepPx;
      if (!insideImage(gray, x - inner * d, 1.0) || !insideImage(gray, x + inner * d, 1.0))
        continue;
      ++s.positions;
      profile[steps] = sampleBilinear(gray, x.x(), x.y());
      for (const int dk : {-1, 1})
        for (int k = dk; std::abs(k) <= steps; k += dk) {
          const Eigen::Vector2d p = x + (k * kProfileStepPx) * d;
          profile[k + steps] = insideImage(gray, p, 1.0) ? sampleBilinear(gray, p.x(), p.y())
                                                         : profile[k - dk + steps];
        }
      // Single profiles are judged as sampled; kept only for a later call to share.
      if (along <= 0) keepPeak(profile, {t, x, d});
      if (!store) continue;
      stored.positions.push_back({t, x, d});
      stored.samples.insert(stored.samples.end(), profile.begin(), profile.end());
    }
    if (!store) return s;
    stored.size = size;
    stored.filled = true;
    if (along <= 0) return s;
  }
  const std::vector<Position>& positions = stored.positions;
  s.positions = static_cast<int>(positions.size());
  // Windows by distance along the side: a position the image border dropped leaves a gap.
  const double reach = (std::max(along, 0) + 0.5) * s.step;
  size_t lo = 0, hi = 0;
  for (const Position& pos : positions) {
    while (positions[lo].t < pos.t - reach) ++lo;
    while (hi < positions.size() && positions[hi].t <= pos.t + reach) ++hi;
    std::fill(profile.begin(), profile.end(), 0.0);
    for (size_t j = lo; j < hi; ++j)
      for (size_t k = 0; k < size; ++k) profile[k] += stored.samples[j * size + k];
    for (double& v : profile) v /= static_cast<double>(hi - lo);
    keepPeak(profile, pos);
  }
  return s;
}

// Sigma of residuals in order along a side from their neighbours' absolute differences `steps`,
// by their median: a hand's outline or a step between two stretches is a few differences among
// many.
double medianNeighbourNoise(std::vector<double> steps) {
  return kMadToSigma * medianOf(std::move(steps)) / std::sqrt(2.0);
}

// Variance of residuals in order along a side, from neighbours' differences: a bump or a tilt (a
// hand on a side) does not count as noise, as it would in residuals from any fitted shape.
double neighbourVariance(const std::vector<double>& r) {
  if (r.size() < 2) return 0;
  double d2 = 0;
  for (size_t k = 1; k < r.size(); ++k) {
    const double d = r[k] - r[k - 1];
    d2 += d * d;
  }
  return d2 / (2.0 * static_cast<double>(r.size() - 1));
}

double neighbourNoise(const std::vector<double>& r) { return std::sqrt(neighbourVariance(r)); }

// Sagitta of the parabola r = a + b t + c t^2 through the inliers' residuals r from the line, over
// their span (t: their position along the line), and its standard error: a straight edge has none
// beyond noise; an arc (a printed disc's tangent), a kink (a side running on along an occluder) or
// a bump (a hand) has.
void bowOfInliers(const std::vector<double>& t, const std::vector<double>& r, double* bow,
                  double* sigma) {
  *bow = *sigma = 0;
  if (t.size() < 6) return;
  const auto [lo, hi] = std::minmax_element(t.begin(), t.end());
  const double mid = 0.5 * (*lo + *hi), half = 0.5 * (*hi - *lo);
  if (!(half > 0)) return;
  Eigen::Matrix3d ata = Eigen::Matrix3d::Zero();
  Eigen::Vector3d atr = Eigen::Vector3d::Zero();
  for (size_t i = 0; i < t.size(); ++i) {
    const double u = (t[i] - mid) / half;  // in [-1, 1]: the sagitta is c itself
    const Eigen::Vector3d a(1.0, u, u * u);
    ata += a * a.transpose();
    atr += a * r[i];
  }
  const Eigen::LDLT<Eigen::Matrix3d> ldlt(ata);
  if (ldlt.info() != Eigen::Success) return;
  const Eigen::Vector3d c = ldlt.solve(atr);
  // The noise from neighbouring samples' differences, not from the parabola's residuals: a bump
  // (a hand on a side) misfits a parabola, which would count its own shape as noise.
  std::vector<size_t> order(t.size());
  for (size_t i = 0; i < order.size(); ++i) order[i] = i;
  std::sort(order.begin(), order.end(), [&](size_t x, size_t y) { return t[x] < t[y]; });
  std::vector<double> ordered;
  ordered.reserve(order.size());
  for (const size_t i : order) ordered.push_back(r[i]);
  const Eigen::Matrix3d cov = ata.inverse() * neighbourVariance(ordered);
  *bow = c(2);
  *sigma = std::sqrt(std::max(0.0, cov(2, 2)));
}

// The first pass searches as wide as the hypothesis is uncertain. A second straight edge there
// with as many peaks near it as the fitted line (a hand's or a leg's outline along the side, a
// rim) makes the side ambiguous: the robust fit may settle between the two and the narrow passes
// then keep a line through parts of both (a far rs16 side so ran 10.8 px off at its end, bowed
// within the limit). Returns how far (px, at the ends of the side's peaks) the best line
// through two peaks lies from the fitted one when it carries at least as many peaks within
// `band`; 0 otherwise. Peaks are picked deterministically, a dozen from each half of the side.
// `fit`: fitPeaks' result on these samples (its line, and the median strength it took of them).
double rivalOffset(const EdgeSamples& s, const EdgeFit& fit, double band) {
  const Eigen::Vector3d& line = fit.line;
  std::vector<size_t> idx;  // the peaks the fit may use
  for (size_t i = 0; i < s.pts_u.size(); ++i)
    if (s.strength[i] >= kWeakPeakFraction * fit.median_strength) idx.push_back(i);
  const size_t n = idx.size();
  constexpr size_t kPicks = 12;
  if (n < 4) return 0.0;
  const Eigen::Vector2d normal = line.head<2>(), dir(-line.y(), line.x());
  int own = 0;
  double lo = 1e18, hi = -1e18;  // the side's extent
  for (const size_t i : idx) {
    own += std::abs(normal.dot(s.pts_u[i]) + line.z()) <= band;
    lo = std::min(lo, dir.dot(s.pts_u[i]));
    hi = std::max(hi, dir.dot(s.pts_u[i]));
  }
  if (own == 0) return 0.0;
  int best = -1;
  double best_sq = 0;
  Eigen::Vector2d best_point = Eigen::Vector2d::Zero(), best_normal = Eigen::Vector2d::Zero();
  for (size_t ka = 0; ka < kPicks; ++ka) {
    const Eigen::Vector2d& p = s.pts_u[idx[ka * (n / 2) / kPicks]];
    for (size_t kb = 0; kb < kPicks; ++kb) {
      const Eigen::Vector2d d = s.pts_u[idx[n / 2 + kb * (n - n / 2) / kPicks]] - p;
      if (d.norm() < 1e-6) continue;
      const Eigen::Vector2d nn = Eigen::Vector2d(-d.y(), d.x()).normalized();
      int count = 0;
      double sq = 0;
      for (const size_t i : idx) {
        const double r = nn.dot(s.pts_u[i] - p);
        if (std::abs(r) > band) continue;
        ++count;
        sq += r * r;
      }
      if (count > best || (count == best && sq < best_sq)) {
        best = count;
        best_sq = sq;
        best_point = p;
        best_normal = nn;
      }
    }
  }
  const double cosine = best_normal.dot(normal);
  if (best < own || std::abs(cosine) < 1e-6) return 0.0;
  double offset = 0;
  for (const double t : {lo, hi}) {
    // The fitted line's point at t, and the rival's distance from it along the fitted normal.
    const Eigen::Vector2d q = -line.z() * normal + t * dir;
    offset = std::max(offset, std::abs(best_normal.dot(q - best_point) / cosine));
  }
  return offset;
}

// The peaks of s at least kWeakPeakFraction of their median strength (weaker ones are outliers).
std::vector<bool> strongPeaks(const EdgeSamples& s, double median_strength) {
  std::vector<bool> strong(s.pts_u.size());
  for (size_t i = 0; i < strong.size(); ++i)
    strong[i] = s.strength[i] >= kWeakPeakFraction * median_strength;
  return strong;
}

// Half-width (px) of the inlier band around `line` of the peaks `use` (in order along the side):
// kRobustSigmas robust sigmas of their residuals, and at least what a straight edge needs there:
// the configured edge_inlier_px, or, where that is wider, a held board's bow over their extent
// (max_edge_bow_fraction) plus kRobustSigmas sigmas of their noise. The noise is taken from
// neighbours' differences (median): a hand's or a leg's outline is no noise. Within 3 px of a
// far board's short side lie the outlines of the hands and legs over it, which pulled its line
// (augmented real frames: far sides 1.2-2.1 px off; docs/BENCHMARKS.md, session 36). Only for
// peaks searched `near_line`, a fitted one: the first search follows the coarse hypothesis as
// wide as it is uncertain, and keeps the configured band.
double inlierBand(const EdgeSamples& s, const Eigen::Vector3d& line, const std::vector<bool>& use,
                  const ImageBoardDetectorOptions& o, bool near_line) {
  std::vector<double> spread, steps;
  double previous = 0, t_lo = 0, t_hi = 0;
  for (size_t i = 0; i < s.pts_u.size(); ++i) {
    if (!use[i]) continue;
    const double r = line.head<2>().dot(s.pts_u[i]) + line.z();
    if (spread.empty())
      t_lo = s.ts[i];
    else
      steps.push_back(std::abs(r - previous));
    spread.push_back(std::abs(r));
    previous = r;
    t_hi = s.ts[i];
  }
  if (spread.empty()) return o.edge_inlier_px;
  double straight = o.edge_inlier_px;
  if (near_line && steps.size() >= kMinNoiseSteps) {
    const double noise = medianNeighbourNoise(std::move(steps));
    straight = std::min(straight, o.max_edge_bow_fraction * (t_hi - t_lo) + kRobustSigmas * noise);
  }
  return std::max(straight, kRobustSigmas * kMadToSigma * medianOf(std::move(spread)));
}

// Robust line through the peaks (weak peaks out, inliers within inlierBand); fills the fit's
// line, inliers, rms, span and coverage, and with `measure_bow` (the last pass: only its fit is
// judged) the bow. `near_line`: the peaks were searched near a fitted line (inlierBand).
void fitPeaks(const EdgeSamples& s, const Orienter& orient, const ImageBoardDetectorOptions& o,
              bool measure_bow, bool near_line, EdgeFit* fit) {
  const double median_strength = medianOf(s.strength);
  const size_t n = s.pts_u.size();
  const std::vector<bool> strong = strongPeaks(s, median_strength);
  std::vector<bool> use = strong;
  Eigen::Vector3d line = fit->line;
  for (int iter = 0; iter < kRobustIterations; ++iter) {
    line = fitLine(s.pts_u, use, orient);
    if (std::none_of(use.begin(), use.end(), [](bool u) { return u; })) break;
    const double thr = inlierBand(s, line, use, o, near_line);
    for (size_t i = 0; i < n; ++i)
      use[i] = strong[i] && std::abs(line.head<2>().dot(s.pts_u[i]) + line.z()) <= thr;
  }
  line = fitLine(s.pts_u, use, orient);
  fit->raw_inliers.clear();
  double sum_sq = 0;
  std::vector<double> along, residual;  // of the inliers
  const Eigen::Vector2d ldir(-line.y(), line.x());
  for (size_t i = 0; i < n; ++i) {
    if (!use[i]) continue;
    const double r = line.head<2>().dot(s.pts_u[i]) + line.z();
    sum_sq += r * r;
    fit->raw_inliers.push_back(s.pts_raw[i]);
    along.push_back(ldir.dot(s.pts_u[i]));
    residual.push_back(r);
  }
  const int count = static_cast<int>(fit->raw_inliers.size());
  fit->rms = count > 0 ? std::sqrt(sum_sq / count) : 0.0;
  fit->coverage = s.positions > 0 ? static_cast<double>(count) / s.positions : 0.0;
  fit->median_strength = median_strength;
  const auto [lo, hi] = std::minmax_element(along.begin(), along.end());
  fit->span = count > 0 ? *hi - *lo : 0.0;
  if (measure_bow) bowOfInliers(along, residual, &fit->bow, &fit->bow_sigma);
  fit->line = line;
}

// Beyond what a held board's bow allows (the last pass's bow, less `sigmas` standard errors).
bool bentBeyondHold(const ImageBoardDetectorOptions& o, const EdgeFit& fit,
                    double sigmas = kBowSigmas) {
  return std::abs(fit.bow) - sigmas * fit.bow_sigma > o.max_edge_bow_fraction * fit.span;
}

// The side's tests on its last pass's fit: sets valid, or the reason it is not. `bow_sigmas`:
// the bow's allowance for its standard error.
void judgeSide(const ImageBoardDetectorOptions& o, double min_span, EdgeFit* fit_out,
               double bow_sigmas = kBowSigmas) {
  EdgeFit& fit = *fit_out;
  fit.valid = false;
  fit.reason.clear();
  if (fit.span < min_span) {
    fit.reason = cv::format("visible edge too short (%.0f px)", fit.span);
  } else if (fit.coverage < o.min_side_coverage) {
    fit.reason = cv::format("edge seen along %.0f %% of its visible length (need %.0f %%)",
                            100 * fit.coverage, 100 * o.min_side_coverage);
  } else if (fit.rms > o.max_edge_rms_px) {
    fit.reason = cv::format("edge not straight (rms %.2f px)", fit.rms);
  } else if (bentBeyondHold(o, fit, bow_sigmas)) {
    fit.reason = cv::format("edge bent (%.1f px over %.0f px)", std::abs(fit.bow), fit.span);
  } else if (fit.rival_offset > o.edge_inlier_px) {
    fit.reason = cv::format("two edges along the side (another as well supported, %.1f px off)",
                            fit.rival_offset);
  } else {
    fit.valid = true;
  }
}

// The contiguous run of `r` (residuals in order along a side) whose sum is largest in magnitude,
// either sign: {first, last, |sum|}.
struct Run {
  size_t first = 0, last = 0;
  double sum = 0;
};
Run strongestRun(const std::vector<double>& r) {
  Run best;
  for (const double sign : {1.0, -1.0}) {
    double sum = 0;
    size_t start = 0;
    for (size_t k = 0; k < r.size(); ++k) {
      if (sum <= 0) {
        sum = 0;
        start = k;
      }
      sum += sign * r[k];
      if (sum > best.sum) best = {start, k, sum};
    }
  }
  return best;
}

// The strong peaks within the inlier band of `line` (inlierBand; peaks of a last pass), in order
// along the side, and their residuals.
void inliersAlong(const EdgeSamples& s, const Eigen::Vector3d& line,
                  const ImageBoardDetectorOptions& o, bool near_line, std::vector<size_t>* idx,
                  std::vector<double>* r) {
  idx->clear();
  r->clear();
  if (s.strength.empty()) return;
  const auto residual = [&](size_t i) { return line.head<2>().dot(s.pts_u[i]) + line.z(); };
  const std::vector<bool> strong = strongPeaks(s, medianOf(s.strength));
  if (std::none_of(strong.begin(), strong.end(), [](bool u) { return u; })) return;
  const double band = inlierBand(s, line, strong, o, near_line);
  for (size_t i = 0; i < s.pts_u.size(); ++i)
    if (strong[i] && std::abs(residual(i)) <= band) idx->push_back(i);
  std::sort(idx->begin(), idx->end(), [&](size_t x, size_t y) { return s.ts[x] < s.ts[y]; });
  for (const size_t i : *idx) r->push_back(residual(i));
}

// The samples i of s for which keep(i) holds, on the same side (positions, step).
template <typename Keep>
EdgeSamples samplesWhere(const EdgeSamples& s, const Keep& keep) {
  EdgeSamples kept;
  kept.positions = s.positions;
  kept.step = s.step;
  for (size_t i = 0; i < s.pts_u.size(); ++i) {
    if (!keep(i)) continue;
    kept.pts_u.push_back(s.pts_u[i]);
    kept.pts_raw.push_back(s.pts_raw[i]);
    kept.strength.push_back(s.strength[i]);
    kept.signs.push_back(s.signs[i]);
    kept.ts.push_back(s.ts[i]);
  }
  return kept;
}

// The samples of s outside positions [stretch.first, stretch.second] along the side.
EdgeSamples outside(const EdgeSamples& s, std::pair<double, double> stretch) {
  return samplesWhere(
      s, [&](size_t i) { return s.ts[i] < stretch.first || s.ts[i] > stretch.second; });
}

// |sum| of `count` residuals in standard errors of their sum.
double runSigmas(double sum, size_t count, double noise) {
  return std::abs(sum) / (noise * std::sqrt(static_cast<double>(count)));
}

// A hand holding the board at a side puts its own outline within the inlier band along a stretch
// of the side: the fit bends towards it ("edge bent", "not straight") while the rest of the side
// is straight. The stretch is the run of inliers whose residuals add up most on one side of the
// line. Without it (at most kMaxBumpShare of the side, and within the side: straight stretches of
// kMinFlankShare on both sides pin the line; a stretch at an end may be a leg the side runs on
// along), the side is fitted again from its other peaks into `rest`, which records the stretch
// (EdgeFit::dropped). Returns true when the dropped stretch lay off the new line beyond the noise
// and no such stretch is left in the rest (a hand and a leg on one side: the rest would still lean
// on the leg). `only_if_off` (a side that passed its tests): only when the run stands that far off
// the side's own line too, so straight sides are not refitted. `near_line`: inlierBand's. The
// caller judges the new fit by every test of a side.
constexpr double kMaxBumpShare = 1.0 / 3.0;  // of the side's sample positions
constexpr double kMinFlankShare = 0.15;      // of the inliers' extent, kept on each side of a drop
constexpr double kRunSigmas = 4.0;    // a run's residual sum, in standard errors: a bump, not noise
constexpr double kMinNoisePx = 0.05;  // floor of the residuals' noise (a synthetic edge has ~none)
// px: a valid side is its rest only when that moves its line this far at an end (half the 1 px a
// board's line must keep): a held board's bow is a run too, and long sides would move by tenths.
constexpr double kMinMovePx = 0.5;
bool withoutBump(const EdgeSamples& s, const Orienter& orient, const ImageBoardDetectorOptions& o,
                 bool only_if_off, bool near_line, EdgeFit* rest) {
  std::vector<size_t> idx;
  std::vector<double> r;
  inliersAlong(s, rest->line, o, near_line, &idx, &r);
  if (idx.size() < 6) return false;
  const Run bump = strongestRun(r);
  const size_t run = bump.last - bump.first + 1;
  if (run < 3 || run > kMaxBumpShare * s.positions) return false;
  if (only_if_off &&
      runSigmas(bump.sum, run, std::max(neighbourNoise(r), kMinNoisePx)) < kRunSigmas)
    return false;
  const double t_from = s.ts[idx[bump.first]] - 0.5 * s.step,
               t_to = s.ts[idx[bump.last]] + 0.5 * s.step;
  const double t_lo = s.ts[idx.front()], t_hi = s.ts[idx.back()];
  const double flank = kMinFlankShare * (t_hi - t_lo);
  if (t_from - t_lo < flank || t_hi - t_to < flank) return false;
  std::vector<Eigen::Vector2d> dropped;
  for (size_t k = bump.first; k <= bump.last; ++k) dropped.push_back(s.pts_u[idx[k]]);
  const EdgeSamples kept = outside(s, {t_from, t_to});
  if (static_cast<int>(kept.pts_u.size()) < o.min_edge_points) return false;
  fitPeaks(kept, orient, o, true, near_line, rest);
  rest->dropped = {t_from, t_to};
  inliersAlong(kept, rest->line, o, near_line, &idx, &r);
  if (idx.size() < 6) return false;
  const double noise = std::max(neighbourNoise(r), kMinNoisePx);
  double off = 0;  // the dropped stretch's residual sum from the new line
  for (const Eigen::Vector2d& p : dropped) off += rest->line.head<2>().dot(p) + rest->line.z();
  const Run left = strongestRun(r);
  return runSigmas(off, dropped.size(), noise) >= kRunSigmas &&
         runSigmas(left.sum, left.last - left.first + 1, noise) < kRunSigmas;
}

// A side whose inliers, in order along it, hold stretches offset from each other (a hand's or
// a leg's outline at one end, the board's edge at the other): the line settles between them
// within every straightness test and runs off at the end (augmented real frames, draw 22: a far
// side's 22 px on a hand 4.5 px outside the edge and 40 px on the edge, 9.4 px off at the side's
// end). A step is local: the mean residual of the kStepWindow inliers after a position against
// the kStepWindow before it, beyond kStepSigmas standard errors of that difference from the
// neighbour noise (a median: a step is one difference among many) and beyond half the inlier
// band (two looks at a side may disagree that much, refineOnce; a near-axis edge's sub-pixel
// staircase steps by ~1 px with hardly any noise between). The steps cut the inliers
// into stretches; returns, in order along the side, whether each inlier lies on the longest
// stretch or on one in line with it (within the same bound of its line: a bump's two flanks),
// empty when there is no step.
constexpr int kStepWindow = 6;       // inliers on each side of a position
constexpr double kStepSigmas = 5.0;  // every position is tried: far beyond noise
std::vector<bool> inLineWithLongestStretch(const EdgeSamples& s, const Eigen::Vector3d& line,
                                           const ImageBoardDetectorOptions& o, bool near_line,
                                           std::vector<size_t>* idx) {
  std::vector<double> r;
  inliersAlong(s, line, o, near_line, idx, &r);
  const int n = static_cast<int>(r.size());
  if (n < 2 * kStepWindow) return {};
  std::vector<double> diffs;
  for (int k = 1; k < n; ++k) diffs.push_back(std::abs(r[k] - r[k - 1]));
  const double noise = std::max(kMinNoisePx, medianNeighbourNoise(std::move(diffs)));
  const double bound =
      std::max(kStepSigmas * noise * std::sqrt(2.0 / kStepWindow), 0.5 * o.edge_inlier_px);
  std::vector<double> d(n, 0.0);  // step before inlier k
  for (int k = kStepWindow; k + kStepWindow <= n; ++k) {
    double before = 0, after = 0;
    for (int j = 0; j < kStepWindow; ++j) {
      before += r[k - 1 - j];
      after += r[k + j];
    }
    d[k] = std::abs(after - before) / kStepWindow;
  }
  // Steps, largest first, none within kStepWindow of a larger one.
  std::vector<int> cuts;
  std::vector<bool> taken(n, false);
  while (true) {
    int best = -1;
    for (int k = 0; k < n; ++k)
      if (!taken[k] && d[k] > bound && (best < 0 || d[k] > d[best])) best = k;
    if (best < 0) break;
    cuts.push_back(best);
    for (int k = std::max(0, best - kStepWindow); k < std::min(n, best + kStepWindow + 1); ++k)
      taken[k] = true;
  }
  if (cuts.empty()) return {};
  cuts.push_back(0);
  cuts.push_back(n);
  std::sort(cuts.begin(), cuts.end());
  int first = 0, last = 0;  // the longest stretch [first, last)
  for (size_t c = 1; c < cuts.size(); ++c)
    if (cuts[c] - cuts[c - 1] > last - first) {
      first = cuts[c - 1];
      last = cuts[c];
    }
  // The longest stretch's own line (residual offset and slope along the inliers' order).
  double sx = 0, sy = 0, sxx = 0, sxy = 0;
  for (int k = first; k < last; ++k) {
    sx += k;
    sy += r[k];
    sxx += double(k) * k;
    sxy += k * r[k];
  }
  const double m = last - first, den = m * sxx - sx * sx;
  const double slope = den > 0 ? (m * sxy - sx * sy) / den : 0.0;
  const double offset = (sy - slope * sx) / m;
  std::vector<bool> keep(n, false);
  for (size_t c = 1; c < cuts.size(); ++c) {
    double mean = 0;
    for (int k = cuts[c - 1]; k < cuts[c]; ++k) mean += r[k] - (offset + slope * k);
    mean /= std::max(1, cuts[c] - cuts[c - 1]);
    const bool in_line = std::abs(mean) <= bound;
    for (int k = cuts[c - 1]; k < cuts[c]; ++k) keep[k] = in_line;
  }
  return keep;
}

// px: how far `other` lies from the fit's line at the ends of the fit's inliers (0: none).
double linesApartAtEnds(const CameraModel& camera, const EdgeFit& fit,
                        const Eigen::Vector3d& other) {
  double apart = 0;
  if (fit.raw_inliers.empty()) return apart;
  for (const Eigen::Vector2d& end_raw : {fit.raw_inliers.front(), fit.raw_inliers.back()}) {
    Eigen::Vector2d end = camera.undistortPixel(end_raw);
    end -= (fit.line.head<2>().dot(end) + fit.line.z()) * fit.line.head<2>();  // onto the line
    apart = std::max(apart, std::abs(other.head<2>().dot(end) + other.z()));
  }
  return apart;
}

// A valid side of single profiles whose line depends on the stretches offset from its longest
// one (inLineWithLongestStretch): fitted on the longest and those in line with it, the line
// moves at the ends of the inliers by more than two looks at a side may disagree (refineOnce)
// and more than a held board's bow over them (a long bowed side fitted on part of itself moves by
// up to its sagitta). A hand's bump in the middle of a side moves it by tenths.
EdgeFit withoutStep(const EdgeSamples& s, const CameraModel& camera, const Orienter& orient,
                    const ImageBoardDetectorOptions& o, bool near_line, EdgeFit fit) {
  if (!near_line || !fit.valid) return fit;
  std::vector<size_t> idx;
  const std::vector<bool> keep = inLineWithLongestStretch(s, fit.line, o, near_line, &idx);
  if (keep.empty()) return fit;
  std::vector<bool> sample_kept(s.pts_u.size(), false);
  for (size_t k = 0; k < idx.size(); ++k) sample_kept[idx[k]] = keep[k];
  const EdgeSamples in_line = samplesWhere(s, [&](size_t i) { return sample_kept[i]; });
  if (in_line.pts_u.size() == idx.size() || in_line.pts_u.size() < 2) return fit;
  EdgeFit other = fit;
  fitPeaks(in_line, orient, o, false, near_line, &other);
  const double moved = linesApartAtEnds(camera, fit, other.line);
  if (moved > std::max(0.5 * o.edge_inlier_px, o.max_edge_bow_fraction * fit.span)) {
    fit.step_px = moved;
    fit.valid = false;
    fit.reason = cv::format(
        "two edges along the side (on its longest stretch and those in line with it, it moves "
        "%.1f px)",
        moved);
  }
  return fit;
}

// One side fitted afresh from its profiles, each one alone or averaged along the side (`along`:
// searchPeaks); `first_pass`: the profiles of the first pass, shared with the side's other fit;
// `leave_out`: positions along the side whose peaks are not used (the other look's dropped
// stretch), if any.
EdgeFit fitSide(const cv::Mat& gray, const CameraModel& camera, const CoarseEdge& coarse,
                const Orienter& orient, const ImageBoardDetectorOptions& o, double min_gradient,
                int along, SideProfiles* first_pass,
                const std::optional<std::pair<double, double>>& leave_out = std::nullopt) {
  EdgeFit fit;
  Eigen::Vector2d a = camera.undistortPixel(coarse.a), b = camera.undistortPixel(coarse.b);
  fit.line = orient.through(a, b);
  // The fine passes' band follows the side's bow and noise (inlierBand) in single profiles. The
  // averaged look is a check on them (refineOnce), measured with the configured band: it keeps
  // it (a striped side's two looks would otherwise part by more than their agreement allows).
  const bool near_line = along == 0;
  LocalPolarity polarity;
  EdgeSamples last;  // the last pass's peaks
  for (int pass = 0; pass <= kFinePasses; ++pass) {
    const double half = pass > 0 ? o.fine_search_px
                                 : (coarse.search_px > 0 ? coarse.search_px : o.coarse_search_px);
    const Eigen::Vector2d n = fit.line.head<2>();
    // Project the segment ends onto the current line.
    a = a - (n.dot(a) + fit.line.z()) * n;
    b = b - (n.dot(b) + fit.line.z()) * n;
    EdgeSamples s =
        searchPeaks(gray, camera, coarse, a, b, n, half, pass == 0 ? nullptr : &polarity, o,
                    min_gradient, along, pass == 0 ? first_pass : nullptr);
    if (pass == 0) {
      polarity.t = s.ts;
      polarity.sum.assign(1, 0);
      for (int sgn : s.signs) polarity.sum.push_back(polarity.sum.back() + sgn);
      polarity.window =
          std::max(kPolarityWindowSteps * s.step, kPolarityWindowFraction * (b - a).norm());
      for (size_t i = 0; i < s.signs.size(); ++i)
        if (s.signs[i] * polarity.at(s.ts[i]) < 0)
          s.strength[i] = 0;  // against its stretch: clutter
    }
    // An averaged profile holds its neighbours within `along` positions: those of the stretch too.
    if (leave_out)
      s = outside(s, {leave_out->first - along * s.step, leave_out->second + along * s.step});
    if (static_cast<int>(s.pts_u.size()) < o.min_edge_points) {
      fit.reason = "too few edge pixels (" + std::to_string(s.pts_u.size()) + ")";
      return fit;
    }
    fitPeaks(s, orient, o, pass == kFinePasses, pass > 0 && near_line, &fit);
    if (pass == 0) fit.rival_offset = rivalOffset(s, fit, o.edge_inlier_px);
    if (static_cast<int>(fit.raw_inliers.size()) < o.min_edge_points) {
      fit.reason = "too few edge inliers (" + std::to_string(fit.raw_inliers.size()) + ")";
      return fit;
    }
    if (pass == kFinePasses) last = std::move(s);
  }
  // A side shorter than twice min_edge_length_px (a far board's, or one the image cuts) shows its
  // edge along the share of its visible length that the coverage asks of every side.
  const double min_span = std::min(o.min_edge_length_px, o.min_side_coverage * (b - a).norm());
  judgeSide(o, min_span, &fit);
  if (fit.span >= min_span && fit.coverage >= o.min_side_coverage &&
      (fit.valid || fit.rms > o.max_edge_rms_px || bentBeyondHold(o, fit))) {
    // A hand bends a side (refused) or, off its middle, tilts it (passed, off at an end). The gap
    // a drop leaves widens the bow's standard error: the rest must be straight outright.
    EdgeFit rest = fit;
    if (withoutBump(last, orient, o, fit.valid, near_line, &rest)) {
      judgeSide(o, min_span, &rest, 0.0);
      if (rest.valid && (!fit.valid || linesApartAtEnds(camera, fit, rest.line) > kMinMovePx))
        return withoutStep(outside(last, *rest.dropped), camera, orient, o, near_line,
                           std::move(rest));
    }
  }
  return withoutStep(last, camera, orient, o, near_line, std::move(fit));
}

// One side refined afresh (refineEdge), looked at twice: one profile at a time, and with each
// profile averaged over its neighbours along the side (kAlongPositions). Grain or stripes on the
// board meeting a faint edge put single profiles' peaks on a stripe's flank inside the board: the
// line then scatters (a side refused as "not straight" or "two edges") or, worse, settles
// several px off with every test passed (a synthetic striped side 4.8 px off). Averaged, a
// texture across the side cancels and the edge remains. So a side counts only when the two looks
// agree within half the inlier band at both ends of the first look's inliers, and a side the
// first look refused is the averaged look's when that passes every test and agrees (it confirms
// the first look's line, never moves the side onto another edge). An averaged look that fails
// (a hand or a leg on the side: averaging spreads it) leaves the first look's verdict.
EdgeFit refineOnce(const cv::Mat& gray, const CameraModel& camera, const CoarseEdge& coarse,
                   const Orienter& orient, const ImageBoardDetectorOptions& o,
                   double min_gradient) {
  SideProfiles first_pass;  // both fits' first pass samples the coarse line alike
  EdgeFit fit = fitSide(gray, camera, coarse, orient, o, min_gradient, 0, &first_pass);
  if (fit.raw_inliers.size() < 2) return fit;
  // Both looks on the same part of the side: averaged, a hand's stretch the first look dropped
  // spreads over its neighbours and pulls the line as it did before the drop.
  const EdgeFit averaged = fitSide(gray, camera, coarse, orient, o, min_gradient, kAlongPositions,
                                   &first_pass, fit.dropped);
  if (!averaged.valid) return fit;
  const double apart = linesApartAtEnds(camera, fit, averaged.line);
  const bool agree = apart <= 0.5 * o.edge_inlier_px;
  if (!fit.valid) return agree && fit.step_px == 0 ? averaged : fit;
  if (!agree) {
    fit.valid = false;
    fit.reason = cv::format(
        "edge moves %.1f px when averaged along the side (texture across it; need %.1f px)", apart,
        0.5 * o.edge_inlier_px);
  }
  return fit;
}

}  // namespace

double edgeContinuation(const cv::Mat& gray, const CameraModel& camera, const Eigen::Vector3d& line,
                        const Eigen::Vector2d& corner, const Eigen::Vector2d& outward,
                        double gap_px, double length_px, const ImageBoardDetectorOptions& o,
                        double min_gradient, int* positions, double* run_on_px) {
  CoarseEdge stretch;
  stretch.a_corner = stretch.b_corner = false;
  const Eigen::Vector2d a = corner + gap_px * outward, b = corner + (gap_px + length_px) * outward;
  const Eigen::Vector2d n = line.head<2>();
  const EdgeSamples s =
      searchPeaks(gray, camera, stretch, a, b, n, o.fine_search_px, nullptr, o, min_gradient);
  *positions = s.positions;
  int on_line = 0;
  const double tolerance = std::min(o.edge_inlier_px, kRunOnTolerancePx);
  for (const auto& p : s.pts_u) on_line += std::abs(n.dot(p) + line.z()) <= tolerance;
  *run_on_px = on_line * s.step;
  return s.positions > 0 ? static_cast<double>(on_line) / s.positions : 0.0;
}

double edgeCoverage(const cv::Mat& gray, const CameraModel& camera, const Eigen::Vector2d& a,
                    const Eigen::Vector2d& b, const Eigen::Vector2d& inside,
                    const ImageBoardDetectorOptions& o, double min_gradient, bool refit) {
  CoarseEdge side;
  side.a_corner = side.b_corner = true;
  const Eigen::Vector3d line = lineThrough(a, b, inside);
  const EdgeSamples s =
      searchPeaks(gray, camera, side, a, b, line.head<2>(),
                  refit ? o.coarse_search_px : o.fine_search_px, nullptr, o, min_gradient);
  if (s.positions == 0) return 0.0;
  if (!refit) return static_cast<double>(s.pts_u.size()) / s.positions;
  if (static_cast<int>(s.pts_u.size()) < o.min_edge_points) return 0.0;
  std::vector<Eigen::Vector3d> oriented;
  EdgeFit fit;
  fit.line = line;
  fitPeaks(s, Orienter{inside, &oriented}, o, false, false, &fit);
  int near = 0;
  for (const auto& p : s.pts_u)
    near += std::abs(fit.line.head<2>().dot(p) + fit.line.z()) <= o.fine_search_px;
  return static_cast<double>(near) / s.positions;
}

EdgeFit refineEdge(const cv::Mat& gray, const CameraModel& camera, const CoarseEdge& coarse,
                   const Eigen::Vector2d& inside_u, const ImageBoardDetectorOptions& o,
                   double min_gradient, RefinedSides* refined) {
  if (refined)
    for (const RefinedSide& r : *refined)
      if (r.coarse.a == coarse.a && r.coarse.b == coarse.b &&
          r.coarse.search_px == coarse.search_px && r.coarse.a_corner == coarse.a_corner &&
          r.coarse.b_corner == coarse.b_corner && insideAll(r.oriented, inside_u))
        return r.fit;
  RefinedSide side;
  side.coarse = coarse;
  side.fit = refineOnce(gray, camera, coarse, Orienter{inside_u, &side.oriented}, o, min_gradient);
  if (!refined || !insideAll(side.oriented, inside_u)) return side.fit;
  refined->push_back(std::move(side));
  return refined->back().fit;
}

}  // namespace image_detection
}  // namespace board_calib
