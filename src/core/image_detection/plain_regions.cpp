// Plain board, region hypotheses: brightness and uniformity regions of a downscaled image,
// their openings when a neighbour of the board's brightness merged with it, the straight sides of
// each region's outline, and the quadrilaterals of its stable regions (a far board in clutter).
#include "plain_internal.h"

#include <opencv2/features2d.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <climits>
#include <cmath>

namespace board_calib {
namespace image_detection {
namespace {

constexpr double kMergeAngleRad =
    0.14;  // ~8 deg: consecutive outline segments this close are one edge
constexpr double kPolygonEpsilon = 0.01;  // outline simplification, fraction of the perimeter
constexpr int kFlatOpeningPx = 11;        // downscaled px, opening of the flat-area proposals
// Openings of a rejected region, fractions of its inradius (a board touching the ceiling band
// merges with it; the band is thinner than the board).
constexpr double kOpeningInradiusFractions[] = {0.33, 0.5};
// The person holding a board is as wide as their shoulders: an opening cuts them off only with a
// radius beyond their half width (a part of one colour or a moving part holds board and person;
// the simulator's person is 0.22 m). The margin keeps the cut clear of the shoulders' width.
constexpr double kHolderHalfWidthM = 0.25;
constexpr double kHolderMargin = 1.25;
// At its inradius an opening leaves nothing of a board but its centre.
constexpr double kMaxOpeningFraction = 0.9;
// Stable regions (stableRegionQuads): OpenCV's MSER delta and variation, and a diversity that
// keeps one of a board's nested thresholds; simplification of the hull to four corners, as a
// fraction of its perimeter; boxes overlapping this much are one region; at most this many.
constexpr int kStableRegionDelta = 5;
constexpr double kStableRegionMaxVariation = 0.25;
constexpr double kStableRegionMinDiversity = 0.5;
constexpr double kQuadEpsilonMin = 0.02, kQuadEpsilonMax = 0.1, kQuadEpsilonStep = 0.01;
constexpr double kSameRegionOverlap = 0.8;
constexpr size_t kMaxStableRegions = 48;

// A downscaled pixel's place at full resolution (`scale` full px per downscaled px; pixel centres
// at integers in both).
Eigen::Vector2d fullResolution(const Eigen::Vector2d& p, double scale) {
  return Eigen::Vector2d((p.array() + 0.5) * scale - 0.5);
}

// Scores one proposed region: a board is large, convex and uniform, and differs from its
// surroundings. Returns false (with the rejection) when it is not board-like.
bool scoreRegion(const std::vector<cv::Point>& contour, const cv::Mat& blurred,
                 const ImageBoardDetectorOptions& o, RegionCandidate* candidate,
                 std::string* rejection) {
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
  const cv::Rect roi = (box + cv::Size(2 * pad, 2 * pad) - cv::Point(pad, pad)) &
                       cv::Rect(0, 0, blurred.cols, blurred.rows);
  cv::Mat region = cv::Mat::zeros(roi.size(), CV_8U);
  cv::drawContours(region, std::vector<std::vector<cv::Point>>{contour}, 0, 255, cv::FILLED,
                   cv::LINE_8, cv::noArray(), INT_MAX, -roi.tl());
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
    *rejection =
        cv::format("region not uniform (texture %.2f > %.2f)", texture, o.max_interior_texture);
    return false;
  }
  candidate->score = area * std::pow(solidity, 4) / (1.0 + texture);
  candidate->contour = std::move(hull);
  return true;
}

int floorDiv(int a, int b) {  // b > 0
  return a >= 0 ? a / b : -((-a + b - 1) / b);
}

// Euclidean distance of every pixel to the nearest zero pixel of `src` (CV_8U): the same float
// values as OpenCV's precise L2 distanceTransform (the square root of the exact integer square),
// at a fraction of its cost: column distances a row at a time (contiguous), then Meijster's lower
// envelope along each row in integers. Without a zero pixel OpenCV's transform is no distance:
// that case stays with OpenCV.
void distanceToZero(const cv::Mat& src, cv::Mat* dist) {
  const int w = src.cols, h = src.rows, inf = w + h;  // beyond any distance inside the image
  cv::Mat g(h, w, CV_32S);
  bool any_zero = false;
  for (int y = 0; y < h; ++y) {
    const uchar* s = src.ptr<uchar>(y);
    int* gy = g.ptr<int>(y);
    const int* above = y > 0 ? g.ptr<int>(y - 1) : nullptr;
    for (int x = 0; x < w; ++x) {
      any_zero |= s[x] == 0;
      gy[x] = s[x] == 0 ? 0 : (above ? std::min(above[x] + 1, inf) : inf);
    }
  }
  if (!any_zero) {
    cv::distanceTransform(src, *dist, cv::DIST_L2, cv::DIST_MASK_PRECISE);
    return;
  }
  for (int y = h - 2; y >= 0; --y) {
    int* gy = g.ptr<int>(y);
    const int* below = g.ptr<int>(y + 1);
    for (int x = 0; x < w; ++x) gy[x] = std::min(gy[x], below[x] + 1);
  }
  cv::Mat d2(h, w, CV_32S);
  std::vector<int> s(w), t(w), g2(w);  // envelope: parabola columns, where each starts
  for (int y = 0; y < h; ++y) {
    const int* gy = g.ptr<int>(y);
    int* out = d2.ptr<int>(y);
    for (int x = 0; x < w; ++x) g2[x] = gy[x] * gy[x];
    auto f = [&g2](int x, int i) { return (x - i) * (x - i) + g2[i]; };
    // A column without a zero pixel (inf) is never the nearest while one with a zero is.
    int first = 0;
    while (gy[first] >= inf) ++first;
    int q = 0;
    s[0] = first;
    t[0] = 0;
    for (int u = first + 1; u < w; ++u) {
      if (gy[u] >= inf) continue;
      while (q >= 0 && f(t[q], s[q]) > f(t[q], u)) --q;
      if (q < 0) {
        q = 0;
        s[0] = u;
      } else {
        const int i = s[q];
        const int start = 1 + floorDiv(u * u - i * i + g2[u] - g2[i], 2 * (u - i));
        if (start < w) {
          ++q;
          s[q] = u;
          t[q] = start;
        }
      }
    }
    for (int u = w - 1; u >= 0; --u) {
      out[u] = f(u, s[q]);
      if (u == t[q]) --q;
    }
  }
  d2.convertTo(*dist, CV_32F);  // exact: the squares stay far below 2^24
  cv::sqrt(*dist, *dist);
}

// Openings of one region by discs of kOpeningInradiusFractions x its inradius (distance
// transforms: fast for any radius); returns the remaining parts large enough to be a board.
// Works on the region's bounding box plus a 1 px frame of background: an opening stays inside
// the region, and the image border still bounds the box where the region touches it.
std::vector<std::vector<cv::Point>> openRegion(const std::vector<cv::Point>& contour, cv::Size size,
                                               double min_area, double extra_fraction = 0.0) {
  std::vector<std::vector<cv::Point>> parts;
  const cv::Rect box =
      (cv::boundingRect(contour) + cv::Size(2, 2) - cv::Point(1, 1)) & cv::Rect(cv::Point(), size);
  cv::Mat mask = cv::Mat::zeros(box.size(), CV_8U);
  cv::drawContours(mask, std::vector<std::vector<cv::Point>>{contour}, 0, 255, cv::FILLED,
                   cv::LINE_8, cv::noArray(), INT_MAX, -box.tl());
  cv::Mat inside, outside;
  distanceToZero(mask, &inside);
  double inradius = 0;
  cv::minMaxLoc(inside, nullptr, &inradius);
  std::vector<double> fractions(std::begin(kOpeningInradiusFractions),
                                std::end(kOpeningInradiusFractions));
  if (extra_fraction > fractions.back()) fractions.push_back(extra_fraction);
  for (const double fraction : fractions) {
    const double radius = fraction * inradius;
    if (radius < 1) continue;
    const cv::Mat core = inside > radius;  // erosion
    // The dilation only reaches radius past the core: its distance transform needs only the
    // core's box grown by more than that (the same distances within radius, far cheaper when a
    // long neighbour made the region's box large).
    const int pad = static_cast<int>(std::ceil(radius)) + 1;
    const cv::Rect grown =
        (cv::boundingRect(core) + cv::Size(2 * pad, 2 * pad) - cv::Point(pad, pad)) &
        cv::Rect(cv::Point(), core.size());
    distanceToZero(255 - core(grown), &outside);
    const cv::Mat opened = outside <= radius;  // dilation of the eroded set
    std::vector<std::vector<cv::Point>> contours;
    cv::findContours(opened, contours, cv::RETR_EXTERNAL, cv::CHAIN_APPROX_NONE,
                     box.tl() + grown.tl());
    for (auto& c : contours)
      if (cv::contourArea(c) >= min_area) parts.push_back(std::move(c));
  }
  return parts;
}

}  // namespace

std::vector<std::vector<cv::Point>> openedParts(const std::vector<cv::Point>& contour,
                                                cv::Size size, double min_area,
                                                double holder_fraction) {
  return openRegion(contour, size, min_area, holder_fraction);
}

double holderOpeningFraction(const Target& target) {
  const double inradius_m = 0.5 * std::min(target.width, target.height);
  if (!(inradius_m > 0)) return 0.0;
  return std::clamp(kHolderMargin * kHolderHalfWidthM / inradius_m, kOpeningInradiusFractions[1],
                    kMaxOpeningFraction);
}

void Segmentation::add(const std::vector<cv::Point>& contour, const ImageBoardDetectorOptions& o,
                       bool keep_rejected) {
  ++proposals;
  RegionCandidate c;
  if (scoreRegion(contour, blurred, o, &c, &last_rejection))
    candidates.push_back(std::move(c));
  else if (keep_rejected)
    rejected.push_back(contour);
}

void Segmentation::sort() {
  std::sort(candidates.begin(), candidates.end(),
            [](const RegionCandidate& a, const RegionCandidate& b) { return a.score > b.score; });
}

// Proposes board regions. Proposals come from brightness (Otsu, both polarities) and uniformity
// (connected low-gradient areas: they separate a board from an equally bright neighbour across
// a faint edge); convexity, uniformity and size decide.
Segmentation segmentBoard(const cv::Mat& small, const ImageBoardDetectorOptions& o,
                          double min_area) {
  Segmentation seg;
  cv::Mat bright, gradient, flat;
  cv::GaussianBlur(small, seg.blurred, cv::Size(5, 5), 0);
  cv::threshold(seg.blurred, bright, 0, 255, cv::THRESH_BINARY | cv::THRESH_OTSU);
  cv::morphologyEx(seg.blurred, gradient, cv::MORPH_GRADIENT, cv::Mat());
  cv::threshold(gradient, flat, o.max_flat_gradient, 255, cv::THRESH_BINARY_INV);
  const cv::Mat kernel = cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(5, 5));
  seg.min_area = min_area > 0 ? min_area : o.min_board_area_fraction * small.total();
  // Flat areas leak into the background through short stretches of low-contrast edge: a larger
  // opening cuts those bridges (the board is far wider than them).
  const cv::Mat wide_kernel =
      cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(kFlatOpeningPx, kFlatOpeningPx));
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

// A board far enough to be small (80-100 px in a 1920 px frame) is neither isolated by the
// frame's global brightness threshold (it joins whatever else has its grey) nor outlined by the
// frame's longest lines (its sides rank past a cluttered scene's few hundred). It is a maximally
// stable extremal region: uniform, and bounded by its own contrast at every threshold near its
// level. Those regions that are convex quadrilaterals become hypotheses; their sides are then
// judged like the weak lines' (rankByEdgeCoverage, the strict corner fit).
std::vector<QuadHypothesis> stableRegionQuads(const cv::Mat& small, const Segmentation& seg,
                                              double sx, const CameraModel& camera,
                                              const ImageBoardDetectorOptions& o, double max_area) {
  // Smallest: a board whose sides all reach min_board_size_px (convexCorners refuses less).
  const double min_area = (o.min_board_size_px / sx) * (o.min_board_size_px / sx);
  if (!(max_area > min_area)) return {};
  // OpenCV's defaults but the diversity: a region nested in one less than this much larger is
  // the same board at another threshold.
  const cv::Ptr<cv::MSER> mser = cv::MSER::create(
      kStableRegionDelta, static_cast<int>(std::ceil(min_area)), static_cast<int>(max_area),
      kStableRegionMaxVariation, kStableRegionMinDiversity);
  std::vector<std::vector<cv::Point>> regions;
  std::vector<cv::Rect> boxes;
  mser->detectRegions(small, regions, boxes);
  struct Quad {
    std::vector<cv::Point> corners;
    cv::Rect box;
    double shape;  // solidity^4 x how well four corners outline the hull
  };
  std::vector<Quad> quads;
  std::vector<int> row_min, row_max;
  std::vector<cv::Point> extremes, hull, corners;
  for (size_t r = 0; r < regions.size(); ++r) {
    const cv::Rect& box = boxes[r];
    if (box.area() < min_area) continue;
    // The hull of a region is the hull of its rows' extreme pixels (a row's pixels lie between).
    row_min.assign(box.height, INT_MAX);
    row_max.assign(box.height, INT_MIN);
    for (const cv::Point& p : regions[r]) {
      const int y = p.y - box.y;
      if (y < 0 || y >= box.height) continue;  // not in its own box: OpenCV's to keep
      row_min[y] = std::min(row_min[y], p.x);
      row_max[y] = std::max(row_max[y], p.x);
    }
    extremes.clear();
    for (int y = 0; y < box.height; ++y)
      if (row_min[y] <= row_max[y]) {
        extremes.emplace_back(row_min[y], box.y + y);
        extremes.emplace_back(row_max[y], box.y + y);
      }
    cv::convexHull(extremes, hull);
    const double hull_area = cv::contourArea(hull);
    if (hull_area < min_area) continue;
    const double solidity = std::min(1.0, static_cast<double>(regions[r].size()) / hull_area);
    if (solidity < o.min_solidity) continue;
    // Four corners at the coarsest simplification that still keeps four (a hand on a corner
    // adds a fifth at the finest).
    for (double eps = kQuadEpsilonMin; eps <= kQuadEpsilonMax + 1e-9; eps += kQuadEpsilonStep) {
      cv::approxPolyDP(hull, corners, eps * cv::arcLength(hull, true), true);
      if (corners.size() <= static_cast<size_t>(kNumEdges)) break;
    }
    if (corners.size() != static_cast<size_t>(kNumEdges)) continue;
    const double fill = hull_area / std::max(1.0, cv::contourArea(corners));
    const double shape = std::pow(solidity, 4) * std::min(fill, 1.0 / fill);
    const cv::Rect quad_box = cv::boundingRect(corners);
    bool same = false;
    for (Quad& q : quads)
      if ((q.box & quad_box).area() > kSameRegionOverlap * (q.box | quad_box).area()) {
        if (shape > q.shape) q = {corners, quad_box, shape};
        same = true;
        break;
      }
    if (!same) quads.push_back({corners, quad_box, shape});
  }
  // Uniform inside and unlike its surroundings, as a board region (scoreRegion) is.
  std::vector<std::pair<double, const Quad*>> ranked;
  for (const Quad& q : quads) {
    RegionCandidate candidate;
    std::string rejection;
    if (!scoreRegion(q.corners, seg.blurred, o, &candidate, &rejection)) continue;
    const double uniformity = candidate.score / std::max(1.0, cv::contourArea(q.corners));
    ranked.emplace_back(q.shape * uniformity, &q);
  }
  std::stable_sort(ranked.begin(), ranked.end(),
                   [](const auto& a, const auto& b) { return a.first > b.first; });
  std::vector<QuadHypothesis> out;
  for (const auto& [score, q] : ranked) {
    if (out.size() >= kMaxStableRegions) break;
    QuadHypothesis h;
    for (int k = 0; k < kNumEdges; ++k)
      h.corners[k] = camera.undistortPixel(
          fullResolution(Eigen::Vector2d(q->corners[k].x, q->corners[k].y), sx));
    out.push_back(h);
  }
  return out;
}

namespace {

// Splits the hull of the board region into straight sides, dropping those along the image border.
std::vector<CoarseEdge> coarseEdges(const std::vector<cv::Point>& hull, double scale,
                                    cv::Size small_size, const ImageBoardDetectorOptions& o,
                                    Eigen::Vector2d* centroid) {
  std::vector<cv::Point> poly;
  cv::approxPolyDP(hull, poly, kPolygonEpsilon * cv::arcLength(hull, true), true);
  const cv::Moments m = cv::moments(hull);
  const Eigen::Vector2d c_small(m.m10 / m.m00, m.m01 / m.m00);
  auto toFull = [scale](const Eigen::Vector2d& p) { return fullResolution(p, scale); };
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
      std::abs(std::remainder(merged.front().angle - merged.back().angle, 2 * M_PI)) <
          kMergeAngleRad) {
    merged.back().b = merged.front().b;
    merged.back().length = (merged.back().b - merged.back().a).norm();
    merged.erase(merged.begin());
  }
  std::vector<CoarseEdge> out;
  for (const auto& e : merged)
    if (e.length >= o.min_edge_length_px) out.push_back(e);
  while (out.size() > static_cast<size_t>(kNumEdges)) {
    auto shortest = std::min_element(
        out.begin(), out.end(),
        [](const CoarseEdge& x, const CoarseEdge& y) { return x.length < y.length; });
    out.erase(shortest);
  }
  return out;
}

}  // namespace

Hypothesis fromRegion(const RegionCandidate& board, double sx, cv::Size small_size,
                      const CameraModel& camera, const ImageBoardDetectorOptions& o) {
  Hypothesis h;
  h.source = kRegionSource;
  for (const auto& p : board.contour)
    h.outline_raw.emplace_back((p.x + 0.5) * sx - 0.5, (p.y + 0.5) * sx - 0.5);
  Eigen::Vector2d centroid;
  h.sides = coarseEdges(board.contour, sx, small_size, o, &centroid);
  h.inside_u = camera.undistortPixel(centroid);
  return h;
}

}  // namespace image_detection
}  // namespace board_calib
