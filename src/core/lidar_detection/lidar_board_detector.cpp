#include <board_calib/core/lidar_board_detector.h>

#include "geometry_2d.h"
#include "scan_segments.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <functional>
#include <limits>
#include <map>
#include <numeric>
#include <unordered_map>
#include <unordered_set>

namespace board_calib {

using lidar_detail::fitLineRobust;
using lidar_detail::intersectLines;
using lidar_detail::LineFit2D;
using lidar_detail::PlaneFit;
using lidar_detail::PlaneStats;

namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kRadPerDeg = kPi / 180.0;
// Voxel indices are packed into one 64-bit key, 21 bits per axis.
constexpr int64_t kVoxelIndexOffset = 1 << 20;
constexpr int64_t kVoxelIndexBits = 21;
// Covariance of a uniform segment of length a is a^2/12: sqrt(12 lambda) estimates a side.
constexpr double kUniformSideFromVariance = 12.0;
// A region whose covariance says it is this many times larger than the board is not scored.
constexpr double kPrefilterExtentFactor = 2.0;
// Weights of the candidate score (lower is better): size terms are |log(ratio)|.
constexpr double kFillWeight = 0.5;
constexpr double kRmsWeight = 0.2;
constexpr double kMinFillForLog = 1e-3;
// Support = points * exp(-kShapeErrorScale * shape error): 0.25 more shape error costs a factor e.
constexpr double kShapeErrorScale = 4.0;
// The plane's up direction becomes undefined when the board is (nearly) horizontal.
constexpr double kMaxNormalUpCosine = 0.97;
// Two candidates closer than this are parts of one board, not two boards.
constexpr double kSameBoardDistanceM = 0.5;
// Median absolute deviation to sigma (Gaussian), band width in sigmas, and its floor.
constexpr double kMadToSigma = 1.4826;
constexpr double kRobustBandSigmas = 2.5;
constexpr double kMinRobustBandM = 0.005;
constexpr double kAdaptiveBandSigmas = 3.0;   // plane inlier band in robust sigmas
constexpr double kMaxAdaptiveBandFactor = 2.0;  // the band grows to at most this times the threshold
// The plane refit after the edges keeps points this far inside the edge lines (drops the
// mixed returns of the rim and anything touching the board from outside).
constexpr double kRimExclusionM = 0.02;
// Points sampled for the convex hull of a large candidate.
constexpr size_t kMaxHullPoints = 4000;
// Re-assignment rounds between the two edges of one side.
constexpr int kEdgeAssignmentRounds = 3;

std::string fmt(const char* format, double a, double b = 0, double c = 0, double d = 0) {
  char buf[256];
  std::snprintf(buf, sizeof(buf), format, a, b, c, d);
  return buf;
}

int64_t voxelKey(int64_t ix, int64_t iy, int64_t iz) {
  return ((ix + kVoxelIndexOffset) << (2 * kVoxelIndexBits)) | ((iy + kVoxelIndexOffset) << kVoxelIndexBits) |
         (iz + kVoxelIndexOffset);
}

struct Voxel {
  int ix = 0, iy = 0, iz = 0;
  PlaneStats stats;
  int first = 0, count = 0;  // range in the voxel-sorted point index array
  int region = -1;
};

struct ValidPoint {
  Eigen::Vector3d p;
  int cloud_index = 0;
};

struct Region {
  std::vector<int> voxels;
  PlaneStats stats;
  // Sparse candidates (scan-line segments): their points and sampling.
  bool sparse = false;
  std::vector<int> points;
  int lines = 0;
  double column_step_rad = 0.0, line_step_rad = 0.0;
};

struct Candidate {
  LidarBoardCandidate info;
  int region = -1;
};

// Azimuth difference wrapped into (-pi, pi].
double wrapAngle(double a) {
  while (a > kPi) a -= 2 * kPi;
  while (a <= -kPi) a += 2 * kPi;
  return a;
}

LidarBoardDetection failure(LidarBoardDetection d, LidarDetectionCode code, const std::string& reason) {
  d.code = code;
  d.features.found = false;
  d.features.reason = reason;
  return d;
}

}  // namespace

std::string LidarBoardDetectorOptions::validate() const {
  if (!(min_range_m >= 0.0)) return "min_range_m must be >= 0";
  if (!(max_range_m > min_range_m)) return "max_range_m must be > min_range_m";
  if (use_roi && !(roi.min.array() < roi.max.array()).all()) return "roi.min must be < roi.max on every axis";
  if (!(voxel_size_m > 0.01 && voxel_size_m < 5.0)) return "voxel_size_m must be in (0.01, 5) m";
  if (min_voxel_points < 1) return "min_voxel_points must be >= 1";
  if (!(max_voxel_thickness_m > 0.0)) return "max_voxel_thickness_m must be > 0";
  if (!(max_voxel_offset_m > 0.0)) return "max_voxel_offset_m must be > 0";
  if (!(min_seed_spread_m >= 0.0)) return "min_seed_spread_m must be >= 0";
  if (!(max_voxel_normal_angle_deg > 0.0 && max_voxel_normal_angle_deg <= 90.0))
    return "max_voxel_normal_angle_deg must be in (0, 90]";
  if (min_board_points < 3) return "min_board_points must be >= 3";
  if (!(min_size_ratio > 0.0 && min_size_ratio <= 1.0)) return "min_size_ratio must be in (0, 1]";
  if (!(max_size_ratio >= 1.0)) return "max_size_ratio must be >= 1";
  if (!(min_fill_ratio >= 0.0 && min_fill_ratio <= 1.0)) return "min_fill_ratio must be in [0, 1]";
  if (!(max_candidate_rms_m > 0.0)) return "max_candidate_rms_m must be > 0";
  if (!(ambiguity_ratio > 0.0 && ambiguity_ratio <= 1.0)) return "ambiguity_ratio must be in (0, 1]";
  if (!(plane_distance_threshold_m > 0.0)) return "plane_distance_threshold_m must be > 0";
  if (ransac_iterations < 1) return "ransac_iterations must be >= 1";
  if (!(elevation_gap_deg > 0.0)) return "elevation_gap_deg must be > 0";
  if (min_points_per_scan_line < 2) return "min_points_per_scan_line must be >= 2";
  if (min_edge_points < 2) return "min_edge_points must be >= 2";
  if (!(edge_inlier_threshold_m > 0.0)) return "edge_inlier_threshold_m must be > 0";
  if (!(max_edge_rms_m > 0.0)) return "max_edge_rms_m must be > 0";
  if (!(max_corner_angle_error_deg > 0.0 && max_corner_angle_error_deg < 90.0))
    return "max_corner_angle_error_deg must be in (0, 90)";
  if (!(size_doubt_ratio >= 0.0)) return "size_doubt_ratio must be >= 0";
  if (!(beam_divergence_deg >= 0.0 && beam_divergence_deg < 5.0)) return "beam_divergence_deg must be in [0, 5)";
  if (min_scan_lines < 3) return "min_scan_lines must be >= 3 (two lines give no edges)";
  if (!(range_noise_m >= 0.0 && range_noise_m < 1.0)) return "range_noise_m must be in [0, 1) m";
  if (!(sparse_size_slack >= 0.0 && sparse_size_slack <= 0.5)) return "sparse_size_slack must be in [0, 0.5]";
  return {};
}

std::string StaticMemoryOptions::validate() const {
  if (!(place_radius_m > 0.0)) return "place_radius_m must be > 0";
  if (!(max_normal_angle_deg > 0.0 && max_normal_angle_deg <= 90.0)) return "max_normal_angle_deg must be in (0, 90]";
  if (!(static_after_s > 0.0)) return "static_after_s must be > 0";
  if (!(min_seen_fraction >= 0.0 && min_seen_fraction <= 1.0)) return "min_seen_fraction must be in [0, 1]";
  if (!(forget_after_s > 0.0)) return "forget_after_s must be > 0";
  return {};
}

const char* lidarDetectionCodeName(LidarDetectionCode code) {
  switch (code) {
    case LidarDetectionCode::kFound: return "found";
    case LidarDetectionCode::kInvalidOptions: return "invalid options";
    case LidarDetectionCode::kInvalidTarget: return "invalid target";
    case LidarDetectionCode::kEmptyCloud: return "empty cloud";
    case LidarDetectionCode::kNoValidPoints: return "no valid points";
    case LidarDetectionCode::kNoPlane: return "no plane";
    case LidarDetectionCode::kWrongSize: return "wrong size";
    case LidarDetectionCode::kAmbiguous: return "ambiguous";
    case LidarDetectionCode::kTooFewPoints: return "too few points";
  }
  return "unknown";
}

namespace {

// ------------------------------------------------------------------------------------------
// Stage 1: valid points.
// ------------------------------------------------------------------------------------------
std::vector<ValidPoint> validPoints(const LidarCloud& cloud, const LidarBoardDetectorOptions& o,
                                    const BackgroundModel* background) {
  std::vector<uint8_t> foreground;
  if (background && !background->empty()) foreground = background->foregroundMask(cloud);
  std::vector<ValidPoint> out;
  out.reserve(cloud.points.size());
  const double min_r2 = o.min_range_m * o.min_range_m, max_r2 = o.max_range_m * o.max_range_m;
  for (size_t i = 0; i < cloud.points.size(); ++i) {
    const auto& q = cloud.points[i];
    if (!std::isfinite(q.x) || !std::isfinite(q.y) || !std::isfinite(q.z)) continue;
    const Eigen::Vector3d p(q.x, q.y, q.z);
    const double r2 = p.squaredNorm();
    if (r2 < min_r2 || r2 > max_r2) continue;
    if (o.use_roi && !o.roi.contains(p)) continue;
    if (!foreground.empty() && !foreground[i]) continue;
    out.push_back({p, static_cast<int>(i)});
  }
  return out;
}

// ------------------------------------------------------------------------------------------
// Stage 2: voxels with plane statistics, planar region growing.
// ------------------------------------------------------------------------------------------
struct VoxelGrid {
  std::vector<Voxel> voxels;
  std::unordered_map<int64_t, int> index;
  std::vector<int> sorted_points;  // point indices grouped by voxel

  int find(int ix, int iy, int iz) const {
    const auto it = index.find(voxelKey(ix, iy, iz));
    return it == index.end() ? -1 : it->second;
  }
};

VoxelGrid buildVoxels(const std::vector<ValidPoint>& pts, double size) {
  VoxelGrid g;
  g.index.reserve(pts.size() / 4 + 16);
  std::vector<int> voxel_of(pts.size());
  for (size_t i = 0; i < pts.size(); ++i) {
    const auto& p = pts[i].p;
    const int ix = static_cast<int>(std::floor(p.x() / size));
    const int iy = static_cast<int>(std::floor(p.y() / size));
    const int iz = static_cast<int>(std::floor(p.z() / size));
    const auto ins = g.index.emplace(voxelKey(ix, iy, iz), static_cast<int>(g.voxels.size()));
    if (ins.second) {
      Voxel v;
      v.ix = ix;
      v.iy = iy;
      v.iz = iz;
      g.voxels.push_back(v);
    }
    Voxel& v = g.voxels[ins.first->second];
    v.stats.add(p);
    v.count++;
    voxel_of[i] = ins.first->second;
  }
  // Counting sort of the point indices by voxel.
  int offset = 0;
  for (auto& v : g.voxels) {
    v.first = offset;
    offset += v.count;
    v.count = 0;
  }
  g.sorted_points.resize(pts.size());
  for (size_t i = 0; i < pts.size(); ++i) {
    Voxel& v = g.voxels[voxel_of[i]];
    g.sorted_points[v.first + v.count++] = static_cast<int>(i);
  }
  return g;
}

std::vector<Region> growPlanarRegions(VoxelGrid& g, const LidarBoardDetectorOptions& o) {
  // Seeds: voxels whose points spread in 2D (not a single scan line) and are thin.
  std::vector<std::pair<int, int>> seeds;  // (points, voxel)
  std::vector<PlaneFit> fits(g.voxels.size());
  for (size_t i = 0; i < g.voxels.size(); ++i) {
    const Voxel& v = g.voxels[i];
    fits[i] = lidar_detail::fitPlane(v.stats);
    if (v.stats.n < o.min_voxel_points) continue;
    const auto& ev = fits[i].eigenvalues;
    if (std::sqrt(ev[0]) < o.max_voxel_thickness_m && std::sqrt(ev[1]) > o.min_seed_spread_m)
      seeds.emplace_back(v.stats.n, static_cast<int>(i));
  }
  std::sort(seeds.begin(), seeds.end(), std::greater<>());

  const double min_spread_sq = o.min_seed_spread_m * o.min_seed_spread_m;
  const double min_normal_cos = std::cos(o.max_voxel_normal_angle_deg * kRadPerDeg);
  std::vector<Region> regions;
  std::vector<int> queue;
  for (const auto& seed : seeds) {
    if (g.voxels[seed.second].region >= 0) continue;
    Region r;
    const int id = static_cast<int>(regions.size());
    r.voxels.push_back(seed.second);
    r.stats = g.voxels[seed.second].stats;
    g.voxels[seed.second].region = id;
    PlaneFit plane = fits[seed.second];
    queue.assign(1, seed.second);
    size_t head = 0;
    int added_since_fit = 0;
    while (head < queue.size()) {
      const Voxel cur = g.voxels[queue[head++]];
      for (int dx = -1; dx <= 1; ++dx)
        for (int dy = -1; dy <= 1; ++dy)
          for (int dz = -1; dz <= 1; ++dz) {
            if (!dx && !dy && !dz) continue;
            const int q = g.find(cur.ix + dx, cur.iy + dy, cur.iz + dz);
            if (q < 0 || g.voxels[q].region >= 0) continue;
            const Voxel& nv = g.voxels[q];
            const Eigen::Vector3d n = plane.normal();
            const double offset = std::abs(n.dot(nv.stats.mean()) - plane.offset());
            const double thickness = std::sqrt(std::max(0.0, n.dot(nv.stats.covariance() * n)));
            if (offset > o.max_voxel_offset_m || thickness > o.max_voxel_thickness_m) continue;
            // A voxel with a reliable normal of its own must agree (a body touching the board
            // at a shallow angle stays out).
            if (nv.stats.n >= o.min_voxel_points && fits[q].eigenvalues[1] > min_spread_sq && std::abs(fits[q].normal().dot(n)) < min_normal_cos) continue;
            g.voxels[q].region = id;
            r.voxels.push_back(q);
            r.stats.add(nv.stats);
            queue.push_back(q);
            // Refit often while the region is small (its normal is still uncertain).
            if (++added_since_fit >= std::max<int>(1, static_cast<int>(r.voxels.size()) / 8)) {
              plane = lidar_detail::fitPlane(r.stats);
              added_since_fit = 0;
            }
          }
    }
    regions.push_back(std::move(r));
  }
  return regions;
}

// In-plane basis of a plane: u "right" as seen from the sensor, v "up" (sensor +z projected).
struct PlaneFrame {
  Eigen::Vector3d origin, n, u, v;
  Eigen::Vector2d project(const Eigen::Vector3d& p) const {
    const Eigen::Vector3d d = p - origin;
    return {d.dot(u), d.dot(v)};
  }
  Eigen::Vector3d lift(const Eigen::Vector2d& q) const { return origin + q.x() * u + q.y() * v; }
};

bool makePlaneFrame(const Eigen::Vector3d& normal, const Eigen::Vector3d& point, PlaneFrame* f) {
  f->n = normal;
  f->origin = point;
  Eigen::Vector3d up = Eigen::Vector3d::UnitZ() - normal * normal.z();
  const bool good = std::abs(normal.z()) < kMaxNormalUpCosine;
  if (!good) {
    // Horizontal board: any in-plane basis serves the size checks.
    up = normal.unitOrthogonal();
  }
  f->v = up.normalized();
  f->u = normal.cross(f->v).normalized();
  return good;
}

Candidate scoreRegion(const Region& r, int region_id, const VoxelGrid& g, const std::vector<ValidPoint>& pts,
                      const Target& target, const LidarBoardDetectorOptions& o) {
  Candidate c;
  c.region = region_id;
  auto& info = c.info;
  const PlaneFit fit = lidar_detail::fitPlane(r.stats);
  info.centroid = fit.centroid;
  info.num_points = r.stats.n;
  info.plane.normal = fit.normal();
  info.plane.offset = fit.offset();
  if (info.plane.offset < 0) {
    info.plane.normal = -info.plane.normal;
    info.plane.offset = -info.plane.offset;
  }
  info.rms_m = std::sqrt(fit.eigenvalues[0]);
  info.score = -1.0;
  const double big_side = std::max(target.width, target.height);
  const double small_side = std::min(target.width, target.height);
  if (r.stats.n < o.min_board_points) {
    info.rejected_because = "too few points (" + std::to_string(r.stats.n) + ")";
    return c;
  }
  // Cheap extent check from the covariance before any hull.
  const double extent_big = std::sqrt(kUniformSideFromVariance * fit.eigenvalues[2]);
  info.rectangle_m = {extent_big, std::sqrt(kUniformSideFromVariance * fit.eigenvalues[1])};
  if (extent_big > kPrefilterExtentFactor * o.max_size_ratio * big_side) {
    info.rejected_because = fmt("far too large (about %.2f m across)", extent_big);
    return c;
  }
  PlaneFrame frame;
  makePlaneFrame(info.plane.normal, fit.centroid, &frame);
  Points2 projected;
  projected.reserve(std::min<size_t>(r.stats.n, kMaxHullPoints));
  const size_t stride = std::max<size_t>(1, r.stats.n / kMaxHullPoints);
  size_t k = 0;
  for (int vi : r.voxels) {
    const Voxel& v = g.voxels[vi];
    for (int j = 0; j < v.count; ++j, ++k)
      if (k % stride == 0) projected.push_back(frame.project(pts[g.sorted_points[v.first + j]].p));
  }
  const Points2 hull = lidar_detail::convexHull(projected);
  info.fill_ratio = lidar_detail::polygonArea(hull) / (target.width * target.height);
  // Two size estimates: the hull's min-area rectangle (exact for a clean board, inflated by a
  // hand or an arm touching it) and the second moments (robust to such appendages, biased
  // where the beams are unevenly spaced, e.g. VLP-32C). The board needs one to fit.
  const Eigen::Vector2d moments = info.rectangle_m;
  const Eigen::Vector2d hull_rect = lidar_detail::minAreaRectangle(hull);
  auto sizeError = [&](const Eigen::Vector2d& sides) {
    return std::abs(std::log(std::max(1e-6, sides.x()) / big_side)) +
           std::abs(std::log(std::max(1e-6, sides.y()) / small_side));
  };
  auto sizeOk = [&](const Eigen::Vector2d& sides) {
    const double rb = sides.x() / big_side, rs = sides.y() / small_side;
    return rb >= o.min_size_ratio && rs >= o.min_size_ratio && rb <= o.max_size_ratio && rs <= o.max_size_ratio;
  };
  const bool moments_ok = sizeOk(moments), hull_ok = sizeOk(hull_rect);
  info.rectangle_m = (hull_ok && (!moments_ok || sizeError(hull_rect) <= sizeError(moments))) ? hull_rect : moments;
  if (!moments_ok && !hull_ok) {
    const bool large = hull_rect.x() > o.max_size_ratio * big_side || hull_rect.y() > o.max_size_ratio * small_side;
    info.rectangle_m = hull_rect;
    info.rejected_because = fmt(large ? "too large (%.2f x %.2f m)" : "too small (%.2f x %.2f m)", hull_rect.x(),
                                hull_rect.y());
    return c;
  }
  if (info.fill_ratio < o.min_fill_ratio) {
    info.rejected_because = fmt("not rectangular enough (hull fills %.0f%% of the board)", 100 * info.fill_ratio);
    return c;
  }
  if (info.rms_m > o.max_candidate_rms_m) {
    info.rejected_because = fmt("not flat (RMS %.3f m)", info.rms_m);
    return c;
  }
  const double shape_error = sizeError(info.rectangle_m) +
                             kFillWeight * std::abs(std::log(std::max(info.fill_ratio, kMinFillForLog))) +
                             kRmsWeight * info.rms_m / o.max_candidate_rms_m;
  // Support: the held board is near the sensor and densely sampled, so point count weighs as
  // much as shape (a far board-sized door or cabinet has a tenth of its points).
  info.score = info.num_points * std::exp(-kShapeErrorScale * shape_error);
  return c;
}

// Fewest returns of a sparse candidate: a few on each of the lines it needs.
constexpr int kSparsePointsPerLine = 4;
constexpr double kSparseLineGapVoxels = 0.5;  // segments where lines are farther apart than this many voxels
constexpr double kSparseMinWidthRatio = 0.8;  // of the widest chord a board's middle line must show
int sparseMinPoints(const LidarBoardDetectorOptions& o) {
  return std::min(o.min_board_points, kSparsePointsPerLine * o.min_scan_lines);
}

// A candidate from scan-line segments. Its sampling sets the tolerances: the board's true
// outline lies up to one line spacing (range x elevation step) beyond the outermost lines and
// up to one column step (plus the beam's bloom) beyond each line's extremes. It must fit inside
// the declared board (plus those tolerances and the range noise) and, with them, be able to
// reach the board's smaller side in both directions.
Candidate scoreSparse(const Region& r, int region_id, const std::vector<ValidPoint>& pts, const Target& target,
                      const LidarBoardDetectorOptions& o) {
  Candidate c;
  c.region = region_id;
  auto& info = c.info;
  const PlaneFit fit = lidar_detail::fitPlane(r.stats);
  info.centroid = fit.centroid;
  info.num_points = r.stats.n;
  info.scan_lines = r.lines;
  info.plane.normal = fit.normal();
  info.plane.offset = fit.offset();
  if (info.plane.offset < 0) {
    info.plane.normal = -info.plane.normal;
    info.plane.offset = -info.plane.offset;
  }
  info.rms_m = std::sqrt(fit.eigenvalues[0]);
  info.score = -1.0;
  if (r.lines < o.min_scan_lines) {
    info.rejected_because = "seen by " + std::to_string(r.lines) + " scan lines (need " + std::to_string(o.min_scan_lines) + ")";
    return c;
  }
  if (info.rms_m > o.max_candidate_rms_m) {
    info.rejected_because = fmt("not flat (RMS %.3f m)", info.rms_m);
    return c;
  }
  // Cheap first: the covariance's extent (a uniform segment of length a has variance a^2/12).
  const double extent = std::sqrt(kUniformSideFromVariance * fit.eigenvalues[2]);
  if (extent > kPrefilterExtentFactor * (1.0 + o.sparse_size_slack) * std::max(target.width, target.height)) {
    info.rectangle_m = {extent, std::sqrt(kUniformSideFromVariance * fit.eigenvalues[1])};
    info.rejected_because = fmt("far too large (about %.2f m across)", extent);
    return c;
  }
  const double range = fit.centroid.norm();
  const double column_m = range * r.column_step_rad;
  const double line_m = range * r.line_step_rad;
  const double bloom_m = range * o.beam_divergence_deg * kRadPerDeg;
  const double tolerance = column_m + bloom_m + 3.0 * o.range_noise_m;
  PlaneFrame frame;
  makePlaneFrame(info.plane.normal, fit.centroid, &frame);
  Points2 projected;
  projected.reserve(r.points.size());
  Eigen::Vector2d lo = Eigen::Vector2d::Constant(1e9), hi = -lo;
  for (int i : r.points) {
    projected.push_back(frame.project(pts[static_cast<size_t>(i)].p));
    lo = lo.cwiseMin(projected.back());
    hi = hi.cwiseMax(projected.back());
  }
  // Vertically the outline may lie a line spacing beyond the outermost lines. Across, the
  // line nearest the board's middle (within half a spacing of it) spans nearly the smaller side
  // whatever the roll: a body or a post under the board is narrower.
  const double small_side = std::min(target.width, target.height);
  const double up = hi.y() - lo.y() + 2.0 * line_m, across = hi.x() - lo.x() + 2.0 * column_m;
  if (up < o.min_size_ratio * small_side || across < kSparseMinWidthRatio * std::max(0.0, small_side - 0.5 * line_m)) {
    info.rectangle_m = hi - lo;
    info.rejected_because = fmt("too small: %.2f m high, %.2f m wide with the sampling gaps (%.2f m between lines)",
                                hi.y() - lo.y(), hi.x() - lo.x(), line_m);
    return c;
  }
  const Points2 hull = lidar_detail::convexHull(projected);
  info.fill_ratio = lidar_detail::polygonArea(hull) / (target.width * target.height);
  info.rectangle_m = lidar_detail::minAreaRectangle(hull);
  const double slack = 1.0 + o.sparse_size_slack;
  // Only the hull decides whether the points fit inside.
  const auto inside = lidar_detail::fitRectangle(hull, {}, {}, slack * target.width, slack * target.height, tolerance);
  if (!inside.ok) {
    info.rejected_because = fmt("too large: %.2f x %.2f m does not fit in the board (sampling %.2f m across, %.2f m "
                                "between lines)",
                                info.rectangle_m.x(), info.rectangle_m.y(), column_m, line_m);
    return c;
  }
  info.score = info.num_points * std::exp(-kShapeErrorScale * kRmsWeight * info.rms_m / o.max_candidate_rms_m);
  return c;
}

// ------------------------------------------------------------------------------------------
// Stage 3: plane refinement (RANSAC seeded from the region, least squares on the inliers).
// ------------------------------------------------------------------------------------------
struct RefinedPlane {
  Plane plane;
  std::vector<int> inliers;  // indices into the valid points
  double rms = 0.0;
};

RefinedPlane refinePlane(const std::vector<int>& region_points, const std::vector<int>& gathered,
                         const std::vector<ValidPoint>& pts, const LidarBoardDetectorOptions& o, std::mt19937& rng) {
  RefinedPlane best;
  const double thr = o.plane_distance_threshold_m;
  std::uniform_int_distribution<size_t> pick(0, region_points.size() - 1);
  Eigen::Vector3d best_n = Eigen::Vector3d::UnitX();
  double best_d = 0.0;
  size_t best_count = 0;
  for (int it = 0; it < o.ransac_iterations; ++it) {
    const auto& a = pts[region_points[pick(rng)]].p;
    const auto& b = pts[region_points[pick(rng)]].p;
    const auto& c = pts[region_points[pick(rng)]].p;
    Eigen::Vector3d n = (b - a).cross(c - a);
    if (n.norm() < 1e-9) continue;
    n.normalize();
    const double d = n.dot(a);
    size_t count = 0;
    for (int i : gathered) count += std::abs(n.dot(pts[i].p) - d) < thr;
    if (count > best_count) {
      best_count = count;
      best_n = n;
      best_d = d;
    }
  }
  // Least squares on the inliers, three times (the inlier set moves with the plane). From the
  // second round the band follows the measured noise (3 RMS): a noisy LiDAR (OS1:
  // ~1.5 cm) would otherwise lose the board's sparse rim rows to a fixed threshold.
  double band_m = thr;
  for (int round = 0; round < 3; ++round) {
    PlaneStats s;
    std::vector<int> inliers;
    for (int i : gathered)
      if (std::abs(best_n.dot(pts[i].p) - best_d) < band_m) {
        s.add(pts[i].p);
        inliers.push_back(i);
      }
    if (s.n < 3) break;
    const PlaneFit f = lidar_detail::fitPlane(s);
    best_n = f.normal();
    best_d = f.offset();
    // RMS, not MAD: a flexing board's rim sits in the tails that the band must reach.
    double sum_sq = 0.0;
    for (int i : inliers) sum_sq += std::pow(best_n.dot(pts[i].p) - best_d, 2);
    band_m = std::clamp(kAdaptiveBandSigmas * std::sqrt(sum_sq / inliers.size()), thr, kMaxAdaptiveBandFactor * thr);
    best.inliers = std::move(inliers);
  }
  // Robust scale of the residuals: a tighter band drops mixed returns at the board's rim (they
  // lie between the board and whatever is behind it) that the fixed threshold let in.
  if (best.inliers.size() >= 3) {
    std::vector<double> abs_res;
    abs_res.reserve(best.inliers.size());
    for (int i : best.inliers) abs_res.push_back(std::abs(best_n.dot(pts[i].p) - best_d));
    std::nth_element(abs_res.begin(), abs_res.begin() + abs_res.size() / 2, abs_res.end());
    const double sigma = kMadToSigma * abs_res[abs_res.size() / 2];
    const double band = std::clamp(kRobustBandSigmas * sigma, kMinRobustBandM, thr);
    PlaneStats s;
    for (int i : best.inliers)
      if (std::abs(best_n.dot(pts[i].p) - best_d) < band) s.add(pts[i].p);
    if (s.n >= 3) {
      const PlaneFit f = lidar_detail::fitPlane(s);
      best_n = f.normal();
      best_d = f.offset();
    }
  }
  if (best_d < 0) {
    best_n = -best_n;
    best_d = -best_d;
  }
  best.plane.normal = best_n;
  best.plane.offset = best_d;
  double sum_sq = 0.0;
  for (int i : best.inliers) sum_sq += std::pow(best.plane.signedDistance(pts[i].p), 2);
  best.rms = best.inliers.empty() ? 0.0 : std::sqrt(sum_sq / best.inliers.size());
  return best;
}

// ------------------------------------------------------------------------------------------
// Stage 4: scan lines and edges.
// ------------------------------------------------------------------------------------------
std::vector<int> scanLines(const LidarCloud& cloud, const std::vector<int>& board, const std::vector<ValidPoint>& pts,
                           const LidarBoardDetectorOptions& o, std::string* source) {
  std::vector<int> line(board.size(), -1);
  bool rings_ok = cloud.has_ring;
  for (size_t k = 0; k < board.size() && rings_ok; ++k) rings_ok = cloud.points[pts[board[k]].cloud_index].ring >= 0;
  if (rings_ok) {
    *source = "ring";
    for (size_t k = 0; k < board.size(); ++k) line[k] = cloud.points[pts[board[k]].cloud_index].ring;
    return line;
  }
  if (cloud.organized() && cloud.width > 0) {
    *source = "row";
    for (size_t k = 0; k < board.size(); ++k) line[k] = pts[board[k]].cloud_index / cloud.width;
    return line;
  }
  // Beams of a spinning LiDAR have fixed elevations: cluster the elevation angles.
  *source = "elevation";
  std::vector<std::pair<double, int>> elev(board.size());
  for (size_t k = 0; k < board.size(); ++k) {
    const auto& p = pts[board[k]].p;
    elev[k] = {std::atan2(p.z(), std::hypot(p.x(), p.y())), static_cast<int>(k)};
  }
  std::sort(elev.begin(), elev.end());
  const double gap = o.elevation_gap_deg * kRadPerDeg;
  int id = 0;
  for (size_t k = 0; k < elev.size(); ++k) {
    if (k > 0 && elev[k].first - elev[k - 1].first > gap) ++id;
    line[elev[k].second] = id;
  }
  return line;
}

struct SideFit {
  LineFit2D upper, lower;
  std::vector<int> upper_members, lower_members;  // indices into the side's points
};

// Splits the extremes of one side (left or right) into an upper and a lower edge and fits both.
// `outward` is -1 for the left side (smaller u), +1 for the right side.
// Sum of squared distances of points to their total-least-squares line.
double lineResidual(const Points2& pts, const std::vector<size_t>& order, size_t begin, size_t end) {
  Eigen::Vector2d mean = Eigen::Vector2d::Zero();
  for (size_t k = begin; k < end; ++k) mean += pts[order[k]];
  mean /= static_cast<double>(end - begin);
  Eigen::Matrix2d cov = Eigen::Matrix2d::Zero();
  for (size_t k = begin; k < end; ++k) {
    const Eigen::Vector2d d = pts[order[k]] - mean;
    cov += d * d.transpose();
  }
  return Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d>(cov).eigenvalues()(0);
}

// `search_split`: instead of taking the most outward point as the corner (a hand at the corner
// can fool it), split the extremes, ordered top to bottom, where two lines fit best.
SideFit fitSide(const Points2& side, double outward, const LidarBoardDetectorOptions& o, std::mt19937& rng,
                bool search_split = false) {
  SideFit s;
  if (side.size() < 2) return s;
  std::vector<int> label(side.size(), -1);  // 0 upper, 1 lower
  if (search_split && side.size() >= 4) {
    std::vector<size_t> order(side.size());
    std::iota(order.begin(), order.end(), 0);
    std::sort(order.begin(), order.end(), [&](size_t a, size_t b) { return side[a].y() > side[b].y(); });
    double best = std::numeric_limits<double>::infinity();
    size_t split = 2;
    for (size_t k = 2; k + 2 <= order.size(); ++k) {
      const double cost = lineResidual(side, order, 0, k) + lineResidual(side, order, k, order.size());
      if (cost < best) {
        best = cost;
        split = k;
      }
    }
    for (size_t k = 0; k < order.size(); ++k) label[order[k]] = k < split ? 0 : 1;
  } else {
    // The side's corner is its most outward point: above it the upper edge, below it the lower.
    size_t corner = 0;
    for (size_t i = 1; i < side.size(); ++i)
      if (outward * side[i].x() > outward * side[corner].x()) corner = i;
    for (size_t i = 0; i < side.size(); ++i)
      if (i != corner) label[i] = side[i].y() > side[corner].y() ? 0 : 1;
  }
  for (int round = 0; round < kEdgeAssignmentRounds; ++round) {
    Points2 up, lo;
    for (size_t i = 0; i < side.size(); ++i) {
      if (label[i] == 0) up.push_back(side[i]);
      if (label[i] == 1) lo.push_back(side[i]);
    }
    s.upper = fitLineRobust(up, o.edge_inlier_threshold_m, o.ransac_iterations, rng);
    s.lower = fitLineRobust(lo, o.edge_inlier_threshold_m, o.ransac_iterations, rng);
    if (!s.upper.ok || !s.lower.ok) break;
    // Re-assign every extreme to the nearer line (fixes points near the corner).
    Eigen::Vector2d x;
    const bool meet = intersectLines(s.upper, s.lower, &x);
    bool changed = false;
    for (size_t i = 0; i < side.size(); ++i) {
      const double du = s.upper.distance(side[i]), dl = s.lower.distance(side[i]);
      int l = du < dl ? 0 : 1;
      // Beyond the corner along v the nearer line can be the wrong one: keep the geometric side.
      if (meet) l = side[i].y() > x.y() ? (du < 3 * o.edge_inlier_threshold_m || du < dl ? 0 : 1)
                                        : (dl < 3 * o.edge_inlier_threshold_m || dl < du ? 1 : 0);
      if (l != label[i]) {
        label[i] = l;
        changed = true;
      }
    }
    if (!changed) break;
  }
  // Final fits with membership.
  Points2 up, lo;
  std::vector<int> up_idx, lo_idx;
  for (size_t i = 0; i < side.size(); ++i) {
    if (label[i] == 0) {
      up.push_back(side[i]);
      up_idx.push_back(static_cast<int>(i));
    } else if (label[i] == 1) {
      lo.push_back(side[i]);
      lo_idx.push_back(static_cast<int>(i));
    }
  }
  s.upper = fitLineRobust(up, o.edge_inlier_threshold_m, o.ransac_iterations, rng);
  s.lower = fitLineRobust(lo, o.edge_inlier_threshold_m, o.ransac_iterations, rng);
  for (size_t i = 0; i < up_idx.size(); ++i)
    if (s.upper.ok && s.upper.inlier[i]) s.upper_members.push_back(up_idx[i]);
  for (size_t i = 0; i < lo_idx.size(); ++i)
    if (s.lower.ok && s.lower.inlier[i]) s.lower_members.push_back(lo_idx[i]);
  return s;
}

void extractEdgesByLines(const LidarCloud& cloud, const std::vector<ValidPoint>& pts, const std::vector<int>& board,
                         const Target& target, const LidarBoardDetectorOptions& o, std::mt19937& rng,
                         LidarBoardDetection* det) {
  auto& f = det->features;
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  for (int i : board) centroid += pts[i].p;
  centroid /= static_cast<double>(board.size());
  centroid -= f.plane.normal * f.plane.signedDistance(centroid);
  PlaneFrame frame;
  if (!makePlaneFrame(f.plane.normal, centroid, &frame)) {
    f.reason = "board plane is nearly horizontal: its edges cannot be named";
    return;
  }
  const std::vector<int> line = scanLines(cloud, board, pts, o, &det->scan_line_source);
  // Per scan line: the extreme points in azimuth (left = larger azimuth, seen from the sensor).
  const double center_azimuth = std::atan2(centroid.y(), centroid.x());
  struct Extremes {
    int count = 0;
    int left = -1, right = -1;
    double left_az = -std::numeric_limits<double>::infinity(), right_az = std::numeric_limits<double>::infinity();
  };
  std::unordered_map<int, Extremes> per_line;
  for (size_t k = 0; k < board.size(); ++k) {
    const auto& p = pts[board[k]].p;
    const double az = wrapAngle(std::atan2(p.y(), p.x()) - center_azimuth);
    Extremes& e = per_line[line[k]];
    ++e.count;
    if (az > e.left_az) {
      e.left_az = az;
      e.left = board[k];
    }
    if (az < e.right_az) {
      e.right_az = az;
      e.right = board[k];
    }
  }
  std::vector<int> left_pts, right_pts;
  // Per extreme: the scan line's in-plane direction and its mean spacing between samples.
  Points2 left_dir, right_dir;
  std::vector<double> left_gap, right_gap;
  for (const auto& kv : per_line) {
    if (kv.second.count < o.min_points_per_scan_line || kv.second.left == kv.second.right) continue;
    ++det->num_scan_lines;
    left_pts.push_back(kv.second.left);
    right_pts.push_back(kv.second.right);
    const Eigen::Vector2d span = frame.project(pts[kv.second.right].p) - frame.project(pts[kv.second.left].p);
    const double gap = span.norm() / (kv.second.count - 1);
    left_dir.push_back(span.normalized());
    right_dir.push_back(span.normalized());
    left_gap.push_back(gap);
    right_gap.push_back(gap);
  }
  Points2 left2, right2;
  for (int i : left_pts) left2.push_back(frame.project(pts[i].p));
  for (int i : right_pts) right2.push_back(frame.project(pts[i].p));
  // Extremes scatter inward by up to one sample spacing: the inlier band must cover that at
  // long range, where the spacing exceeds the configured threshold.
  LidarBoardDetectorOptions edge_options = o;
  if (!left_gap.empty()) {
    std::vector<double> gaps = left_gap;
    std::nth_element(gaps.begin(), gaps.begin() + gaps.size() / 2, gaps.end());
    edge_options.edge_inlier_threshold_m = std::max(o.edge_inlier_threshold_m, gaps[gaps.size() / 2]);
  }
  SideFit left = fitSide(left2, -1.0, edge_options, rng);
  SideFit right = fitSide(right2, +1.0, edge_options, rng);
  // Adjacent edges of a rectangle meet at right angles; when they do not, one side's split was
  // wrong: try the split search on either side, then on both.
  auto anglesOk = [&](const SideFit& l, const SideFit& r) {
    const std::array<const LineFit2D*, kNumEdges> ls = {&l.upper, &r.upper, &r.lower, &l.lower};
    for (int j = 0; j < kNumEdges; ++j) {
      const LineFit2D& a = *ls[j];
      const LineFit2D& b = *ls[(j + 1) % kNumEdges];
      if (!a.ok || !b.ok) return false;
      const double angle = std::acos(std::min(1.0, std::abs(a.direction.dot(b.direction)))) / kRadPerDeg;
      if (std::abs(90.0 - angle) > o.max_corner_angle_error_deg) return false;
    }
    return true;
  };
  if (!anglesOk(left, right)) {
    const SideFit left_split = fitSide(left2, -1.0, edge_options, rng, true);
    const SideFit right_split = fitSide(right2, +1.0, edge_options, rng, true);
    if (anglesOk(left_split, right)) {
      left = left_split;
    } else if (anglesOk(left, right_split)) {
      right = right_split;
    } else if (anglesOk(left_split, right_split)) {
      left = left_split;
      right = right_split;
    }
  }
  if (o.correct_edge_sampling_bias) {
    // The true edge lies between a scan line's extreme and the next (missing) sample outside:
    // on average half a sample spacing further out along the scan line.
    // A return registers once part of the beam's footprint is on the board, so the extremes
    // bloom out by about half the divergence (times the range), which offsets that inset.
    const double bloom = 0.5 * o.beam_divergence_deg * kRadPerDeg * centroid.norm();
    auto shiftOut = [bloom](LineFit2D& l, const std::vector<int>& members, const Points2& dirs,
                            const std::vector<double>& gaps) {
      if (!l.ok || members.empty()) return;
      Eigen::Vector2d normal(-l.direction.y(), l.direction.x());
      if (normal.dot(l.point) < 0) normal = -normal;  // away from the board centre (the origin)
      double shift = 0.0;
      for (int m : members) shift += std::max(0.0, 0.5 * gaps[m] - bloom) * std::abs(dirs[m].dot(normal));
      l.point += normal * (shift / members.size());
    };
    shiftOut(left.upper, left.upper_members, left_dir, left_gap);
    shiftOut(left.lower, left.lower_members, left_dir, left_gap);
    shiftOut(right.upper, right.upper_members, right_dir, right_gap);
    shiftOut(right.lower, right.lower_members, right_dir, right_gap);
  }

  // Edge order: UL, UR, LR, LL.
  const std::array<const LineFit2D*, kNumEdges> lines = {&left.upper, &right.upper, &right.lower, &left.lower};
  const std::array<const std::vector<int>*, kNumEdges> members = {&left.upper_members, &right.upper_members,
                                                                   &right.lower_members, &left.lower_members};
  const std::array<const std::vector<int>*, kNumEdges> side_pts = {&left_pts, &right_pts, &right_pts, &left_pts};
  std::string edge_problems;
  for (int j = 0; j < kNumEdges; ++j) {
    f.edge_points[j].clear();
    for (int m : *members[j]) f.edge_points[j].push_back(pts[(*side_pts[j])[m]].p);
    const LineFit2D& l = *lines[j];
    const int n = l.ok ? l.num_inliers : 0;
    f.edge_valid[j] = l.ok && n >= o.min_edge_points && l.rms <= o.max_edge_rms_m;
    if (!f.edge_valid[j]) {
      edge_problems += std::string(edge_problems.empty() ? "" : ", ") + edgeName(j) + ": " +
                       (n < o.min_edge_points ? "too few points (" + std::to_string(n) + ")"
                                              : fmt("line fit RMS %.3f m", l.rms));
    }
    f.edge_line_point[j] = frame.lift(l.point);
    f.edge_line_direction[j] = (frame.lift(l.point + l.direction) - frame.lift(l.point)).normalized();
  }
  // Corners j = edge j x edge j+1.
  std::array<bool, kNumEdges> corner_ok{};
  std::array<Eigen::Vector2d, kNumEdges> corner2;
  std::string angle_problems;
  static const char* kCornerNames[kNumEdges] = {"top", "right", "bottom", "left"};
  for (int j = 0; j < kNumEdges; ++j) {
    const int k = (j + 1) % kNumEdges;
    if (!f.edge_valid[j] || !f.edge_valid[k]) continue;
    corner_ok[j] = intersectLines(*lines[j], *lines[k], &corner2[j]);
    if (!corner_ok[j]) continue;
    f.corners[j] = frame.lift(corner2[j]);
    const double angle = std::acos(std::min(1.0, std::abs(lines[j]->direction.dot(lines[k]->direction)))) / kRadPerDeg;
    if (std::abs(90.0 - angle) > o.max_corner_angle_error_deg)
      angle_problems += std::string(" ") + kCornerNames[j] + fmt(" corner meets at %.0f deg", angle);
  }
  // Line points and directions from the corners when both ends exist: edge j runs from corner
  // j-1 to corner j (clockwise as the sensor sees it).
  for (int j = 0; j < kNumEdges; ++j) {
    const int prev = (j + kNumEdges - 1) % kNumEdges;
    if (corner_ok[j] && corner_ok[prev]) {
      f.edge_line_point[j] = 0.5 * (f.corners[j] + f.corners[prev]);
      f.edge_line_direction[j] = (f.corners[j] - f.corners[prev]).normalized();
    }
  }
  if (!angle_problems.empty()) {
    for (int j = 0; j < kNumEdges; ++j) f.edge_valid[j] = false;
    f.reason = "edges inconsistent:" + angle_problems;
    return;
  }
  if (!edge_problems.empty()) {
    f.reason = "edges rejected: " + edge_problems;
    return;
  }
  bool all_corners = corner_ok[0] && corner_ok[1] && corner_ok[2] && corner_ok[3];
  if (!all_corners) {
    for (int j = 0; j < kNumEdges; ++j) f.edge_valid[j] = false;
    f.reason = "edges inconsistent: parallel adjacent edges";
    return;
  }
  // Sides: UL (left-top) and LR (right-bottom) are opposite, as are UR and LL.
  const double ul = (f.corners[0] - f.corners[3]).norm(), ur = (f.corners[1] - f.corners[0]).norm();
  const double lr = (f.corners[2] - f.corners[1]).norm(), ll = (f.corners[3] - f.corners[2]).norm();
  const double s1 = 0.5 * (ul + lr), s2 = 0.5 * (ur + ll);
  const double w = target.width, h = target.height;
  const bool direct = std::abs(s1 - w) + std::abs(s2 - h) <= std::abs(s1 - h) + std::abs(s2 - w);
  f.measured_size_m = direct ? Eigen::Vector2d(s1, s2) : Eigen::Vector2d(s2, s1);
  const double rw = f.measured_size_m.x() / w, rh = f.measured_size_m.y() / h;
  if (rw < o.min_size_ratio || rh < o.min_size_ratio || rw > o.max_size_ratio || rh > o.max_size_ratio) {
    for (int j = 0; j < kNumEdges; ++j) f.edge_valid[j] = false;
    f.reason = "edges inconsistent: " +
               fmt("corners span %.3f x %.3f m, declared %.3f x %.3f m", f.measured_size_m.x(),
                   f.measured_size_m.y(), w, h);
    return;
  }
  if (std::abs(rw - 1.0) > o.size_doubt_ratio || std::abs(rh - 1.0) > o.size_doubt_ratio)
    f.reason = fmt("measured %.3f x %.3f m, declared %.3f x %.3f m", f.measured_size_m.x(), f.measured_size_m.y(), w,
                   h);
}

// Sparse boards (a few scan lines): too few extremes per edge for four line fits, but the
// declared rectangle has only 3 degrees of freedom in the plane. Fit it to all extremes, each
// moved out by its expected inset (half a column step minus the beam's bloom, along the scan
// line), with every board point inside; its sides are the edges, the extremes each side owns
// its edge points.
bool extractEdgesByRectangle(const LidarCloud& cloud, const std::vector<ValidPoint>& pts, const std::vector<int>& board,
                             const Target& target, const LidarBoardDetectorOptions& o, LidarBoardDetection* det) {
  auto& f = det->features;
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  for (int i : board) centroid += pts[i].p;
  centroid /= static_cast<double>(board.size());
  centroid -= f.plane.normal * f.plane.signedDistance(centroid);
  PlaneFrame frame;
  if (!makePlaneFrame(f.plane.normal, centroid, &frame)) return false;
  std::string source;
  const std::vector<int> line = scanLines(cloud, board, pts, o, &source);
  const double center_azimuth = std::atan2(centroid.y(), centroid.x());
  struct Extremes {
    int count = 0, left = -1, right = -1;
    double left_az = -std::numeric_limits<double>::infinity(), right_az = std::numeric_limits<double>::infinity();
  };
  std::map<int, Extremes> per_line;
  for (size_t k = 0; k < board.size(); ++k) {
    const double az = wrapAngle(std::atan2(pts[board[k]].p.y(), pts[board[k]].p.x()) - center_azimuth);
    Extremes& e = per_line[line[k]];
    ++e.count;
    if (az > e.left_az) {
      e.left_az = az;
      e.left = board[k];
    }
    if (az < e.right_az) {
      e.right_az = az;
      e.right = board[k];
    }
  }
  const double range = centroid.norm();
  const double bloom = 0.5 * o.beam_divergence_deg * kRadPerDeg * range;
  Points2 board2, extremes;
  std::vector<double> insets;
  std::vector<int> extreme_index;
  double gap_sum = 0.0;
  int lines = 0;
  for (int i : board) board2.push_back(frame.project(pts[i].p));
  for (const auto& kv : per_line) {
    const Extremes& e = kv.second;
    if (e.count < o.min_points_per_scan_line || e.left == e.right) continue;
    ++lines;
    const Eigen::Vector2d a = frame.project(pts[e.left].p), b = frame.project(pts[e.right].p);
    const double gap = (b - a).norm() / (e.count - 1);
    gap_sum += gap;
    const double inset = o.correct_edge_sampling_bias ? std::max(0.0, 0.5 * gap - bloom) : 0.0;
    for (int idx : {e.left, e.right}) {
      extremes.push_back(frame.project(pts[idx].p));
      insets.push_back(inset);
      extreme_index.push_back(idx);
    }
  }
  if (lines < o.min_scan_lines) return false;
  const double column_m = gap_sum / lines;
  // Extremes scatter within a column step of the outline; the range noise moves them in-plane
  // only on tilted boards, the beam's bloom adds to the outside.
  const double tolerance = std::max(o.edge_inlier_threshold_m, column_m + 2.0 * bloom + 3.0 * o.range_noise_m);
  // Only the hull matters for "every board point inside".
  const auto fit = lidar_detail::fitRectangle(lidar_detail::convexHull(board2), extremes, insets, target.width,
                                              target.height, tolerance);
  if (!fit.ok || fit.rms_m > tolerance || fit.worst_outside_m > tolerance) return false;
  // Sides: outward normals of the four sides; UL is the one nearest to up-left (135 deg), then
  // clockwise UR, LR, LL.
  std::array<Eigen::Vector2d, kNumEdges> a, b;  // side endpoints, counter-clockwise corners
  std::array<double, kNumEdges> normal_angle;
  for (int k = 0; k < kNumEdges; ++k) {
    a[k] = fit.corners[k];
    b[k] = fit.corners[(k + 1) % kNumEdges];
    const Eigen::Vector2d d = b[k] - a[k];
    normal_angle[k] = std::atan2(-d.x(), d.y());  // ccw polygon: outward normal = (d.y, -d.x)
  }
  int ul = 0;
  auto angleTo = [](double x, double ref) { return std::abs(wrapAngle(x - ref)); };
  for (int k = 1; k < kNumEdges; ++k)
    if (angleTo(normal_angle[k], 0.75 * kPi) < angleTo(normal_angle[ul], 0.75 * kPi)) ul = k;
  // Clockwise from UL = backwards through the counter-clockwise sides.
  std::array<int, kNumEdges> side_of_edge;
  for (int j = 0; j < kNumEdges; ++j) side_of_edge[j] = (ul - j + kNumEdges) % kNumEdges;
  std::array<lidar_detail::LineFit2D, kNumEdges> lines2;
  for (int j = 0; j < kNumEdges; ++j) {
    const int k = side_of_edge[j];
    lines2[j].ok = true;
    lines2[j].point = 0.5 * (a[k] + b[k]);
    lines2[j].direction = (b[k] - a[k]).normalized();
    f.edge_points[j].clear();
  }
  for (size_t e = 0; e < extremes.size(); ++e) {
    int owner = 0;
    for (int j = 1; j < kNumEdges; ++j)
      if (lines2[j].distance(extremes[e]) < lines2[owner].distance(extremes[e])) owner = j;
    f.edge_points[owner].push_back(pts[extreme_index[e]].p);
  }
  std::string missing;
  for (int j = 0; j < kNumEdges; ++j)
    if (f.edge_points[j].empty()) missing += std::string(missing.empty() ? "" : ", ") + edgeName(j);
  if (!missing.empty()) return false;
  for (int j = 0; j < kNumEdges; ++j) {
    f.edge_valid[j] = true;
    f.edge_line_point[j] = frame.lift(lines2[j].point);
    f.edge_line_direction[j] = (frame.lift(lines2[j].point + lines2[j].direction) - frame.lift(lines2[j].point)).normalized();
    // Corner j = edge j x edge j+1: the end of side j shared with side j+1 (clockwise).
    const int k = side_of_edge[j];
    f.corners[j] = frame.lift(a[k]);
  }
  det->num_scan_lines = lines;
  det->scan_line_source = source;
  f.measured_size_m = Eigen::Vector2d(target.width, target.height);
  f.reason = fmt("edges from the declared %.3f x %.3f m rectangle fitted to %.0f scan lines (RMS %.3f m)", target.width,
                 target.height, lines, fit.rms_m);
  return true;
}

void extractEdges(const LidarCloud& cloud, const std::vector<ValidPoint>& pts, const std::vector<int>& board,
                  const Target& target, const LidarBoardDetectorOptions& o, std::mt19937& rng,
                  LidarBoardDetection* det) {
  const LidarBoardDetection before = *det;
  extractEdgesByLines(cloud, pts, board, target, o, rng, det);
  if (det->features.allEdgesValid() || !o.sparse_candidates) return;
  LidarBoardDetection sparse = before;
  if (extractEdgesByRectangle(cloud, pts, board, target, o, &sparse)) {
    *det = std::move(sparse);
  }
}

}  // namespace

namespace {

// History of a stateful detector: whether a board-like candidate sits at a static place, and
// whether two unknown places are ambiguous whatever their support.
struct History {
  std::function<bool(const LidarBoardCandidate&)> is_static;
  bool strict_ambiguity = false;
};

LidarBoardDetection detectImpl(const LidarCloud& cloud, const Target& target, const LidarBoardDetectorOptions& options,
                               const BackgroundModel* background, const History* history) {
  LidarBoardDetection det;
  auto& f = det.features;
  f.frame_id = cloud.frame_id;
  f.stamp = cloud.stamp;
  for (int j = 0; j < kNumEdges; ++j) {
    f.edge_line_point[j].setZero();
    f.edge_line_direction[j] = Eigen::Vector3d::UnitX();
    f.corners[j].setZero();
  }
  const std::string bad_options = options.validate();
  if (!bad_options.empty())
    return failure(std::move(det), LidarDetectionCode::kInvalidOptions, "invalid detector options: " + bad_options);
  const std::string bad_target = target.validate();
  if (!bad_target.empty())
    return failure(std::move(det), LidarDetectionCode::kInvalidTarget, "invalid target: " + bad_target);
  if (cloud.points.empty()) return failure(std::move(det), LidarDetectionCode::kEmptyCloud, "empty cloud (0 points)");

  const std::vector<ValidPoint> pts = validPoints(cloud, options, background);
  det.num_valid_points = static_cast<int>(pts.size());
  if (pts.size() < 3) {
    std::string why = "no valid returns among " + std::to_string(cloud.points.size()) + " points (NaN, zero or out of " +
                      fmt("%.1f..%.1f m", options.min_range_m, options.max_range_m) + ")";
    if (options.use_roi) why += ", or outside the ROI";
    if (background && !background->empty()) why += ", or background";
    return failure(std::move(det), LidarDetectionCode::kNoValidPoints, why);
  }

  VoxelGrid grid = buildVoxels(pts, options.voxel_size_m);
  std::vector<Region> regions = growPlanarRegions(grid, options);

  std::vector<Candidate> candidates;
  for (size_t r = 0; r < regions.size(); ++r) {
    if (regions[r].stats.n < options.min_board_points) continue;  // not worth reporting
    candidates.push_back(scoreRegion(regions[r], static_cast<int>(r), grid, pts, target, options));
  }
  if (options.sparse_candidates) {
    // Far boards: scan lines spaced wider than a voxel leave no planar voxel; grow planes from
    // scan-line segments instead. A board the voxels already found is not added twice.
    std::vector<int> cloud_index(pts.size());
    std::vector<Eigen::Vector3d> xyz(pts.size());
    for (size_t i = 0; i < pts.size(); ++i) {
      cloud_index[i] = pts[i].cloud_index;
      xyz[i] = pts[i].p;
    }
    std::string source;
    const std::vector<int> all_lines =
        lidar_detail::scanLinesOf(cloud, cloud_index, xyz, options.elevation_gap_deg * kRadPerDeg, &source);
    // Points the voxels already explain (floor, walls: larger than the board; boards they
    // accepted) need no second look: the segments run on the rest, which keeps this cheap.
    std::vector<uint8_t> explained(regions.size(), 0);
    const double big_side = std::max(target.width, target.height);
    for (const auto& c : candidates)
      explained[static_cast<size_t>(c.region)] = c.info.score >= 0 || c.info.rectangle_m.x() > options.max_size_ratio * big_side;
    std::vector<uint8_t> skip(pts.size(), 0);
    for (const auto& v : grid.voxels)
      if (v.region >= 0 && explained[static_cast<size_t>(v.region)])
        for (int j = 0; j < v.count; ++j) skip[static_cast<size_t>(grid.sorted_points[v.first + j])] = 1;
    // Only where the lines are too far apart for the voxels (fewer than two lines in a voxel's
    // height can seed no plane) do the segments add anything.
    const std::vector<double> gap = lidar_detail::lineGaps(xyz, all_lines);
    std::vector<int> subset;  // indices into pts, in cloud order (lines come in firing order)
    subset.reserve(pts.size());
    for (size_t i = 0; i < pts.size(); ++i)
      if (!skip[i] && xyz[i].norm() * gap[static_cast<size_t>(all_lines[i])] > kSparseLineGapVoxels * options.voxel_size_m)
        subset.push_back(static_cast<int>(i));
    xyz.resize(subset.size());
    std::vector<int> line(subset.size());
    for (size_t k = 0; k < subset.size(); ++k) {
      xyz[k] = pts[static_cast<size_t>(subset[k])].p;
      line[k] = all_lines[static_cast<size_t>(subset[k])];
    }
    lidar_detail::SegmentOptions so;
    so.max_length_m = (1.0 + options.sparse_size_slack) * std::hypot(target.width, target.height) + options.voxel_size_m;
    so.max_rms_m = options.max_candidate_rms_m;
    so.plane_band_m = options.max_voxel_offset_m;
    so.range_noise_m = options.range_noise_m;
    so.min_lines = options.min_scan_lines;
    for (auto& sr : lidar_detail::segmentRegions(xyz, line, so)) {
      for (int& i : sr.points) i = subset[static_cast<size_t>(i)];
      Region r;
      r.sparse = true;
      r.lines = sr.lines;
      r.column_step_rad = sr.column_step_rad;
      r.line_step_rad = sr.line_step_rad;
      for (int i : sr.points) r.stats.add(pts[static_cast<size_t>(i)].p);
      // Far away a board has few returns: a few per line on each of its lines is enough.
      if (r.stats.n < sparseMinPoints(options)) continue;
      r.points = sr.points;
      Candidate c = scoreSparse(r, static_cast<int>(regions.size()), pts, target, options);
      bool known = false;
      for (const auto& other : candidates)
        known = known || (other.info.score >= 0 && (other.info.centroid - c.info.centroid).norm() < kSameBoardDistanceM);
      if (known) continue;
      std::unordered_set<int> voxels;
      for (int i : sr.points) {
        const auto& p = pts[static_cast<size_t>(i)].p;
        voxels.insert(grid.find(static_cast<int>(std::floor(p.x() / options.voxel_size_m)),
                                static_cast<int>(std::floor(p.y() / options.voxel_size_m)),
                                static_cast<int>(std::floor(p.z() / options.voxel_size_m))));
      }
      r.voxels.assign(voxels.begin(), voxels.end());
      regions.push_back(std::move(r));
      candidates.push_back(std::move(c));
    }
  }
  if (candidates.empty())
    return failure(std::move(det), LidarDetectionCode::kNoPlane,
                   "no planar region with at least " + std::to_string(options.min_board_points) + " points among " +
                       std::to_string(pts.size()) + " valid points");
  std::sort(candidates.begin(), candidates.end(), [](const Candidate& a, const Candidate& b) {
    const bool pa = a.info.score >= 0, pb = b.info.score >= 0;
    if (pa != pb) return pa;
    if (pa) return a.info.score > b.info.score;
    return a.info.num_points > b.info.num_points;
  });
  // History: board-like candidates at static places are background. When no moving one is
  // left, say so (the board is what moves).
  if (history && history->is_static) {
    int accepted = 0, dropped = 0;
    for (auto& c : candidates) {
      if (c.info.score < 0) continue;
      ++accepted;
      if (!history->is_static(c.info)) continue;
      c.info.score = -1.0;
      c.info.rejected_because = "static background (stayed put over the session)";
      ++dropped;
    }
    if (dropped > 0) {
      std::stable_sort(candidates.begin(), candidates.end(), [](const Candidate& a, const Candidate& b) {
        return (a.info.score >= 0) > (b.info.score >= 0);
      });
      if (dropped == accepted) {
        for (const auto& c : candidates) det.candidates.push_back(c.info);
        const auto& a = candidates.front().info.centroid;
        return failure(std::move(det), LidarDetectionCode::kAmbiguous,
                       "only static board-like planes (" + std::to_string(dropped) + ", nearest at " +
                           fmt("(%.2f, %.2f, %.2f) m): they stayed put over the session, the board is what moves", a.x(),
                               a.y(), a.z()));
      }
    }
  }
  for (const auto& c : candidates) det.candidates.push_back(c.info);
  const Candidate& best = candidates.front();
  if (best.info.score < 0) {
    const auto& c = best.info;
    return failure(std::move(det), LidarDetectionCode::kWrongSize,
                   "no board-sized plane: largest planar region (" + std::to_string(c.num_points) + " points at " +
                       fmt("%.1f m) is ", c.centroid.norm()) + c.rejected_because +
                       fmt("; declared %.3f x %.3f m", target.width, target.height));
  }
  const double ratio = history && history->strict_ambiguity ? 0.0 : options.ambiguity_ratio;
  if (options.reject_ambiguous && candidates.size() > 1 && candidates[1].info.score >= 0 &&
      candidates[1].info.score >= ratio * best.info.score &&
      (candidates[1].info.centroid - best.info.centroid).norm() > kSameBoardDistanceM) {
    const auto& a = best.info.centroid;
    const auto& b = candidates[1].info.centroid;
    return failure(std::move(det), LidarDetectionCode::kAmbiguous,
                   "ambiguous: two board-like planes, at " + fmt("(%.2f, %.2f, %.2f)", a.x(), a.y(), a.z()) + " and " +
                       fmt("(%.2f, %.2f, %.2f) m; set an ROI or capture a background", b.x(), b.y(), b.z()));
  }

  // Points of the winning region and of its neighbouring voxels (edge voxels mix the board
  // with what lies behind it, so they rarely join the region).
  const Region& region = regions[best.region];
  const int min_points = region.sparse ? sparseMinPoints(options) : options.min_board_points;
  std::vector<int> region_points, gathered;
  std::unordered_set<int> gathered_voxels;
  for (int vi : region.voxels) {
    const Voxel& v = grid.voxels[vi];
    for (int dx = -1; dx <= 1; ++dx)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dz = -1; dz <= 1; ++dz) {
          const int q = grid.find(v.ix + dx, v.iy + dy, v.iz + dz);
          if (q >= 0) gathered_voxels.insert(q);
        }
    if (!region.sparse)
      for (int j = 0; j < v.count; ++j) region_points.push_back(grid.sorted_points[v.first + j]);
  }
  if (region.sparse) region_points = region.points;
  for (int vi : gathered_voxels) {
    const Voxel& v = grid.voxels[vi];
    // Only voxels that belong to no other large plane (walls behind the board stay out).
    if (v.region >= 0 && v.region != best.region && regions[v.region].stats.n >= options.min_board_points) continue;
    for (int j = 0; j < v.count; ++j) gathered.push_back(grid.sorted_points[v.first + j]);
  }
  std::mt19937 rng(options.random_seed);
  const RefinedPlane refined = refinePlane(region_points, gathered, pts, options, rng);
  if (static_cast<int>(refined.inliers.size()) < min_points)
    return failure(std::move(det), LidarDetectionCode::kTooFewPoints,
                   "board candidate has only " + std::to_string(refined.inliers.size()) +
                       " points on its plane (need " + std::to_string(min_points) + ")");
  f.found = true;
  det.code = LidarDetectionCode::kFound;
  const LidarBoardDetection before_edges = det;
  f.plane = refined.plane;
  f.plane_rms_m = refined.rms;
  for (int i : refined.inliers) f.board_points.push_back(pts[i].p);
  extractEdges(cloud, pts, refined.inliers, target, options, rng, &det);
  if (!f.allEdgesValid()) return det;

  // Second pass: whatever touches the board near its plane (a body, an arm) lies outside the
  // quadrilateral of the four edges. Drop it, refit the plane and find the edges again.
  const Eigen::Vector3d centre = 0.25 * (f.corners[0] + f.corners[1] + f.corners[2] + f.corners[3]);
  std::array<Eigen::Vector3d, kNumEdges> outward;
  for (int j = 0; j < kNumEdges; ++j) {
    outward[j] = f.plane.normal.cross(f.edge_line_direction[j]);
    if (outward[j].dot(centre - f.edge_line_point[j]) > 0) outward[j] = -outward[j];
  }
  // Signed in-plane distance outside the edge quadrilateral (negative inside).
  auto outside = [&](const Eigen::Vector3d& p) {
    double d = -std::numeric_limits<double>::infinity();
    for (int j = 0; j < kNumEdges; ++j) d = std::max(d, outward[j].dot(p - f.edge_line_point[j]));
    return d;
  };
  PlaneStats core_stats;  // well inside: no rim mixed returns, nothing touching from outside
  for (int i : refined.inliers)
    if (outside(pts[i].p) < -kRimExclusionM) core_stats.add(pts[i].p);
  if (core_stats.n < min_points) return det;
  const PlaneFit fit = lidar_detail::fitPlane(core_stats);
  Plane plane{fit.normal(), fit.offset()};
  if (plane.offset < 0) plane = Plane{-plane.normal, -plane.offset};
  std::vector<int> board;
  double sum_sq = 0.0;
  for (int i : refined.inliers) {
    const double r = plane.signedDistance(pts[i].p);
    if (std::abs(r) >= options.plane_distance_threshold_m || outside(pts[i].p) >= options.edge_inlier_threshold_m)
      continue;
    board.push_back(i);
    sum_sq += r * r;
  }
  if (static_cast<int>(board.size()) < min_points) return det;
  LidarBoardDetection second = before_edges;
  second.features.plane = plane;
  second.features.plane_rms_m = std::sqrt(sum_sq / board.size());
  for (int i : board) second.features.board_points.push_back(pts[i].p);
  extractEdges(cloud, pts, board, target, options, rng, &second);
  return second.features.allEdgesValid() ? second : det;
}

}  // namespace

LidarBoardDetection detectLidarBoard(const LidarCloud& cloud, const Target& target,
                                     const LidarBoardDetectorOptions& options, const BackgroundModel* background) {
  return detectImpl(cloud, target, options, background, nullptr);
}

// ------------------------------------------------------------------------------------------
// Stateful detector: static places are background.
// ------------------------------------------------------------------------------------------
LidarBoardTracker::LidarBoardTracker(Target target, LidarBoardDetectorOptions detector, StaticMemoryOptions memory)
    : target_(std::move(target)), detector_(std::move(detector)), memory_(memory) {}

void LidarBoardTracker::reset() {
  places_.clear();
  frames_ = 0;
  last_stamp_ = -1e300;
}

bool LidarBoardTracker::isStatic(const Place& p) const {
  const long frames_since = frames_ - p.first_frame + 1;
  return p.last_s - p.first_s >= memory_.static_after_s &&
         p.seen >= memory_.min_seen_fraction * static_cast<double>(frames_since);
}

int LidarBoardTracker::numStaticPlaces() const {
  int n = 0;
  for (const auto& p : places_) n += isStatic(p);
  return n;
}

int LidarBoardTracker::match(const LidarBoardCandidate& c) const {
  const double min_cos = std::cos(memory_.max_normal_angle_deg * kRadPerDeg);
  int best = -1;
  double best_d = memory_.place_radius_m;
  for (size_t k = 0; k < places_.size(); ++k) {
    const double d = (places_[k].centroid - c.centroid).norm();
    if (d <= best_d && std::abs(places_[k].normal.dot(c.plane.normal)) >= min_cos) {
      best_d = d;
      best = static_cast<int>(k);
    }
  }
  return best;
}

LidarBoardDetection LidarBoardTracker::detect(const LidarCloud& cloud, const BackgroundModel* background) {
  if (!memory_.validate().empty()) {
    LidarBoardDetection det = detectLidarBoard(cloud, target_, detector_, background);
    if (det.features.found) return det;
    return failure(std::move(det), LidarDetectionCode::kInvalidOptions, "invalid static memory options: " + memory_.validate());
  }
  if (cloud.stamp < last_stamp_) reset();  // a replay started over
  last_stamp_ = cloud.stamp;
  ++frames_;
  History history;
  history.strict_ambiguity = memory_.strict_ambiguity;
  history.is_static = [this](const LidarBoardCandidate& c) {
    const int k = match(c);
    return k >= 0 && isStatic(places_[static_cast<size_t>(k)]);
  };
  LidarBoardDetection det = detectImpl(cloud, target_, detector_, background, &history);
  // Remember every board-like candidate of this cloud (accepted, or dropped as static).
  for (const auto& c : det.candidates) {
    if (c.score < 0 && c.rejected_because.rfind("static", 0) != 0) continue;
    const int k = match(c);
    if (k < 0) {
      Place p;
      p.centroid = c.centroid;
      p.normal = c.plane.normal;
      p.first_s = p.last_s = cloud.stamp;
      p.first_frame = p.last_frame = frames_;
      p.seen = 1;
      places_.push_back(p);
    } else {
      Place& p = places_[static_cast<size_t>(k)];
      if (p.last_frame == frames_) continue;  // two candidates of this cloud at one place
      p.last_s = cloud.stamp;
      p.last_frame = frames_;
      ++p.seen;
    }
  }
  places_.erase(std::remove_if(places_.begin(), places_.end(),
                               [&](const Place& p) { return cloud.stamp - p.last_s > memory_.forget_after_s; }),
                places_.end());
  return det;
}

}  // namespace board_calib
