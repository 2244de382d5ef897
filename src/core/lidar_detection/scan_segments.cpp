#include "scan_segments.h"

#include <board_calib/core/common/statistics.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <numeric>

namespace board_calib {
namespace lidar_detail {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kElevationBinsPerGap = 3.0;  // histogram bins per elevation gap
constexpr double kMaxGapSteps = 4.0;  // missing returns (dropouts) a run bridges, in column steps
constexpr double kMaxRangeSlope =
    3.0;  // range change per arc length within a run (surfaces to ~70 deg grazing)
constexpr double kJumpSigmas = 4.0;  // range noise never splits a run
constexpr double kLinkMarginSteps =
    2.0;  // azimuth overlap margin between segments of adjacent lines
// Of a segment's points within the band of a region's plane.
constexpr double kMinInPlaneFraction = 0.7;
// Seed triples: untrimmed RMS bound before the trimmed fit.
constexpr double kUntrimmedRmsFactor = 4.0;

struct Segment {
  int line = 0;
  std::vector<int> points;
  double az_lo = 0, az_hi = 0;  // rad
  double step = 0;              // median azimuth step, rad
  int region = -1;
  PlaneStats stats;
};

// Renumber line ids bottom-up by their mean elevation (rings and rows come in either order).
void rankByElevation(const std::vector<Eigen::Vector3d>& points, std::vector<int>* line) {
  if (line->empty()) return;
  const int lo = *std::min_element(line->begin(), line->end()),
            hi = *std::max_element(line->begin(), line->end());
  std::vector<std::pair<double, int>> sums(static_cast<size_t>(hi - lo + 1), {0.0, 0});
  // One point per line in every few gives its elevation well enough (beams are fixed).
  constexpr size_t kStride = 7;
  for (size_t i = 0; i < points.size(); i += kStride) {
    auto& s = sums[static_cast<size_t>((*line)[i] - lo)];
    s.first += points[i].z() / std::max(1e-9, std::hypot(points[i].x(), points[i].y()));
    ++s.second;
  }
  for (size_t i = 0; i < points.size(); ++i) {  // lines the stride missed
    auto& s = sums[static_cast<size_t>((*line)[i] - lo)];
    if (s.second == 0) {
      s.first = points[i].z() / std::max(1e-9, std::hypot(points[i].x(), points[i].y()));
      s.second = 1;
    }
  }
  std::vector<std::pair<double, int>> order;
  for (size_t k = 0; k < sums.size(); ++k)
    if (sums[k].second > 0) order.emplace_back(sums[k].first / sums[k].second, static_cast<int>(k));
  std::sort(order.begin(), order.end());
  std::vector<int> rank(sums.size(), 0);
  for (size_t k = 0; k < order.size(); ++k)
    rank[static_cast<size_t>(order[k].second)] = static_cast<int>(k);
  for (auto& l : *line) l = rank[static_cast<size_t>(l - lo)];
}

// Ascending azimuth. Drivers emit each line in firing order (azimuth monotonic, one wrap at
// +-pi), so a rotation (and a reversal for clockwise spin) usually replaces the sort.
void sortByAzimuth(std::vector<std::pair<double, int>>* pts) {
  auto& v = *pts;
  const size_t n = v.size();
  if (n < 2) return;
  size_t up = 0, down = 0, wrap_up = n, wrap_down = n;
  for (size_t k = 1; k < n; ++k) {
    if (v[k].first > v[k - 1].first) {
      ++up;
      wrap_up = k;
    } else if (v[k].first < v[k - 1].first) {
      ++down;
      wrap_down = k;
    }
  }
  if (down <= 1) {  // ascending with at most one wrap
    if (down == 1 && v.front().first >= v.back().first)
      std::rotate(v.begin(), v.begin() + static_cast<long>(wrap_down), v.end());
    if (down == 0 || v.front().first >= v.back().first || std::is_sorted(v.begin(), v.end())) {
      if (std::is_sorted(v.begin(), v.end())) return;
    }
  } else if (up <= 1) {  // descending with at most one wrap
    if (up == 1 && v.front().first <= v.back().first)
      std::rotate(v.begin(), v.begin() + static_cast<long>(wrap_up), v.end());
    std::reverse(v.begin(), v.end());
    if (std::is_sorted(v.begin(), v.end())) return;
  }
  std::sort(v.begin(), v.end());
}

}  // namespace

std::vector<int> scanLinesOf(const LidarCloud& cloud, const std::vector<int>& cloud_index,
                             const std::vector<Eigen::Vector3d>& points, double elevation_gap_rad,
                             std::string* source) {
  std::vector<int> line(points.size(), 0);
  bool rings = cloud.has_ring;
  for (size_t i = 0; i < points.size() && rings; ++i)
    rings = cloud.points[cloud_index[i]].ring >= 0;
  if (rings || (cloud.organized() && cloud.width > 0)) {
    *source = rings ? "ring" : "row";
    for (size_t i = 0; i < points.size(); ++i)
      line[i] = rings ? cloud.points[cloud_index[i]].ring : cloud_index[i] / cloud.width;
    rankByElevation(points, &line);
    return line;
  }
  // Elevation histogram: occupied bins separated by more than the gap start a new beam.
  *source = "elevation";
  const double bin = elevation_gap_rad / kElevationBinsPerGap;
  const int bins = static_cast<int>(std::ceil(kPi / bin)) + 1;
  std::vector<int> count(static_cast<size_t>(bins), 0), bin_of(points.size());
  for (size_t i = 0; i < points.size(); ++i) {
    const double el = std::atan2(points[i].z(), std::hypot(points[i].x(), points[i].y()));
    bin_of[i] = std::clamp(static_cast<int>((el + kPi / 2) / bin), 0, bins - 1);
    ++count[static_cast<size_t>(bin_of[i])];
  }
  std::vector<int> id(static_cast<size_t>(bins), -1);
  int current = -1, last = -1000000;
  for (int b = 0; b < bins; ++b) {
    if (!count[static_cast<size_t>(b)]) continue;
    if ((b - last) * bin > elevation_gap_rad) ++current;
    id[static_cast<size_t>(b)] = current;
    last = b;
  }
  for (size_t i = 0; i < points.size(); ++i) line[i] = id[static_cast<size_t>(bin_of[i])];
  return line;
}

std::vector<double> lineGaps(const std::vector<Eigen::Vector3d>& points,
                             const std::vector<int>& line) {
  if (points.empty()) return {};
  const int lines = *std::max_element(line.begin(), line.end()) + 1;
  std::vector<double> sum(static_cast<size_t>(lines), 0.0), gap(static_cast<size_t>(lines), kPi);
  std::vector<int> n(static_cast<size_t>(lines), 0);
  constexpr size_t kStride = 7;  // beams have fixed elevations: a sample suffices
  for (size_t i = 0; i < points.size(); i += (n[static_cast<size_t>(line[i])] < 3 ? 1 : kStride)) {
    sum[static_cast<size_t>(line[i])] +=
        std::atan2(points[i].z(), std::hypot(points[i].x(), points[i].y()));
    ++n[static_cast<size_t>(line[i])];
  }
  int prev = -1;
  for (int l = 0; l < lines; ++l) {
    if (!n[static_cast<size_t>(l)]) continue;
    if (prev >= 0) {
      const double g = sum[static_cast<size_t>(l)] / n[static_cast<size_t>(l)] -
                       sum[static_cast<size_t>(prev)] / n[static_cast<size_t>(prev)];
      gap[static_cast<size_t>(l)] = std::min(gap[static_cast<size_t>(l)], g);
      gap[static_cast<size_t>(prev)] = std::min(gap[static_cast<size_t>(prev)], g);
    }
    prev = l;
  }
  return gap;
}

namespace {

// Segments of every scan line and each line's elevation.
struct LineSegments {
  std::vector<Segment> segments;
  std::vector<std::vector<int>> of_line;   // line -> segment ids
  std::vector<double> line_elevation;      // rad
  std::vector<std::vector<int>> down, up;  // segment -> linked segments on the adjacent lines
};

// The runs of one scan line (points in azimuth order) that stand in front of their
// surroundings and are no wider than a board.
void addRunsOfLine(const std::vector<Eigen::Vector3d>& points, int l,
                   std::vector<std::pair<double, int>> pts, const SegmentOptions& o,
                   LineSegments* out) {
  sortByAzimuth(&pts);
  const auto& p0 = points[static_cast<size_t>(pts[pts.size() / 2].second)];
  out->line_elevation[static_cast<size_t>(l)] = std::atan2(p0.z(), std::hypot(p0.x(), p0.y()));
  std::vector<double> steps;
  steps.reserve(pts.size());
  for (size_t k = 1; k < pts.size(); ++k)
    if (pts[k].first > pts[k - 1].first) steps.push_back(pts[k].first - pts[k - 1].first);
  const double step = std::max(medianOf(steps), 1e-5);
  std::vector<double> range(pts.size());
  for (size_t k = 0; k < pts.size(); ++k)
    range[k] = points[static_cast<size_t>(pts[k].second)].norm();
  // In front of its surroundings: the neighbours beyond a range jump are farther (a gap in
  // azimuth means no return there, which counts as far).
  auto farther = [&](size_t inside, long outside) {
    if (outside < 0 || outside >= static_cast<long>(pts.size())) return true;
    const double daz = std::abs(pts[static_cast<size_t>(outside)].first - pts[inside].first);
    return daz > kMaxGapSteps * step || range[static_cast<size_t>(outside)] > range[inside];
  };
  size_t begin = 0;
  for (size_t k = 1; k <= pts.size(); ++k) {
    bool split = k == pts.size();
    if (!split) {
      const double daz = pts[k].first - pts[k - 1].first;
      const double jump = std::abs(range[k] - range[k - 1]);
      split = daz > kMaxGapSteps * step ||
              jump > std::max(kJumpSigmas * o.range_noise_m, kMaxRangeSlope * range[k] * daz);
    }
    if (!split) continue;
    const size_t end = k;  // run [begin, end)
    const bool front =
        farther(begin, static_cast<long>(begin) - 1) && farther(end - 1, static_cast<long>(end));
    // Width across the view: the chord would miss a whole ring on the ground (it closes on
    // itself) and a path length sums the range noise.
    const double az_span = pts[end - 1].first - pts[begin].first;
    const double chord =
        2.0 * std::min(range[begin], range[end - 1]) * std::sin(0.5 * std::min(az_span, kPi));
    if (end - begin >= 2 && front && az_span < kPi && chord <= o.max_length_m) {
      Segment seg;
      seg.line = l;
      seg.az_lo = pts[begin].first;
      seg.az_hi = pts[end - 1].first;
      seg.step = step;
      for (size_t q = begin; q < end; ++q) {
        seg.points.push_back(pts[q].second);
        seg.stats.add(points[static_cast<size_t>(pts[q].second)]);
      }
      out->of_line[static_cast<size_t>(l)].push_back(static_cast<int>(out->segments.size()));
      out->segments.push_back(std::move(seg));
    }
    begin = k;
  }
}

LineSegments splitIntoSegments(const std::vector<Eigen::Vector3d>& points,
                               const std::vector<int>& line, int lines, const SegmentOptions& o) {
  LineSegments out;
  out.of_line.resize(static_cast<size_t>(lines));
  out.line_elevation.assign(static_cast<size_t>(lines), 0.0);
  // Points of each line in azimuth order.
  std::vector<std::vector<std::pair<double, int>>> by_line(static_cast<size_t>(lines));
  for (size_t i = 0; i < points.size(); ++i)
    by_line[static_cast<size_t>(line[i])].emplace_back(std::atan2(points[i].y(), points[i].x()),
                                                       static_cast<int>(i));
  for (int l = 0; l < lines; ++l)
    if (by_line[static_cast<size_t>(l)].size() >= 2)
      addRunsOfLine(points, l, std::move(by_line[static_cast<size_t>(l)]), o, &out);
  // Links between segments of adjacent lines that overlap in azimuth.
  out.down.resize(out.segments.size());
  out.up.resize(out.segments.size());
  for (int l = 0; l + 1 < lines; ++l) {
    for (int a : out.of_line[static_cast<size_t>(l)])
      for (int b : out.of_line[static_cast<size_t>(l + 1)]) {
        const Segment& sa = out.segments[static_cast<size_t>(a)];
        const Segment& sb = out.segments[static_cast<size_t>(b)];
        const double margin = kLinkMarginSteps * std::max(sa.step, sb.step);
        if (sa.az_hi + margin < sb.az_lo || sb.az_hi + margin < sa.az_lo) continue;
        out.up[static_cast<size_t>(a)].push_back(b);
        out.down[static_cast<size_t>(b)].push_back(a);
      }
  }
  return out;
}

// Planar regions grown over linked segments, largest segments first.
class RegionGrower {
 public:
  RegionGrower(const std::vector<Eigen::Vector3d>& points, LineSegments* ls,
               const SegmentOptions& o)
      : points_(points), ls_(*ls), seg_(ls->segments), o_(o) {}

  // The region seeded at segment s, or false when it has no flat seed or is no plane.
  bool grow(int s, int id, SegmentRegion* r) {
    const std::vector<int> seed = seedTriple(s);
    if (seed.empty()) return false;
    std::vector<int> members = seed;
    for (int k : seed) seg_[static_cast<size_t>(k)].region = id;
    PlaneFit plane = trimmedFit(seed);
    PlaneStats stats;
    std::vector<int> region_points;
    for (int k : seed) addInPlane(k, plane, &stats, &region_points);
    plane = fitPlane(stats);
    for (size_t head = 0; head < members.size(); ++head) {
      const int cur = members[head];
      for (const auto* links :
           {&ls_.down[static_cast<size_t>(cur)], &ls_.up[static_cast<size_t>(cur)]})
        for (int nb : *links) {
          Segment& seg = seg_[static_cast<size_t>(nb)];
          if (seg.region >= 0 || !fitsPlane(seg, plane)) continue;
          seg.region = id;
          members.push_back(nb);
          addInPlane(nb, plane, &stats, &region_points);
          plane = fitPlane(stats);
        }
    }
    if (std::sqrt(plane.eigenvalues[0]) > o_.max_rms_m) return false;
    r->points = std::move(region_points);
    return describe(members, r);
  }

 private:
  // A segment lies on a plane when most of its points do: its ends may be mixed returns that
  // blend the board with what is behind it. Only the points within the band join a region.
  bool inPlane(int i, const PlaneFit& f) const {
    return std::abs(f.normal().dot(points_[static_cast<size_t>(i)]) - f.offset()) <=
           o_.plane_band_m;
  }
  bool fitsPlane(const Segment& seg, const PlaneFit& f) const {
    int in = 0;
    for (int i : seg.points) in += inPlane(i, f);
    return in >= 2 && in >= kMinInPlaneFraction * static_cast<double>(seg.points.size());
  }
  PlaneFit trimmedFit(const std::vector<int>& segs) const {
    PlaneStats all;
    for (int k : segs) all.add(seg_[static_cast<size_t>(k)].stats);
    PlaneFit f = fitPlane(all);
    for (int round = 0; round < 2; ++round) {
      PlaneStats s;
      for (int k : segs)
        for (int i : seg_[static_cast<size_t>(k)].points)
          if (inPlane(i, f)) s.add(points_[static_cast<size_t>(i)]);
      if (s.n < 3) break;
      f = fitPlane(s);
    }
    return f;
  }
  void addInPlane(int k, const PlaneFit& plane, PlaneStats* stats, std::vector<int>* pts) const {
    for (int i : seg_[static_cast<size_t>(k)].points)
      if (inPlane(i, plane)) {
        stats->add(points_[static_cast<size_t>(i)]);
        pts->push_back(i);
      }
  }
  // Segment s with one unassigned neighbour below and one above: the flattest triple.
  std::vector<int> seedTriple(int s) const {
    double best_rms = std::numeric_limits<double>::infinity();
    std::vector<int> seed;
    for (int a : ls_.down[static_cast<size_t>(s)]) {
      if (seg_[static_cast<size_t>(a)].region >= 0) continue;
      for (int b : ls_.up[static_cast<size_t>(s)]) {
        if (seg_[static_cast<size_t>(b)].region >= 0) continue;
        const std::vector<int> triple = {a, s, b};
        // Cheap test first: the untrimmed fit from the segments' sums. A few mixed returns at
        // the runs' ends raise its RMS, not by a factor kUntrimmedRmsFactor.
        PlaneStats all = seg_[static_cast<size_t>(a)].stats;
        all.add(seg_[static_cast<size_t>(s)].stats);
        all.add(seg_[static_cast<size_t>(b)].stats);
        if (std::sqrt(fitPlane(all).eigenvalues[0]) > kUntrimmedRmsFactor * o_.max_rms_m) continue;
        const PlaneFit f = trimmedFit(triple);
        const double rms = std::sqrt(f.eigenvalues[0]);
        if (rms < best_rms && rms <= o_.max_rms_m &&
            std::all_of(triple.begin(), triple.end(),
                        [&](int k) { return fitsPlane(seg_[static_cast<size_t>(k)], f); })) {
          best_rms = rms;
          seed = triple;
        }
      }
    }
    return seed;
  }
  // Lines, column and line steps of a region; false with fewer lines than asked.
  bool describe(const std::vector<int>& members, SegmentRegion* r) const {
    std::vector<int> region_lines;
    std::vector<double> steps;
    for (int k : members) {
      const Segment& seg = seg_[static_cast<size_t>(k)];
      region_lines.push_back(seg.line);
      steps.push_back(seg.step);
    }
    std::sort(region_lines.begin(), region_lines.end());
    region_lines.erase(std::unique(region_lines.begin(), region_lines.end()), region_lines.end());
    r->lines = static_cast<int>(region_lines.size());
    if (r->lines < o_.min_lines) return false;
    std::vector<double> gaps;
    for (size_t k = 1; k < region_lines.size(); ++k)
      gaps.push_back(ls_.line_elevation[static_cast<size_t>(region_lines[k])] -
                     ls_.line_elevation[static_cast<size_t>(region_lines[k - 1])]);
    r->column_step_rad = medianOf(steps);
    r->line_step_rad = medianOf(gaps);
    return true;
  }

  const std::vector<Eigen::Vector3d>& points_;
  const LineSegments& ls_;
  std::vector<Segment>& seg_;
  const SegmentOptions& o_;
};

}  // namespace

std::vector<SegmentRegion> segmentRegions(const std::vector<Eigen::Vector3d>& points,
                                          const std::vector<int>& line, const SegmentOptions& o) {
  std::vector<SegmentRegion> out;
  if (points.empty()) return out;
  const int lines = *std::max_element(line.begin(), line.end()) + 1;
  LineSegments ls = splitIntoSegments(points, line, lines, o);
  std::vector<int> order(ls.segments.size());
  std::iota(order.begin(), order.end(), 0);
  std::sort(order.begin(), order.end(), [&](int a, int b) {
    return ls.segments[static_cast<size_t>(a)].points.size() >
           ls.segments[static_cast<size_t>(b)].points.size();
  });
  RegionGrower grower(points, &ls, o);
  for (int s : order) {
    if (ls.segments[static_cast<size_t>(s)].region >= 0) continue;
    SegmentRegion r;
    if (grower.grow(s, static_cast<int>(out.size()), &r)) out.push_back(std::move(r));
  }
  return out;
}

}  // namespace lidar_detail
}  // namespace board_calib
