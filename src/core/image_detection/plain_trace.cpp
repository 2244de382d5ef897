// Plain board, a side without a line: three lines of the board (two open sides joined by a base,
// ThreeSides) fix two corners, the board plane's vanishing points through the camera matrix, and
// so the pencil of lines the fourth side belongs to. The fourth side is searched along the open
// sides, scored by gradient of either polarity along its whole length against the gradient noise
// measured around it, and each strong placement becomes a quadrilateral for the usual checks.
#include "plain_internal.h"

#include <board_calib/core/common/statistics.h>

#include <algorithm>
#include <cmath>
#include <cstdint>

namespace board_calib {
namespace image_detection {
namespace {

constexpr double kStepPx = 1.0;  // spacing of the open corner's positions along side a
// Gradient is read across the candidate side at -0.5, 0, +0.5 px (a difference of samples 1 px
// apart, as the edge refinement reads it): a side within half a step of the edge sees its peak.
// The three differences share their samples: five reads at -1 ... +1 px.
constexpr double kReadAtPx[] = {-1.0, -0.5, 0.0, 0.5, 1.0};
constexpr int kSamples = 48;  // gradient samples along a candidate side (coverage to ~2 %)
// The far corner on side b may leave the pencil by this much (the pencil's direction comes from
// measured lines: a 0.2 deg error moves a 300 px side's far end by 1 px).
constexpr double kPencilSlackPx = 3.0;
// A placement is an edge, not a ramp or a textured band: its coverage must drop by half the side
// coverage rule this far to both sides (a blurred step edge's gradient falls to ~10 % at 3 px).
constexpr double kPeakWidthPx = 3.0;
constexpr double kPeakDropShare = 0.5;
constexpr int kMaxPeaks = 2;  // placements tried per chain (the strongest may be a print line)
constexpr double kMadToSigma = 1.4826;
constexpr int kMaxRows = 4000;  // open-corner positions (bounds the search on huge images)
constexpr int kSlackRows = static_cast<int>(kPencilSlackPx / kStepPx);
// The coarse pass reads every third column (16 of 48); only rows whose coarse coverage may meet
// the rule are read whole.
constexpr int kCoarseStride = 3;

Eigen::Vector3d hom(const Eigen::Vector2d& p) { return {p.x(), p.y(), 1.0}; }

bool dehom(const Eigen::Vector3d& h, Eigen::Vector2d* p) {
  if (std::abs(h.z()) < 1e-12 * h.head<2>().norm()) return false;
  *p = h.head<2>() / h.z();
  return std::isfinite(p->x()) && std::isfinite(p->y());
}

// The fourth side's pencil: it is parallel on the board to the base, so it passes through the
// base's vanishing point. That point is the base's back-projected plane crossed with the board
// direction of the open sides (their vanishing point, possibly at infinity): K (N_base x d_open).
struct Pencil {
  Eigen::Vector3d vanishing;  // homogeneous, undistorted px
  Eigen::Vector3d normal;     // board plane normal (camera frame, either sign)
  Eigen::Matrix3d K_inv;
};

bool pencilOf(const ThreeSides& u, const Eigen::Matrix3d& K, Pencil* p) {
  p->K_inv = K.inverse();
  const Eigen::Vector3d d_open = p->K_inv * u.lines[0].cross(u.lines[2]);
  const Eigen::Vector3d d_base = (K.transpose() * u.lines[1]).cross(d_open);
  if (d_open.norm() < 1e-12 || d_base.norm() < 1e-12 * d_open.norm()) return false;
  p->vanishing = K * d_base;
  p->normal = d_open.normalized().cross(d_base.normalized());
  return p->normal.norm() > 1e-9;
}

// Open-side length over base length of the board the corners c1, c2, b, a span on the pencil's
// plane (scale-free); false when the plane would pass between the corners and the camera.
bool boardAspect(const Pencil& p, const ThreeSides& u, const Eigen::Vector2d& a,
                 const Eigen::Vector2d& b, double* aspect) {
  const Eigen::Vector2d pts[4] = {u.corners[0], u.corners[1], b, a};
  Eigen::Vector3d X[4];
  double sign = 0;
  for (int k = 0; k < 4; ++k) {
    const Eigen::Vector3d r = p.K_inv * hom(pts[k]);
    const double depth = p.normal.dot(r);
    if (std::abs(depth) < 1e-12 || (sign != 0 && depth * sign < 0)) return false;
    sign = depth;
    X[k] = r / depth;
  }
  const double base = (X[1] - X[0]).norm();
  *aspect = 0.5 * ((X[3] - X[0]).norm() + (X[2] - X[1]).norm()) / std::max(base, 1e-12);
  return true;
}

// Gradient strengths of the band the fourth side sweeps: row k is the side of the pencil through
// the point kStepPx * k along side a from its corner, column i a point along it (the corners'
// neighbourhood skipped). Negative where a point lies outside the image or was not read.
struct Band {
  std::vector<Eigen::Vector2d> a, b;  // open corners per row (undistorted px)
  std::vector<char> row_ok, allowed, read_fine;
  std::vector<char> seen;       // the row's side crosses the image
  std::vector<float> strength;  // rows x kSamples: strongest |gradient| read across the side
  // Per row, bit i for column i: read inside the image (strength set), an edge (markEdges).
  // Coverage counts them a run of columns at a time.
  std::vector<uint64_t> read_bits, edge_bits;
  std::vector<float> centre;  // |gradient| on the side itself (the noise sample)
  double lambda0 = 0;         // share of the side skipped at each corner
  int rows = 0;
  float at(int k, int i) const { return strength[static_cast<size_t>(k) * kSamples + i]; }
};

// Reads columns first, first + stride, ... of row k.
void readRow(const cv::Mat& gray, const CameraModel& camera, const ImageBoardDetectorOptions& o,
             int k, int first, int stride, Band* band) {
  const Eigen::Vector2d &a = band->a[k], &b = band->b[k];
  const Eigen::Vector2d dir = (b - a).normalized(), n_u(-dir.y(), dir.x());
  const Eigen::Vector2d mid = 0.5 * (a + b);
  // Distortion turns the normal slowly: one raw normal per row.
  Eigen::Vector2d n = camera.distortPixel(mid + n_u) - camera.distortPixel(mid);
  n.normalize();
  const double margin = o.border_margin_px + 2.0;
  for (int i = first; i < kSamples; i += stride) {
    const double lambda = band->lambda0 + (1.0 - 2.0 * band->lambda0) * i / (kSamples - 1);
    const Eigen::Vector2d x_u = a + lambda * (b - a);
    Eigen::Vector2d x;  // the raw pixel the visibility check projects (no second distortion)
    if (!visibleUndistorted(camera, x_u, 0.0, &x)) continue;
    if (x.x() < margin || x.y() < margin || x.x() > gray.cols - 1 - margin ||
        x.y() > gray.rows - 1 - margin)
      continue;
    double v[5];
    for (int j = 0; j < 5; ++j)
      v[j] = sampleBilinear(gray, x.x() + kReadAtPx[j] * n.x(), x.y() + kReadAtPx[j] * n.y());
    const double g_centre = std::abs(v[3] - v[1]);
    const double best = std::max({0.0, std::abs(v[2] - v[0]), g_centre, std::abs(v[4] - v[2])});
    band->centre.push_back(static_cast<float>(g_centre));
    band->strength[static_cast<size_t>(k) * kSamples + i] = static_cast<float>(best);
    band->read_bits[k] |= uint64_t{1} << i;
  }
}

// The open corner positions the declared board allows: both open sides reach at least where
// their segments end, and the board spanned has an aspect within what any tilt up to the
// maximum can show of the declared one (width or height along the base).
Band sweepBand(const CameraModel& camera, const Target& target, const ImageBoardDetectorOptions& o,
               const ThreeSides& u, const Pencil& p) {
  Band band;
  const double ratio =
      std::max(target.width, target.height) / std::min(target.width, target.height);
  const double slack = 1.0 / std::cos(o.max_board_tilt_deg * M_PI / 180.0);
  const double lo = 1.0 / (ratio * slack), hi = ratio * slack;
  int past = 0;  // rows past the largest aspect, kept for the far corner's slack
  for (int k = 0; k < kMaxRows && past <= kSlackRows; ++k) {
    const Eigen::Vector2d a = u.corners[0] + (k * kStepPx) * u.inward[0];
    Eigen::Vector2d b;
    double aspect = 0;
    const bool ok = dehom(hom(a).cross(p.vanishing).cross(u.lines[2]), &b) &&
                    (b - u.corners[1]).dot(u.inward[1]) > 0 && boardAspect(p, u, a, b, &aspect);
    if (ok && aspect > hi) ++past;  // the aspect grows along the open sides
    band.a.push_back(a);
    band.b.push_back(ok ? b : a);
    band.row_ok.push_back(ok);
    band.allowed.push_back(ok && aspect >= lo && aspect <= hi && k * kStepPx >= u.reach[0] &&
                           (b - u.corners[1]).dot(u.inward[1]) >= u.reach[1] &&
                           (b - a).norm() >= o.min_board_size_px);
  }
  band.rows = static_cast<int>(band.a.size());
  const cv::Rect2d bounds = undistortedBounds(camera);
  for (int k = 0; k < band.rows; ++k)
    band.seen.push_back(band.row_ok[k] && clippedLength(band.a[k], band.b[k], bounds) > 0);
  band.strength.assign(static_cast<size_t>(band.rows) * kSamples, -1.0f);
  band.read_bits.assign(band.rows, 0);
  band.edge_bits.assign(band.rows, 0);
  band.read_fine.assign(band.rows, 0);
  const double base = (u.corners[1] - u.corners[0]).norm();
  band.lambda0 = std::min(o.corner_exclusion_px, 0.15 * base) / std::max(base, 1.0);
  return band;
}

static_assert(kSamples <= 64, "a row's columns are the bits of one word");

// The side whose far corner is delta rows away crosses the rows in runs of columns: column i
// lies on row offset round(delta i / (kSamples - 1)). Per delta in the far corner's slack, the
// runs as (row offset, column bits): computed once, not per side and column.
struct SideRows {
  int runs[2 * kSlackRows + 1] = {};
  int offset[2 * kSlackRows + 1][kSlackRows + 1] = {};
  uint64_t columns[2 * kSlackRows + 1][kSlackRows + 1] = {};
  SideRows() {
    for (int delta = -kSlackRows; delta <= kSlackRows; ++delta) {
      const int d = delta + kSlackRows;
      for (int i = 0; i < kSamples; ++i) {
        const int r =
            static_cast<int>(std::lround(delta * static_cast<double>(i) / (kSamples - 1)));
        if (i == 0 || r != offset[d][runs[d] - 1]) offset[d][runs[d]++] = r;
        columns[d][runs[d] - 1] |= uint64_t{1} << i;
      }
    }
  }
};
const SideRows kSideRows;

// Columns 0, stride, 2 stride, ... as bits.
uint64_t strideColumns(int stride) {
  uint64_t bits = 0;
  for (int i = 0; i < kSamples; i += stride) bits |= uint64_t{1} << i;
  return bits;
}

// Set bits of a word (__builtin_popcountll is a library call on the baseline x86-64 target).
int bitCount(uint64_t v) {
  v -= (v >> 1) & 0x5555555555555555ULL;
  v = (v & 0x3333333333333333ULL) + ((v >> 2) & 0x3333333333333333ULL);
  v = (v + (v >> 4)) & 0x0F0F0F0F0F0F0F0FULL;
  return static_cast<int>((v * 0x0101010101010101ULL) >> 56);
}

// Share of the side from row k's open corner on a to row k + delta's on b that shows an edge,
// over the columns read with `stride` (their bits `columns`); -1 when too little of it lies
// inside the image. `side_length` is row k's side length (b - a).
double coverage(const Band& band, int k, int delta, int stride, uint64_t columns,
                double side_length, const ImageBoardDetectorOptions& o) {
  int positions = 0, edges = 0;
  const int d = delta + kSlackRows;
  for (int run = 0; run < kSideRows.runs[d]; ++run) {
    const int r = k + kSideRows.offset[d][run];
    if (r < 0 || r >= band.rows) continue;  // rows not ok are never read: no bits
    const uint64_t mask = kSideRows.columns[d][run] & columns;
    positions += bitCount(band.read_bits[r] & mask);
    edges += bitCount(band.edge_bits[r] & mask);
  }
  const double spacing = stride * side_length * (1.0 - 2.0 * band.lambda0) / (kSamples - 1);
  if (positions * stride < o.min_edge_points || positions * spacing < o.min_edge_length_px)
    return -1;
  return static_cast<double>(edges) / positions;
}

// An edge sample stands out of the noise and is the strongest within `ridge` rows to either
// side (the rows lie 1 px apart along the open sides): on texture or a ramp the strongest
// gradient sits anywhere in the window, on an edge at the edge. Marks columns first, first +
// stride, ... of the rows in `rows`.
void markEdges(double threshold, int ridge, const std::vector<char>& rows, int first, int stride,
               Band* band) {
  for (int k = 0; k < band->rows; ++k) {
    if (!rows[k]) continue;
    for (int i = first; i < kSamples; i += stride) {
      const float s = band->at(k, i);
      bool edge = s >= threshold;
      for (int d = 2; d <= ridge + 1 && edge; ++d)
        edge =
            (k < d || band->at(k - d, i) <= s) && (k + d >= band->rows || band->at(k + d, i) <= s);
      const uint64_t bit = uint64_t{1} << i;
      band->edge_bits[k] = edge ? band->edge_bits[k] | bit : band->edge_bits[k] & ~bit;
    }
  }
}

// Per allowed row, the best coverage over the far corner's slack (and which delta gave it).
void bestCoverage(const Band& band, int stride, const ImageBoardDetectorOptions& o,
                  const std::vector<char>& rows, std::vector<double>* best,
                  std::vector<int>* best_delta) {
  best->assign(band.rows, -1.0);
  best_delta->assign(band.rows, 0);
  const uint64_t columns = strideColumns(stride);
  for (int k = 0; k < band.rows; ++k) {
    if (!rows[k]) continue;
    const double side_length = (band.b[k] - band.a[k]).norm();
    for (int delta = -kSlackRows; delta <= kSlackRows; ++delta) {
      const int r = k + delta;
      if (r < 0 || r >= band.rows || !band.allowed[r]) continue;
      const double cov = coverage(band, k, delta, stride, columns, side_length, o);
      if (cov > (*best)[k]) {
        (*best)[k] = cov;
        (*best_delta)[k] = delta;
      }
    }
  }
}

}  // namespace

std::vector<QuadHypothesis> traceFourthSide(const cv::Mat& gray, const CameraModel& camera,
                                            const Target& target,
                                            const ImageBoardDetectorOptions& o, const ThreeSides& u,
                                            double min_gradient) {
  Pencil pencil;
  if (!pencilOf(u, camera.K(), &pencil)) return {};
  Band band = sweepBand(camera, target, o, u, pencil);
  // An edge is the strongest gradient within the refinement's search half width.
  const int ridge = static_cast<int>(std::ceil(o.fine_search_px / kStepPx));
  // Coarse pass: every kCoarseStride-th column of the rows an allowed side may touch (and of
  // their ridge neighbours).
  std::vector<char> near_allowed(band.rows, 0), read(band.rows, 0);
  for (int k = 0; k < band.rows; ++k)
    if (band.allowed[k])
      for (int r = std::max(0, k - kSlackRows - ridge - 1);
           r <= std::min(band.rows - 1, k + kSlackRows + ridge + 1); ++r) {
        read[r] = 1;
        near_allowed[r] |= std::abs(r - k) <= kSlackRows;
      }
  for (int k = 0; k < band.rows; ++k)
    if (read[k] && band.seen[k]) readRow(gray, camera, o, k, 0, kCoarseStride, &band);
  if (band.centre.empty()) return {};
  // An edge sample stands out of the gradient noise of this band (board, background, texture):
  // most of the band is no edge, so the median |gradient| across the sides measures that noise.
  const double threshold = std::max(
      min_gradient, o.edge_snr * kMadToSigma *
                        medianOf(std::vector<double>(band.centre.begin(), band.centre.end())));
  std::vector<double> best;
  std::vector<int> best_delta;
  markEdges(threshold, ridge, near_allowed, 0, kCoarseStride, &band);
  bestCoverage(band, kCoarseStride, o, band.allowed, &best, &best_delta);
  // Fine pass: every column around the rows whose coarse coverage may meet the rule (two
  // binomial sigmas of a coarse estimate below it).
  const int coarse_n = (kSamples + kCoarseStride - 1) / kCoarseStride;
  const double coarse_floor =
      o.min_side_coverage - 2.0 * std::sqrt(0.25 / static_cast<double>(coarse_n));
  const int width = static_cast<int>(std::ceil(kPeakWidthPx / kStepPx));
  // Rows within a peak width of a candidate are scored (a peak there is compared with rows a
  // width further), and read with the far corner's slack.
  const int scored = 2 * width, marked = scored + kSlackRows, reread = marked + ridge + 1;
  std::vector<char> fine(band.rows, 0), to_mark(band.rows, 0);
  for (int k = 0; k < band.rows; ++k) {
    if (best[k] < coarse_floor) continue;
    for (int r = std::max(0, k - reread); r <= std::min(band.rows - 1, k + reread); ++r) {
      if (!band.read_fine[r] && band.seen[r]) {
        for (int first = 1; first < kCoarseStride; ++first)
          readRow(gray, camera, o, r, first, kCoarseStride, &band);
        band.read_fine[r] = 1;
      }
      to_mark[r] |= std::abs(r - k) <= marked;
      fine[r] |= band.allowed[r] && std::abs(r - k) <= scored;
    }
  }
  markEdges(threshold, ridge, to_mark, 0, 1, &band);
  bestCoverage(band, 1, o, fine, &best, &best_delta);
  // Local maxima that meet the side-coverage rule and stand out of their neighbourhood.
  std::vector<int> peaks;
  for (int k = 0; k < band.rows; ++k) {
    if (best[k] < o.min_side_coverage) continue;
    bool peak = true;
    for (int d = 1; d <= width && peak; ++d)
      peak = (k - d < 0 || best[k - d] <= best[k]) && (k + d >= band.rows || best[k + d] < best[k]);
    const double lo =
        std::max(k >= width ? best[k - width] : 0.0, k + width < band.rows ? best[k + width] : 0.0);
    if (peak && best[k] - lo >= kPeakDropShare * o.min_side_coverage) peaks.push_back(k);
  }
  std::sort(peaks.begin(), peaks.end(), [&](int x, int y) { return best[x] > best[y]; });
  std::vector<QuadHypothesis> quads;
  for (int k : peaks) {
    if (static_cast<int>(quads.size()) >= kMaxPeaks) break;
    QuadHypothesis q;
    q.corners = {u.corners[0], u.corners[1], band.b[k + best_delta[k]], band.a[k]};
    q.score = best[k];
    quads.push_back(q);
  }
  return quads;
}

double segmentShareAlong(const std::vector<std::array<Eigen::Vector2d, 2>>& segments_u,
                         const Eigen::Vector2d& p, const Eigen::Vector2d& q, double tolerance_px) {
  const double length = (q - p).norm();
  if (length <= 0) return 0;
  const Eigen::Vector2d dir = (q - p) / length, n(-dir.y(), dir.x());
  std::vector<std::pair<double, double>> spans;
  for (const auto& seg : segments_u) {
    // The part of the segment beside p-q must lie within the tolerance of it (a long scene line
    // may leave it further on).
    const double t0 = dir.dot(seg[0] - p), t1 = dir.dot(seg[1] - p);
    const double lo = std::max(0.0, std::min(t0, t1)), hi = std::min(length, std::max(t0, t1));
    if (hi <= lo) continue;
    const double d0 = n.dot(seg[0] - p), d1 = n.dot(seg[1] - p);
    auto offset = [&](double t) { return d0 + (d1 - d0) * (t - t0) / (t1 - t0); };
    if (std::abs(offset(lo)) <= tolerance_px && std::abs(offset(hi)) <= tolerance_px)
      spans.emplace_back(lo, hi);
  }
  std::sort(spans.begin(), spans.end());
  double covered = 0, end = 0;
  for (const auto& sp : spans) {
    covered += std::max(0.0, sp.second - std::max(sp.first, end));
    end = std::max(end, sp.second);
  }
  return covered / length;
}

}  // namespace image_detection
}  // namespace board_calib
