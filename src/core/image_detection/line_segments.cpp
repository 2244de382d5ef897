// The line stage of the plain detector (as PBPC-Cal does with LSD): segments from the line
// segment detector (line_segment_detector.cpp) on a downscaled image, merged in undistorted pixels
// into long straight lines of either polarity.
#include "line_internal.h"

#include <Eigen/Eigenvalues>

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>

namespace board_calib {
namespace image_detection {
namespace {

constexpr double kMinSegmentPx = 5.0;       // LSD-scale px: shorter segments are texture, not edges
constexpr double kSegmentEndSigmaPx = 0.7;  // LSD-scale px, endpoint noise of a segment
constexpr double kMergeSigmas = 3.0;        // angle tolerance of a merge, in endpoint-noise sigmas
constexpr double kMinMergeAngleRad = 0.02;  // ~1 deg: floor of that tolerance (long segments)
constexpr double kMaxMergeAngleRad = 0.10;  // ~6 deg: cap (short segments)
constexpr double kMergeOffsetPx = 3.5;      // full-res px: a held board bows ~3 px
// The faint-line search's q: the rounding bound of a gradient component, or this many sigmas of
// its noise if more.
constexpr double kRoundingQuantization = 1.0;
constexpr double kFaintNoiseSigmas = 3.0;
// A bound less than a quarter lower reaches few fainter edges for the cost of a second line
// search (the simulator's street, noise 1.5 at 1440 px: q 1.97, +11 ms per frame for no board).
constexpr double kFaintQuantizationShare = 0.75;
constexpr double kCosRoundingMargin = 1e-9;  // far above the rounding of a cosine near 1

// Segment ends this far from a line still lie on it: a held board's bow, or the ends' noise.
double mergeOffsetPx(double end_sigma) { return std::max(kMergeOffsetPx, 2.0 * end_sigma); }

// LSD segments of the downscaled image, in undistorted full-resolution px, longest first.
// `scale`: full-resolution px per LSD px.
std::vector<Member> detectSegments(const cv::Mat& gray, const CameraModel& camera,
                                   const ImageBoardDetectorOptions& o, double quantization,
                                   LineEvidence* evidence, double* scale) {
  *scale = lineDetectionScale(o, gray.cols);
  PlainStageTimes times;
  double start = threadCpuMs();
  cv::Mat small;
  if (*scale > 1.0)
    cv::resize(gray, small,
               cv::Size(static_cast<int>(std::lround(gray.cols / *scale)),
                        static_cast<int>(std::lround(gray.rows / *scale))),
               0, 0, cv::INTER_AREA);
  else
    small = gray;
  const double sx = static_cast<double>(gray.cols) / small.cols,
               sy = static_cast<double>(gray.rows) / small.rows;
  times.line_resize_ms = msSince(start);
  start = threadCpuMs();
  // LSD's region growing, no internal rescale (done above, by area averaging, which also lowers
  // the noise).
  const std::vector<cv::Vec4f> raw_segments = lineSegments(small, quantization);
  times.lsd_ms = msSince(start);
  start = threadCpuMs();

  std::vector<Member> segments;
  for (const auto& s : raw_segments) {
    const double len_small = std::hypot(s[2] - s[0], s[3] - s[1]);
    if (len_small < kMinSegmentPx) continue;
    const Eigen::Vector2d a_raw((s[0] + 0.5) * sx - 0.5, (s[1] + 0.5) * sy - 0.5);
    const Eigen::Vector2d b_raw((s[2] + 0.5) * sx - 0.5, (s[3] + 0.5) * sy - 0.5);
    Member m{camera.undistortPixel(a_raw), camera.undistortPixel(b_raw), 0};
    if (evidence) {
      evidence->segments_raw.push_back({a_raw, b_raw});
      evidence->segments_u.push_back({m.a, m.b});
    }
    m.length = (m.b - m.a).norm();
    if (m.length > 0) segments.push_back(m);
  }
  std::sort(segments.begin(), segments.end(),
            [](const Member& x, const Member& y) { return x.length > y.length; });
  times.undistort_ms = msSince(start);
  if (evidence) {
    evidence->segments = static_cast<int>(segments.size());
    evidence->times += times;
  }
  return segments;
}

// Greedy merge, longest first: a segment joins a line when its direction agrees within its own
// endpoint noise and both its ends lie within the bow of a held board. Returns the lines with
// enough support, most supported first (past the first options.max_lines, those ending at a
// corner first), at most max_lines (a floor or ceiling has many longer than the board).
std::vector<MergedLine> mergeSegments(const std::vector<Member>& segments, double end_sigma,
                                      const ImageBoardDetectorOptions& o, int max_lines) {
  std::vector<MergedLine> lines;
  const double max_offset = mergeOffsetPx(end_sigma);
  for (const Member& s : segments) {
    const Eigen::Vector2d d = (s.b - s.a) / s.length;
    const double angle_tol = std::clamp(kMergeSigmas * std::sqrt(2.0) * end_sigma / s.length,
                                        kMinMergeAngleRad, kMaxMergeAngleRad);
    // The angle test on |cos| first (no acos): acos only where rounding could tip it.
    const double cos_tol = std::cos(angle_tol);
    MergedLine* host = nullptr;
    for (auto& l : lines) {
      const double c = std::abs(d.dot(l.dir));
      if (c < cos_tol - kCosRoundingMargin) continue;
      if (c <= cos_tol + kCosRoundingMargin && angleBetweenLines(d, l.dir) > angle_tol) continue;
      if (std::abs(l.offset(s.a)) > max_offset || std::abs(l.offset(s.b)) > max_offset) continue;
      host = &l;
      break;
    }
    if (host) {
      host->members.push_back(s);
      host->refit();
    } else {
      MergedLine l;
      l.point = s.a;
      l.dir = d;
      l.members.push_back(s);
      l.refit();
      lines.push_back(std::move(l));
    }
  }
  const double min_support = std::max(o.min_edge_length_px, 0.5 * o.min_board_size_px);
  lines.erase(std::remove_if(lines.begin(), lines.end(),
                             [&](const MergedLine& l) { return l.support < min_support; }),
              lines.end());
  std::sort(lines.begin(), lines.end(),
            [](const MergedLine& x, const MergedLine& y) { return x.support > y.support; });
  rankLinesEndingAtCorners(&lines, static_cast<size_t>(std::max(0, o.max_lines)), end_sigma);
  if (lines.size() > static_cast<size_t>(max_lines)) lines.resize(max_lines);
  return lines;
}

}  // namespace

double lineDetectionScale(const ImageBoardDetectorOptions& o, int image_width) {
  if (o.line_detection_width_px <= 0) return 1.0;
  return std::max(1.0, static_cast<double>(image_width) / o.line_detection_width_px);
}

void MergedLine::refit() {
  double w = 0;
  Eigen::Vector2d mean = Eigen::Vector2d::Zero();
  for (const auto& m : members)
    for (const Eigen::Vector2d& p : {m.a, m.b, Eigen::Vector2d(0.5 * (m.a + m.b))}) {
      mean += m.length * p;
      w += m.length;
    }
  mean /= w;
  Eigen::Matrix2d cov = Eigen::Matrix2d::Zero();
  for (const auto& m : members)
    for (const Eigen::Vector2d& p : {m.a, m.b, Eigen::Vector2d(0.5 * (m.a + m.b))})
      cov += m.length * (p - mean) * (p - mean).transpose();
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig(cov);
  Eigen::Vector2d d = eig.eigenvectors().col(1);
  if (d.dot(dir) < 0) d = -d;
  point = mean;
  dir = d.normalized();
  intervals.clear();
  for (const auto& m : members) {
    const double ta = along(m.a), tb = along(m.b);
    intervals.emplace_back(std::min(ta, tb), std::max(ta, tb));
  }
  std::sort(intervals.begin(), intervals.end());
  std::vector<std::pair<double, double>> merged;
  for (const auto& iv : intervals) {
    if (!merged.empty() && iv.first <= merged.back().second)
      merged.back().second = std::max(merged.back().second, iv.second);
    else
      merged.push_back(iv);
  }
  intervals = std::move(merged);
  support = 0;
  for (const auto& iv : intervals) support += iv.second - iv.first;
  t_min = intervals.front().first;
  t_max = intervals.back().second;
}

LineSet detectLines(const cv::Mat& gray, const CameraModel& camera,
                    const ImageBoardDetectorOptions& o, LineEvidence* evidence, int max_lines,
                    double quantization) {
  double scale = 1.0;
  const std::vector<Member> segments =
      detectSegments(gray, camera, o, quantization, evidence, &scale);
  LineSet set;
  set.end_sigma_px = kSegmentEndSigmaPx * scale;
  const double start = threadCpuMs();
  set.lines = mergeSegments(segments, set.end_sigma_px, o, max_lines);
  if (evidence) evidence->times.merge_ms += msSince(start);
  return set;
}

double faintLineQuantization(const ImageBoardDetectorOptions& o, int image_width,
                             double noise_sigma) {
  if (o.line_detection_width_px <= 0 || !(noise_sigma >= 0)) return 0.0;
  // The area average divides the noise by the scale; a 2x2 gradient component has the pixel
  // sigma. The rounding of the averaged grey levels bounds the error at 1 (LSD's raw q is twice
  // that).
  const double noise = noise_sigma / lineDetectionScale(o, image_width);
  const double q = std::max(kRoundingQuantization, kFaintNoiseSigmas * noise);
  return q <= kFaintQuantizationShare * kLsdRawQuantization ? q : 0.0;
}

double sameLineTolerancePx(const ImageBoardDetectorOptions& o, int image_width) {
  if (o.line_detection_width_px <= 0) return kMergeOffsetPx;
  return mergeOffsetPx(kSegmentEndSigmaPx * lineDetectionScale(o, image_width));
}

std::vector<std::array<Eigen::Vector2d, 2>> sceneLines(const cv::Mat& gray,
                                                       const CameraModel& camera,
                                                       const ImageBoardDetectorOptions& o) {
  if (o.line_detection_width_px <= 0) return {};
  std::vector<std::array<Eigen::Vector2d, 2>> out;
  for (const MergedLine& l :
       detectLines(gray, camera, o, nullptr, std::max(o.max_lines, o.max_lines_static_scene)).lines)
    out.push_back(l.ends());
  return out;
}

}  // namespace image_detection
}  // namespace board_calib
