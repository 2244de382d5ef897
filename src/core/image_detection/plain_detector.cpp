// Plain board (PBPC-Cal): board hypotheses from two sources, brightness/uniformity regions on a
// downscaled image and quadrilaterals of long straight edges (LSD segments, line_hypotheses.cpp).
// Each hypothesis's sides are refined at full resolution by sub-pixel gradient peaks searched
// along the edge normal, the lines fitted to those edge pixels after undistortion (a straight edge
// is only straight there); a hypothesis is the board when every visible side shows its edge over
// most of its length, the lines form a convex quadrilateral and the four corners fit a board of
// the declared width and height. The best-supported such hypothesis wins.
#include "detection_internal.h"

#include <Eigen/Eigenvalues>
#include <Eigen/LU>

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <climits>
#include <cmath>

namespace board_calib {
namespace image_detection {
namespace {

constexpr double kProfileStepPx = 0.5;      // spacing of intensity samples along the edge normal
constexpr double kMergeAngleRad = 0.14;     // ~8 deg: consecutive outline segments this close are one edge
constexpr double kPolygonEpsilon = 0.01;    // outline simplification, fraction of the perimeter
constexpr double kWeakPeakFraction = 0.3;   // a gradient peak below this fraction of the median is an outlier
constexpr double kMadToSigma = 1.4826;
constexpr int kFinePasses = 2;
constexpr double kCleanBoardCoverage = 0.9;  // a region board this well evidenced on every side needs no line search
constexpr double kCornerMatchPx = 1e-6;  // a clipped side end this close to its corner is the corner
constexpr double kSquareTolerance = 0.01;  // boards whose width and height differ less are square
constexpr double kMaxCornerExclusionFraction = 0.15;  // of a side, skipped at each end
constexpr double kMaxSamplesPerSide = 240;  // more add nothing to a line fit (errors ~1/sqrt(n) are already ~0.02 px)
constexpr double kPolarityWindowSteps = 8;      // edge polarity is a majority over +-this many samples ...
constexpr double kPolarityWindowFraction = 0.1;  // ... or this fraction of the side, whichever is longer
// The edge gradient is a difference of two samples 1 px apart: its noise is sqrt(2) x the pixel noise.
constexpr double kGradientNoiseGain = 1.41421356;
constexpr double kDuplicateHypothesisFraction = 0.05;  // of the board size: hypotheses this close are one
constexpr int kFlatOpeningPx = 11;          // downscaled px, opening of the flat-area proposals
// Openings of a rejected region, fractions of its inradius (a board touching the ceiling band
// merges with it; the band is thinner than the board).
constexpr double kOpeningInradiusFractions[] = {0.33, 0.5};

double sampleBilinear(const cv::Mat& gray, double x, double y) {
  const int x0 = static_cast<int>(std::floor(x)), y0 = static_cast<int>(std::floor(y));
  const double fx = x - x0, fy = y - y0;
  const uchar* r0 = gray.ptr<uchar>(y0);
  const uchar* r1 = gray.ptr<uchar>(y0 + 1);
  return (1 - fy) * ((1 - fx) * r0[x0] + fx * r0[x0 + 1]) + fy * ((1 - fx) * r1[x0] + fx * r1[x0 + 1]);
}

bool insideImage(const cv::Mat& gray, const Eigen::Vector2d& p, double margin) {
  return p.x() >= margin && p.y() >= margin && p.x() <= gray.cols - 1 - margin && p.y() <= gray.rows - 1 - margin;
}

struct Candidate {
  std::vector<cv::Point> contour;
  double score = 0;
};

// Scores one proposed region: a board is large, convex and uniform, and differs from its
// surroundings. Returns false (with the rejection) when it is not board-like.
bool scoreRegion(const std::vector<cv::Point>& contour, const cv::Mat& blurred, const ImageBoardDetectorOptions& o,
                 Candidate* candidate, std::string* rejection) {
  static const cv::Mat kernel = cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(5, 5));
  const double area = cv::contourArea(contour);
  std::vector<cv::Point> hull;
  cv::convexHull(contour, hull);
  const double solidity = area / std::max(1.0, cv::contourArea(hull));
  if (solidity < o.min_solidity) {
    *rejection = cv::format("region not convex (solidity %.2f < %.2f)", solidity, o.min_solidity);
    return false;
  }
  const cv::Rect box = cv::boundingRect(hull);
  const int pad = 8;
  const cv::Rect roi = (box + cv::Size(2 * pad, 2 * pad) - cv::Point(pad, pad)) & cv::Rect(0, 0, blurred.cols, blurred.rows);
  cv::Mat region = cv::Mat::zeros(roi.size(), CV_8U);
  cv::drawContours(region, std::vector<std::vector<cv::Point>>{contour}, 0, 255, cv::FILLED, cv::LINE_8, cv::noArray(),
                   INT_MAX, -roi.tl());
  cv::Mat interior, around;
  cv::erode(region, interior, kernel, cv::Point(-1, -1), 2);
  cv::dilate(region, around, kernel, cv::Point(-1, -1), 3);
  around -= region;
  if (cv::countNonZero(interior) == 0 || cv::countNonZero(around) == 0) return false;
  const cv::Mat patch = blurred(roi);
  cv::Scalar mean_in, std_in;
  cv::meanStdDev(patch, mean_in, std_in, interior);
  // Contrast as the mean absolute difference of the surroundings from the board level: the
  // background may be brighter on one side and darker on another.
  cv::Mat diff;
  cv::absdiff(patch, cv::Scalar(mean_in[0]), diff);
  const double contrast = cv::mean(diff, around)[0];
  const double texture = std_in[0] / std::max(1.0, contrast);
  if (texture > o.max_interior_texture) {
    *rejection = cv::format("region not uniform (texture %.2f > %.2f)", texture, o.max_interior_texture);
    return false;
  }
  candidate->score = area * std::pow(solidity, 4) / (1.0 + texture);
  candidate->contour = std::move(hull);
  return true;
}

// Openings of one region by discs of kOpeningInradiusFractions x its inradius (distance
// transforms: fast for any radius); returns the remaining parts large enough to be a board.
std::vector<std::vector<cv::Point>> openRegion(const std::vector<cv::Point>& contour, cv::Size size, double min_area) {
  std::vector<std::vector<cv::Point>> parts;
  cv::Mat mask = cv::Mat::zeros(size, CV_8U);
  cv::drawContours(mask, std::vector<std::vector<cv::Point>>{contour}, 0, 255, cv::FILLED);
  cv::Mat inside, outside;
  cv::distanceTransform(mask, inside, cv::DIST_L2, cv::DIST_MASK_PRECISE);
  double inradius = 0;
  cv::minMaxLoc(inside, nullptr, &inradius);
  for (const double fraction : kOpeningInradiusFractions) {
    const double radius = fraction * inradius;
    if (radius < 1) continue;
    const cv::Mat core = inside > radius;  // erosion
    cv::distanceTransform(255 - core, outside, cv::DIST_L2, cv::DIST_MASK_PRECISE);
    const cv::Mat opened = outside <= radius;  // dilation of the eroded set
    std::vector<std::vector<cv::Point>> contours;
    cv::findContours(opened, contours, cv::RETR_EXTERNAL, cv::CHAIN_APPROX_NONE);
    for (auto& c : contours)
      if (cv::contourArea(c) >= min_area) parts.push_back(std::move(c));
  }
  return parts;
}

// Board region proposals on the downscaled image.
struct Segmentation {
  cv::Mat blurred;
  std::vector<Candidate> candidates;                  ///< board-like regions, best first
  std::vector<std::vector<cv::Point>> rejected;       ///< large regions that are not board-like
  int proposals = 0;
  std::string last_rejection = "no region large enough";
  double min_area = 0;

  std::string reason() const {
    return proposals == 0 ? "board not found: no region large enough" : "board not found: " + last_rejection;
  }
  void add(const std::vector<cv::Point>& contour, const ImageBoardDetectorOptions& o, bool keep_rejected) {
    ++proposals;
    Candidate c;
    if (scoreRegion(contour, blurred, o, &c, &last_rejection))
      candidates.push_back(std::move(c));
    else if (keep_rejected)
      rejected.push_back(contour);
  }
  void sort() {
    std::sort(candidates.begin(), candidates.end(), [](const Candidate& a, const Candidate& b) { return a.score > b.score; });
  }
};

// Proposes board regions. Proposals come from brightness (Otsu, both polarities) and uniformity
// (connected low-gradient areas: they separate a board from an equally bright neighbour across
// a faint edge); convexity, uniformity and size decide.
Segmentation segmentBoard(const cv::Mat& small, const ImageBoardDetectorOptions& o) {
  Segmentation seg;
  cv::Mat bright, gradient, flat;
  cv::GaussianBlur(small, seg.blurred, cv::Size(5, 5), 0);
  cv::threshold(seg.blurred, bright, 0, 255, cv::THRESH_BINARY | cv::THRESH_OTSU);
  cv::morphologyEx(seg.blurred, gradient, cv::MORPH_GRADIENT, cv::Mat());
  cv::threshold(gradient, flat, o.max_flat_gradient, 255, cv::THRESH_BINARY_INV);
  const cv::Mat kernel = cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(5, 5));
  seg.min_area = o.min_board_area_fraction * small.total();
  // Flat areas leak into the background through short stretches of low-contrast edge: a larger
  // opening cuts those bridges (the board is far wider than them).
  const cv::Mat wide_kernel = cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(kFlatOpeningPx, kFlatOpeningPx));
  for (const cv::Mat& proposal : {bright, cv::Mat(255 - bright), flat}) {
    const bool is_flat = proposal.data == flat.data;
    cv::Mat mask;
    cv::morphologyEx(proposal, mask, cv::MORPH_OPEN, is_flat ? wide_kernel : kernel);
    // A flat area stops where the blurred edge starts to rise: grow it back to the edge itself.
    if (is_flat) cv::dilate(mask, mask, kernel);
    std::vector<std::vector<cv::Point>> contours;
    cv::findContours(mask, contours, cv::RETR_EXTERNAL, cv::CHAIN_APPROX_NONE);
    for (auto& contour : contours)
      if (cv::contourArea(contour) >= seg.min_area) seg.add(contour, o, !is_flat);
  }
  seg.sort();
  return seg;
}

// Second chance: a board merged with a neighbour of nearly its brightness (the ceiling band
// above a board held high) makes one rejected region; openings of it cut the thinner neighbour
// off and keep the board (corners rounded; the edges are refined at full resolution).
void proposeOpenedRegions(cv::Size size, const ImageBoardDetectorOptions& o, Segmentation* seg) {
  seg->candidates.clear();
  const auto rejected = std::move(seg->rejected);
  seg->rejected.clear();
  for (const auto& contour : rejected)
    for (const auto& part : openRegion(contour, size, seg->min_area)) seg->add(part, o, false);
  seg->sort();
}

struct CoarseEdge {
  Eigen::Vector2d a = Eigen::Vector2d::Zero(), b = Eigen::Vector2d::Zero();  // raw full-resolution px
  double angle = 0;      // outward normal angle
  double length = 0;
  bool a_corner = true, b_corner = true;  // an end at a board corner (not where the image cuts the side)
};

// Splits the hull of the board region into straight sides, dropping those along the image border.
std::vector<CoarseEdge> coarseEdges(const std::vector<cv::Point>& hull, double scale, cv::Size small_size,
                                    const ImageBoardDetectorOptions& o, Eigen::Vector2d* centroid) {
  std::vector<cv::Point> poly;
  cv::approxPolyDP(hull, poly, kPolygonEpsilon * cv::arcLength(hull, true), true);
  const cv::Moments m = cv::moments(hull);
  const Eigen::Vector2d c_small(m.m10 / m.m00, m.m01 / m.m00);
  auto toFull = [scale](const Eigen::Vector2d& p) { return Eigen::Vector2d((p.array() + 0.5) * scale - 0.5); };
  *centroid = toFull(c_small);
  const double border = o.border_margin_px / scale + 1.5;  // small px; the opening erodes ~1 px
  auto onBorder = [&](const cv::Point& p, int side) {
    switch (side) {
      case 0: return p.x <= border;
      case 1: return p.x >= small_size.width - 1 - border;
      case 2: return p.y <= border;
      default: return p.y >= small_size.height - 1 - border;
    }
  };
  std::vector<CoarseEdge> sides;
  const size_t n = poly.size();
  for (size_t i = 0; i < n; ++i) {
    const cv::Point& p = poly[i];
    const cv::Point& q = poly[(i + 1) % n];
    bool along_border = false;
    for (int side = 0; side < 4; ++side) along_border |= onBorder(p, side) && onBorder(q, side);
    if (along_border) {
      sides.push_back(CoarseEdge{});  // placeholder keeps the cyclic order; length 0 = border
      continue;
    }
    CoarseEdge e;
    e.a = toFull(Eigen::Vector2d(p.x, p.y));
    e.b = toFull(Eigen::Vector2d(q.x, q.y));
    e.length = (e.b - e.a).norm();
    const Eigen::Vector3d l = lineThrough(e.a, e.b, *centroid);
    e.angle = std::atan2(l.y(), l.x());
    sides.push_back(e);
  }
  // Merge consecutive, nearly collinear sides (the polygon may split a bowed or notched edge).
  std::vector<CoarseEdge> merged;
  for (const auto& s : sides) {
    if (s.length > 0 && !merged.empty() && merged.back().length > 0) {
      double d = std::abs(std::remainder(s.angle - merged.back().angle, 2 * M_PI));
      if (d < kMergeAngleRad) {
        CoarseEdge& e = merged.back();
        e.b = s.b;
        e.length = (e.b - e.a).norm();
        continue;
      }
    }
    merged.push_back(s);
  }
  if (merged.size() > 1 && merged.front().length > 0 && merged.back().length > 0 &&
      std::abs(std::remainder(merged.front().angle - merged.back().angle, 2 * M_PI)) < kMergeAngleRad) {
    merged.back().b = merged.front().b;
    merged.back().length = (merged.back().b - merged.back().a).norm();
    merged.erase(merged.begin());
  }
  std::vector<CoarseEdge> out;
  for (const auto& e : merged)
    if (e.length >= o.min_edge_length_px) out.push_back(e);
  while (out.size() > static_cast<size_t>(kNumEdges)) {
    auto shortest = std::min_element(out.begin(), out.end(),
                                     [](const CoarseEdge& x, const CoarseEdge& y) { return x.length < y.length; });
    out.erase(shortest);
  }
  return out;
}

struct EdgeFit {
  Eigen::Vector3d line = Eigen::Vector3d::Zero();
  Points2 raw_inliers;
  double rms = 0;
  double span = 0;
  double coverage = 0;         // inlier samples / sample positions inside the image
  double median_strength = 0;  // grey levels per px
  std::string reason;
  bool valid = false;
};

// Total least squares line through points (undistorted px).
Eigen::Vector3d fitLine(const Points2& pts, const std::vector<bool>& use, const Eigen::Vector2d& inside) {
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
  return lineThrough(mean, mean + dir, inside);
}

// Refines one edge: samples along the current (undistorted) line estimate, searches the strongest
// inside-to-outside gradient along the raw-image normal, fits a line to the undistorted peaks.
EdgeFit refineEdge(const cv::Mat& gray, const CameraModel& camera, const CoarseEdge& coarse, const Eigen::Vector2d& inside_u,
                   const ImageBoardDetectorOptions& o, double min_gradient) {
  EdgeFit fit;
  Eigen::Vector2d a = camera.undistortPixel(coarse.a), b = camera.undistortPixel(coarse.b);
  Eigen::Vector3d line = lineThrough(a, b, inside_u);
  // Sign of the intensity change walking outward. It may change along one side (the background
  // is brighter than the board behind one stretch and darker behind another), so it is a local
  // majority: the first pass takes the strongest change of either sign, then each stretch of the
  // side keeps the sign most of its samples showed (an opposite edge beside it is clutter).
  std::vector<double> polarity_t;  // first-pass samples along the side (sorted) ...
  std::vector<int> polarity_sum;   // ... and the prefix sums of their signs
  double polarity_window = 0;
  auto localPolarity = [&](double t) {
    if (polarity_t.empty()) return 0;
    const size_t lo = std::lower_bound(polarity_t.begin(), polarity_t.end(), t - polarity_window) - polarity_t.begin();
    const size_t hi = std::upper_bound(polarity_t.begin(), polarity_t.end(), t + polarity_window) - polarity_t.begin();
    const int sum = polarity_sum[hi] - polarity_sum[lo];
    return sum > 0 ? 1 : (sum < 0 ? -1 : 0);
  };
  for (int pass = 0; pass <= kFinePasses; ++pass) {
    const double half = pass == 0 ? o.coarse_search_px : o.fine_search_px;
    const int steps = static_cast<int>(std::ceil(half / kProfileStepPx)) + 1;
    const Eigen::Vector2d n = line.head<2>();
    // Project the segment ends onto the current line.
    a = a - (n.dot(a) + line.z()) * n;
    b = b - (n.dot(b) + line.z()) * n;
    const double len = (b - a).norm();
    const Eigen::Vector2d dir = (b - a) / std::max(len, 1e-9);
    Points2 pts_u, pts_raw;
    std::vector<double> strength;
    std::vector<int> signs;
    std::vector<double> profile(2 * steps + 1);
    // Corners are rounded by the coarse stage and crowded by the other side: skip their
    // neighbourhood, at most a fraction of a short (far) side.
    const double exclusion = std::min(o.corner_exclusion_px, kMaxCornerExclusionFraction * len);
    // Long sides need no more samples than a line fit can use.
    const double step = std::max(o.sample_step_px, len / kMaxSamplesPerSide);
    int positions = 0;
    std::vector<double> ts;
    const double t_end = len - (coarse.b_corner ? exclusion : 0.0);
    for (double t = coarse.a_corner ? exclusion : 0.0; t <= t_end; t += step) {
      const double polarity = pass == 0 ? 0.0 : localPolarity(t);
      const Eigen::Vector2d xu = a + t * dir;
      const Eigen::Vector2d x = camera.distortPixel(xu);
      Eigen::Vector2d d = camera.distortPixel(xu + n) - x;
      d.normalize();
      if (!insideImage(gray, x - half * d, 1.0) || !insideImage(gray, x + half * d, 1.0) ||
          !insideImage(gray, x - (half + kProfileStepPx) * d, 1.0) ||
          !insideImage(gray, x + (half + kProfileStepPx) * d, 1.0))
        continue;
      ++positions;
      for (int k = -steps; k <= steps; ++k) {
        const Eigen::Vector2d p = x + (k * kProfileStepPx) * d;
        profile[k + steps] = sampleBilinear(gray, p.x(), p.y());
      }
      int best_k = 0;
      double best_g = 0;
      std::vector<double> g(profile.size(), 0.0);
      for (int k = 1; k + 1 < static_cast<int>(profile.size()); ++k) {
        // Derivative across one full pixel (samples at +-0.5 px): robust to noise, unbiased.
        const double raw_g = (profile[k + 1] - profile[k - 1]) / (2 * kProfileStepPx);
        g[k] = polarity != 0.0 ? polarity * raw_g : std::abs(raw_g);
        if (g[k] > best_g) {
          best_g = g[k];
          best_k = k;
        }
      }
      if (best_k <= 1 || best_k + 2 >= static_cast<int>(profile.size()) || best_g < min_gradient) continue;
      const double gm = g[best_k - 1], g0 = g[best_k], gp = g[best_k + 1];
      const double denom = gm - 2 * g0 + gp;
      const double delta = denom < 0 ? std::clamp(0.5 * (gm - gp) / denom, -0.5, 0.5) : 0.0;
      const Eigen::Vector2d edge_raw = x + ((best_k - steps + delta) * kProfileStepPx) * d;
      if (!insideImage(gray, edge_raw, o.border_margin_px)) continue;
      pts_raw.push_back(edge_raw);
      pts_u.push_back(camera.undistortPixel(edge_raw));
      strength.push_back(best_g);
      signs.push_back(profile[best_k + 1] > profile[best_k - 1] ? 1 : -1);
      ts.push_back(t);
    }
    if (pass == 0) {
      polarity_t = ts;
      polarity_sum.assign(1, 0);
      for (int sgn : signs) polarity_sum.push_back(polarity_sum.back() + sgn);
      polarity_window = std::max(kPolarityWindowSteps * step, kPolarityWindowFraction * len);
      for (size_t i = 0; i < signs.size(); ++i)
        if (signs[i] * localPolarity(ts[i]) < 0) strength[i] = 0;  // against its stretch: clutter
    }
    if (static_cast<int>(pts_u.size()) < o.min_edge_points) {
      fit.reason = "too few edge pixels (" + std::to_string(pts_u.size()) + ")";
      fit.valid = false;
      return fit;
    }
    std::vector<double> sorted = strength;
    std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
    const double median_strength = sorted[sorted.size() / 2];
    std::vector<bool> use(pts_u.size());
    for (size_t i = 0; i < pts_u.size(); ++i) use[i] = strength[i] >= kWeakPeakFraction * median_strength;
    // Robust refit: MAD-based threshold, never tighter than the configured inlier distance.
    for (int iter = 0; iter < 3; ++iter) {
      line = fitLine(pts_u, use, inside_u);
      std::vector<double> res;
      for (size_t i = 0; i < pts_u.size(); ++i)
        if (use[i]) res.push_back(std::abs(line.head<2>().dot(pts_u[i]) + line.z()));
      if (res.empty()) break;
      std::nth_element(res.begin(), res.begin() + res.size() / 2, res.end());
      const double thr = std::max(o.edge_inlier_px, 3 * kMadToSigma * res[res.size() / 2]);
      for (size_t i = 0; i < pts_u.size(); ++i)
        use[i] = strength[i] >= kWeakPeakFraction * median_strength &&
                 std::abs(line.head<2>().dot(pts_u[i]) + line.z()) <= thr;
    }
    line = fitLine(pts_u, use, inside_u);
    fit.raw_inliers.clear();
    double sum_sq = 0, tmin = 1e18, tmax = -1e18;
    const Eigen::Vector2d ldir(-line.y(), line.x());
    for (size_t i = 0; i < pts_u.size(); ++i) {
      if (!use[i]) continue;
      const double r = line.head<2>().dot(pts_u[i]) + line.z();
      sum_sq += r * r;
      fit.raw_inliers.push_back(pts_raw[i]);
      tmin = std::min(tmin, ldir.dot(pts_u[i]));
      tmax = std::max(tmax, ldir.dot(pts_u[i]));
    }
    const int count = static_cast<int>(fit.raw_inliers.size());
    fit.rms = count > 0 ? std::sqrt(sum_sq / count) : 0.0;
    fit.coverage = positions > 0 ? static_cast<double>(count) / positions : 0.0;
    fit.median_strength = median_strength;
    fit.span = count > 0 ? tmax - tmin : 0.0;
    fit.line = line;
    if (count < o.min_edge_points) {
      fit.reason = "too few edge inliers (" + std::to_string(count) + ")";
      return fit;
    }
  }
  if (fit.span < o.min_edge_length_px) {
    fit.reason = cv::format("visible edge too short (%.0f px)", fit.span);
  } else if (fit.coverage < o.min_side_coverage) {
    fit.reason = cv::format("edge seen along %.0f %% of its visible length (need %.0f %%)", 100 * fit.coverage,
                            100 * o.min_side_coverage);
  } else if (fit.rms > o.max_edge_rms_px) {
    fit.reason = cv::format("edge not straight (rms %.2f px)", fit.rms);
  } else {
    fit.valid = true;
  }
  return fit;
}

// One board hypothesis: its straight sides (raw px; in cyclic order when there are four) and a
// point inside it (undistorted px).
struct Hypothesis {
  std::vector<CoarseEdge> sides;
  Eigen::Vector2d inside_u = Eigen::Vector2d::Zero();
  Points2 outline_raw;
  const char* source = "";
};

Hypothesis fromRegion(const Candidate& board, double sx, cv::Size small_size, const CameraModel& camera,
                      const ImageBoardDetectorOptions& o) {
  Hypothesis h;
  h.source = "region";
  for (const auto& p : board.contour) h.outline_raw.emplace_back((p.x + 0.5) * sx - 0.5, (p.y + 0.5) * sx - 0.5);
  Eigen::Vector2d centroid;
  h.sides = coarseEdges(board.contour, sx, small_size, o, &centroid);
  h.inside_u = camera.undistortPixel(centroid);
  return h;
}

// Sides of a line quadrilateral, each cut to its part inside the image.
Hypothesis fromQuad(const QuadHypothesis& q, const CameraModel& camera, const ImageBoardDetectorOptions& o) {
  Hypothesis h;
  h.source = "lines";
  h.inside_u = 0.25 * (q.corners[0] + q.corners[1] + q.corners[2] + q.corners[3]);
  for (int s = 0; s < kNumEdges; ++s) {
    Eigen::Vector2d a, b;
    const Eigen::Vector2d& p = q.corners[(s + 3) % 4];
    const Eigen::Vector2d& r = q.corners[s];
    if (!visibleSideInterval(camera, p, r, o.border_margin_px, &a, &b)) continue;
    CoarseEdge e;
    e.a_corner = (a - p).norm() < kCornerMatchPx;
    e.b_corner = (b - r).norm() < kCornerMatchPx;
    e.a = camera.distortPixel(a);
    e.b = camera.distortPixel(b);
    e.length = (b - a).norm();
    const Eigen::Vector3d l = lineThrough(a, b, h.inside_u);
    e.angle = std::atan2(l.y(), l.x());
    h.sides.push_back(e);
    h.outline_raw.push_back(e.a);
    h.outline_raw.push_back(e.b);
  }
  // Clockwise image order (v down) for the cyclic edge naming.
  if (h.sides.size() == static_cast<size_t>(kNumEdges)) {
    const Eigen::Vector2d e1 = q.corners[1] - q.corners[0], e2 = q.corners[2] - q.corners[1];
    if (e1.x() * e2.y() - e1.y() * e2.x() < 0) {
      std::reverse(h.sides.begin(), h.sides.end());
      for (auto& e : h.sides) {
        std::swap(e.a, e.b);
        std::swap(e.a_corner, e.b_corner);
      }
    }
  }
  return h;
}

// Fits the board edges, corners and pose to one hypothesis; false (reason in f) when it is not a
// complete board. `score` is the edge support (px of edge samples along the four sides).
bool fitCandidate(const cv::Mat& gray, const CameraModel& camera, const Target& target, const ImageBoardDetectorOptions& o,
                  const Hypothesis& h, double min_gradient, ImageDetection* out, double* score,
                  double* min_coverage) {
  CameraBoardFeatures& f = out->features;
  ImageDetectionDetails& d = out->details;
  *score = 0;
  d.outline_raw = h.outline_raw;
  const std::vector<CoarseEdge>& sides = h.sides;
  if (sides.size() < 2) {
    f.reason = "board not found: " + std::to_string(sides.size()) + " straight board edge(s) in the outline";
    return false;
  }
  std::vector<double> angles, weights;
  for (const auto& s : sides) {
    angles.push_back(s.angle);
    weights.push_back(s.length);
  }
  const std::vector<int> names = nameEdges(angles, weights, sides.size() == static_cast<size_t>(kNumEdges));
  const Eigen::Vector2d& inside_u = h.inside_u;
  for (int j = 0; j < kNumEdges; ++j) d.edge_reason[j] = "not in the outline (outside the image or along its border)";
  for (size_t k = 0; k < sides.size(); ++k) {
    const int j = names[k];
    if (j < 0) continue;
    const EdgeFit fit = refineEdge(gray, camera, sides[k], inside_u, o, min_gradient);
    f.edge_lines[j] = fit.line;
    f.edge_valid[j] = fit.valid;
    d.edge_points_raw[j] = fit.raw_inliers;
    d.edge_rms_px[j] = fit.rms;
    d.edge_reason[j] = fit.reason;
    if (fit.valid) *score += fit.coverage * sides[k].length;
    *min_coverage = k == 0 ? fit.coverage : std::min(*min_coverage, fit.coverage);
  }
  int valid = 0;
  for (int j = 0; j < kNumEdges; ++j) valid += f.edge_valid[j];
  for (int j = 0; j < kNumEdges; ++j)
    if (f.edge_valid[j] && f.edge_valid[(j + 1) % 4] &&
        !intersectLines(f.edge_lines[j], f.edge_lines[(j + 1) % 4], &f.corners_px[j])) {
      f.reason = std::string("board not found: edges ") + edgeName(j) + " and " + edgeName((j + 1) % 4) + " are parallel";
      return false;
    }
  if (valid < kNumEdges) {
    std::string why;
    for (int j = 0; j < kNumEdges; ++j)
      if (!f.edge_valid[j]) why += std::string(why.empty() ? "" : "; ") + edgeName(j) + ": " + d.edge_reason[j];
    f.reason = "board edges missing (" + std::to_string(valid) + " of 4 valid): " + why;
    return false;
  }
  // The four corners must form a convex quadrilateral in clockwise image order with sides of a
  // usable length; otherwise the edges were mislabelled or belong to something else.
  double perimeter = 0;
  for (int j = 0; j < kNumEdges; ++j) {
    const Eigen::Vector2d e1 = f.corners_px[(j + 1) % 4] - f.corners_px[j];
    perimeter += e1.norm();
    const Eigen::Vector2d e2 = f.corners_px[(j + 2) % 4] - f.corners_px[(j + 1) % 4];
    if (e1.x() * e2.y() - e1.y() * e2.x() <= 0) {
      f.reason = "board not found: edge lines do not form a convex quadrilateral";
      return false;
    }
    if (e1.norm() < o.min_board_size_px) {
      f.reason = cv::format("board too small: side %.0f px", e1.norm());
      return false;
    }
  }
  const auto outer = target.outerCorners();
  const Points3 obj(outer.begin(), outer.end());
  const Points2 img(f.corners_px.begin(), f.corners_px.end());
  PoseFit pose = fitPose(obj, img, f.K, o.pixel_sigma_px);
  if (std::abs(target.width - target.height) > kSquareTolerance * std::max(target.width, target.height)) {
    // A rectangular board held near upright (or turned by ~45 deg) is as close to a diamond with
    // its width on the upper right side as on the upper left: the naming one step round that
    // fits the declared width and height better decides (names shift cyclically, the image
    // order stays).
    const int shift = rotatedNamingShift(f.edge_lines);
    Points2 rotated(kNumEdges);
    for (int k = 0; k < kNumEdges; ++k) rotated[k] = f.corners_px[(k + shift) % kNumEdges];
    const PoseFit alternative = fitPose(obj, rotated, f.K, o.pixel_sigma_px);
    if (alternative.ok && (!pose.ok || alternative.rms_px < pose.rms_px)) {
      pose = alternative;
      auto rotate = [shift](auto& array) {
        auto copy = array;
        for (int k = 0; k < kNumEdges; ++k) array[k] = copy[(k + shift) % kNumEdges];
      };
      rotate(f.edge_lines);
      rotate(f.edge_valid);
      rotate(f.corners_px);
      rotate(d.edge_points_raw);
      rotate(d.edge_rms_px);
      rotate(d.edge_reason);
    }
  }
  if (!pose.ok) {
    f.reason = pose.reason;
    return false;
  }
  f.camera_T_board = pose.camera_T_board;
  f.plane = planeFromPose(pose.camera_T_board);
  f.reprojection_rms_px = pose.rms_px;
  d.pattern_errors_px = pose.errors_px;
  d.pose_covariance = pose.covariance;
  // Corner misfit grows with the board in the image (flex, a slightly wrong declared size).
  const double max_rms = std::min(o.max_plain_corner_rms_px, o.max_plain_corner_rms_fraction * perimeter / kNumEdges);
  if (pose.rms_px > max_rms) {
    f.reason = cv::format("corners do not fit a %.3f x %.3f m board (rms %.2f px > %.2f)", target.width, target.height,
                          pose.rms_px, max_rms);
    return false;
  }
  const Eigen::Vector3d centre = pose.camera_T_board * target.center();
  const double tilt_deg =
      std::acos(std::min(1.0, std::abs(f.plane.normal.dot(centre.normalized())))) * 180.0 / M_PI;
  if (centre.norm() > o.max_board_distance_m) {
    f.reason = cv::format("a %.3f x %.3f m board would be %.1f m away (max %.1f m): another rectangle", target.width,
                          target.height, centre.norm(), o.max_board_distance_m);
    return false;
  }
  if (tilt_deg > o.max_board_tilt_deg) {
    f.reason = cv::format("board turned %.0f deg from the line of sight (max %.0f)", tilt_deg, o.max_board_tilt_deg);
    return false;
  }
  f.found = true;
  return true;
}

}  // namespace

void detectPlain(const cv::Mat& gray, const CameraModel& camera, const Target& target,
                 const ImageBoardDetectorOptions& o, ImageDetection* out) {
  const double scale = std::max(1.0, static_cast<double>(gray.cols) / o.segmentation_width_px);
  cv::Mat small;
  if (scale > 1.0)
    cv::resize(gray, small, cv::Size(static_cast<int>(std::lround(gray.cols / scale)),
                                      static_cast<int>(std::lround(gray.rows / scale))),
               0, 0, cv::INTER_AREA);
  else
    small = gray;
  const double sx = static_cast<double>(gray.cols) / small.cols;
  // Edge pixels must stand out of this image's own noise (sensor, compression, texture).
  const double noise = estimateNoiseSigma(gray);
  const double min_gradient = std::max(o.min_edge_contrast, o.edge_snr * kGradientNoiseGain * noise);
  out->details.noise_sigma = noise;

  // Hypotheses: regions (best score first, then openings of the rejected ones) and quadrilaterals
  // of long straight edges. None is a gate for the others.
  Segmentation seg = segmentBoard(small, o);
  std::vector<Hypothesis> hypotheses;
  for (size_t i = 0; i < seg.candidates.size() && i < static_cast<size_t>(o.max_board_candidates); ++i)
    hypotheses.push_back(fromRegion(seg.candidates[i], sx, small.size(), camera, o));
  const size_t first_regions = hypotheses.size();
  const std::string region_reason = seg.reason();
  proposeOpenedRegions(small.size(), o, &seg);
  for (size_t i = 0; i < seg.candidates.size() && i < static_cast<size_t>(o.max_board_candidates); ++i)
    hypotheses.push_back(fromRegion(seg.candidates[i], sx, small.size(), camera, o));
  const size_t regions = hypotheses.size();
  LineEvidence evidence;
  std::vector<QuadHypothesis> quads;
  bool lines_tried = false;

  // Every hypothesis is tried (a duplicate of an accepted board is skipped); the accepted one with
  // the most edge support wins. When none is a board, report the attempt that got furthest (most
  // valid edges, then the more edge support).
  const ImageDetection fresh = *out;
  ImageDetection best_miss;
  int best_valid = -1;
  double best_miss_score = -1, best_score = -1;
  ImageDetection best_found;
  std::vector<std::array<Eigen::Vector2d, 4>> tried;
  std::vector<std::string> reasons;
  double best_min_coverage = 0;
  for (size_t i = 0;; ++i) {
    if (i == regions && !lines_tried) {
      // Line evidence (the costly part) unless a region already gave a board whose four sides
      // show their edge along nearly all their visible length.
      lines_tried = true;
      if (!(best_score > 0 && best_min_coverage >= kCleanBoardCoverage)) {
        quads = lineQuadHypotheses(gray, camera, o, &evidence);
        for (const auto& q : quads) hypotheses.push_back(fromQuad(q, camera, o));
      }
    }
    if (i >= hypotheses.size()) break;
    if (i >= first_regions && i < regions && best_score > 0) continue;  // openings only when no region was the board
    // The edge support of a hypothesis cannot exceed the length of its sides: skip those that
    // cannot beat the board already accepted.
    double bound = 0;
    for (const auto& side : hypotheses[i].sides) bound += side.length;
    if (bound <= best_score) continue;
    ImageDetection attempt = fresh;
    double score = 0;
    double min_coverage = 0;
    const bool found =
        fitCandidate(gray, camera, target, o, hypotheses[i], min_gradient, &attempt, &score, &min_coverage);
    const CameraBoardFeatures& af = attempt.features;
    std::array<Eigen::Vector2d, 4> corners = af.corners_px;
    if (i >= regions) corners = quads[i - regions].corners;
    if (i >= regions && best_score > 0) {
      // A line quadrilateral on the accepted board adds nothing.
      double worst = 0, size = 0;
      for (int s = 0; s < kNumEdges; ++s) {
        double nearest = 1e18;
        for (int t = 0; t < kNumEdges; ++t) nearest = std::min(nearest, (corners[s] - best_found.features.corners_px[t]).norm());
        worst = std::max(worst, nearest);
        size += (best_found.features.corners_px[(s + 1) % 4] - best_found.features.corners_px[s]).norm() / kNumEdges;
      }
      if (worst < kDuplicateHypothesisFraction * size) continue;
    }
    tried.push_back(corners);
    reasons.push_back(std::string(hypotheses[i].source) + ": " + (found ? "board" : af.reason));
    if (found) {
      if (score > best_score) {
        best_score = score;
        best_min_coverage = min_coverage;
        best_found = std::move(attempt);
      }
      continue;
    }
    int valid = 0;
    for (int j = 0; j < kNumEdges; ++j) valid += af.edge_valid[j];
    if (valid > best_valid || (valid == best_valid && score > best_miss_score)) {
      best_valid = valid;
      best_miss_score = score;
      best_miss = std::move(attempt);
    }
  }
  if (best_score > 0) {
    *out = std::move(best_found);
  } else if (best_valid >= 0) {
    *out = std::move(best_miss);
  } else {
    out->features.reason = hypotheses.empty() && evidence.lines < kNumEdges
                               ? region_reason + cv::format("; %d straight lines from %d segments (need 4)",
                                                            evidence.lines, evidence.segments)
                               : region_reason + cv::format("; no quadrilateral of straight edges among %d lines",
                                                            evidence.lines);
  }
  out->details.segments_raw = std::move(evidence.segments_raw);
  out->details.line_segments = evidence.segments;
  out->details.straight_lines = evidence.lines;
  out->details.line_quads = evidence.quads;
  out->details.hypotheses_px = std::move(tried);
  out->details.hypothesis_reasons = std::move(reasons);
  out->details.noise_sigma = noise;
}

}  // namespace image_detection
}  // namespace board_calib
