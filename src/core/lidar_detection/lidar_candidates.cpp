// LiDAR board detector, stages 1-2: valid points, planar voxel regions and scan-line segment
// candidates, each scored against the declared board.
#include "detector_internal.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <unordered_set>

namespace board_calib {
namespace lidar_detail {

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

VoxelGrid buildVoxels(const std::vector<ValidPoint>& pts, double size) {
  VoxelGrid g;
  g.index.reserve(pts.size() / 4 + 16);
  std::vector<int> voxel_of(pts.size());
  for (size_t i = 0; i < pts.size(); ++i) {
    const auto& p = pts[i].p;
    const int ix = static_cast<int>(std::floor(p.x() / size));
    const int iy = static_cast<int>(std::floor(p.y() / size));
    const int iz = static_cast<int>(std::floor(p.z() / size));
    bool inserted = false;
    const int number =
        g.index.emplace(voxelKey(ix, iy, iz), static_cast<int>(g.voxels.size()), &inserted);
    if (inserted) {
      Voxel v;
      v.ix = ix;
      v.iy = iy;
      v.iz = iz;
      g.voxels.push_back(v);
    }
    Voxel& v = g.voxels[number];
    v.stats.add(p);
    v.count++;
    voxel_of[i] = number;
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
      const Voxel& head_voxel = g.voxels[queue[head++]];
      const int cx = head_voxel.ix, cy = head_voxel.iy, cz = head_voxel.iz;
      for (int dx = -1; dx <= 1; ++dx)
        for (int dy = -1; dy <= 1; ++dy)
          for (int dz = -1; dz <= 1; ++dz) {
            if (!dx && !dy && !dz) continue;
            const int q = g.find(cx + dx, cy + dy, cz + dz);
            if (q < 0 || g.voxels[q].region >= 0) continue;
            const Voxel& nv = g.voxels[q];
            const Eigen::Vector3d n = plane.normal();
            const double offset = std::abs(n.dot(nv.stats.mean()) - plane.offset());
            const double thickness = std::sqrt(std::max(0.0, n.dot(nv.stats.covariance() * n)));
            if (offset > o.max_voxel_offset_m || thickness > o.max_voxel_thickness_m) continue;
            // A voxel with a reliable normal of its own must agree (a body touching the board
            // at a shallow angle stays out).
            if (nv.stats.n >= o.min_voxel_points && fits[q].eigenvalues[1] > min_spread_sq &&
                std::abs(fits[q].normal().dot(n)) < min_normal_cos)
              continue;
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

bool boardFrameAtCentroid(const std::vector<ValidPoint>& pts, const std::vector<int>& board,
                          const Plane& plane, Eigen::Vector3d* centroid, PlaneFrame* frame) {
  Eigen::Vector3d c = Eigen::Vector3d::Zero();
  for (int i : board) c += pts[i].p;
  c /= static_cast<double>(board.size());
  *centroid = c - plane.normal * plane.signedDistance(c);
  return makePlaneFrame(plane.normal, *centroid, frame);
}

namespace {

// A candidate's centroid, plane (offset >= 0) and flatness from its plane fit, not scored yet.
Candidate unscoredCandidate(const PlaneFit& fit, int num_points, int region_id) {
  Candidate c;
  c.region = region_id;
  auto& info = c.info;
  info.centroid = fit.centroid;
  info.num_points = num_points;
  info.plane.normal = fit.normal();
  info.plane.offset = fit.offset();
  if (info.plane.offset < 0) {
    info.plane.normal = -info.plane.normal;
    info.plane.offset = -info.plane.offset;
  }
  info.rms_m = std::sqrt(fit.eigenvalues[0]);
  info.score = -1.0;
  return c;
}

// |log| of the measured over the declared sides, larger with larger.
double sizeError(const Eigen::Vector2d& sides, const Target& target) {
  return std::abs(std::log(std::max(1e-6, sides.x()) / std::max(target.width, target.height))) +
         std::abs(std::log(std::max(1e-6, sides.y()) / std::min(target.width, target.height)));
}

// Two size estimates: the hull's min-area rectangle (exact for a clean board, inflated by a
// hand or an arm touching it) and the second moments in info->rectangle_m (robust to such
// appendages, biased where the beams are unevenly spaced, e.g. VLP-32C). The board needs one to
// fit; the better one is kept. False with the reason when neither fits.
bool chooseSize(const Points2& hull, const Target& target, const LidarBoardDetectorOptions& o,
                LidarBoardCandidate* info) {
  const double big_side = std::max(target.width, target.height);
  const double small_side = std::min(target.width, target.height);
  const Eigen::Vector2d moments = info->rectangle_m;
  const Eigen::Vector2d hull_rect = lidar_detail::minAreaRectangle(hull);
  auto sizeOk = [&](const Eigen::Vector2d& sides) {
    const double rb = sides.x() / big_side, rs = sides.y() / small_side;
    return rb >= o.min_size_ratio && rs >= o.min_size_ratio && rb <= o.max_size_ratio &&
           rs <= o.max_size_ratio;
  };
  const bool moments_ok = sizeOk(moments), hull_ok = sizeOk(hull_rect);
  info->rectangle_m =
      (hull_ok && (!moments_ok || sizeError(hull_rect, target) <= sizeError(moments, target)))
          ? hull_rect
          : moments;
  if (moments_ok || hull_ok) return true;
  const bool large =
      hull_rect.x() > o.max_size_ratio * big_side || hull_rect.y() > o.max_size_ratio * small_side;
  info->rectangle_m = hull_rect;
  info->rejected_because = fmt(large ? "too large (%.2f x %.2f m)" : "too small (%.2f x %.2f m)",
                               hull_rect.x(), hull_rect.y());
  return false;
}

}  // namespace

Candidate scoreRegion(const Region& r, int region_id, const VoxelGrid& g,
                      const std::vector<ValidPoint>& pts, const Target& target,
                      const LidarBoardDetectorOptions& o) {
  const PlaneFit fit = lidar_detail::fitPlane(r.stats);
  Candidate c = unscoredCandidate(fit, r.stats.n, region_id);
  auto& info = c.info;
  const double big_side = std::max(target.width, target.height);
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
  if (!chooseSize(hull, target, o, &info)) return c;
  if (info.fill_ratio < o.min_fill_ratio) {
    info.rejected_because =
        fmt("not rectangular enough (hull fills %.0f%% of the board)", 100 * info.fill_ratio);
    return c;
  }
  if (info.rms_m > o.max_candidate_rms_m) {
    info.rejected_because = fmt("not flat (RMS %.3f m)", info.rms_m);
    return c;
  }
  const double shape_error =
      sizeError(info.rectangle_m, target) +
      kFillWeight * std::abs(std::log(std::max(info.fill_ratio, kMinFillForLog))) +
      kRmsWeight * info.rms_m / o.max_candidate_rms_m;
  // Support: the held board is near the sensor and densely sampled, so point count weighs as
  // much as shape (a far board-sized door or cabinet has a tenth of its points).
  info.score = info.num_points * std::exp(-kShapeErrorScale * shape_error);
  return c;
}

// Fewest returns of a sparse candidate: a few on each of the lines it needs.
int sparseMinPoints(const LidarBoardDetectorOptions& o) {
  return std::min(o.min_board_points, kSparsePointsPerLine * o.min_scan_lines);
}

// A candidate from scan-line segments. Its sampling sets the tolerances: the board's true
// outline lies up to one line spacing (range x elevation step) beyond the outermost lines and
// up to one column step (plus the beam's bloom) beyond each line's extremes. It must fit inside
// the declared board (plus those tolerances and the range noise) and, with them, be able to
// reach the board's smaller side in both directions.
Candidate scoreSparse(const Region& r, int region_id, const std::vector<ValidPoint>& pts,
                      const Target& target, const LidarBoardDetectorOptions& o) {
  const PlaneFit fit = lidar_detail::fitPlane(r.stats);
  Candidate c = unscoredCandidate(fit, r.stats.n, region_id);
  auto& info = c.info;
  info.scan_lines = r.lines;
  if (r.lines < o.min_scan_lines) {
    info.rejected_because = "seen by " + std::to_string(r.lines) + " scan lines (need " +
                            std::to_string(o.min_scan_lines) + ")";
    return c;
  }
  if (info.rms_m > o.max_candidate_rms_m) {
    info.rejected_because = fmt("not flat (RMS %.3f m)", info.rms_m);
    return c;
  }
  // Cheap first: the covariance's extent (a uniform segment of length a has variance a^2/12).
  const double extent = std::sqrt(kUniformSideFromVariance * fit.eigenvalues[2]);
  if (extent > kPrefilterExtentFactor * (1.0 + o.sparse_size_slack) *
                   std::max(target.width, target.height)) {
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
  if (up < o.min_size_ratio * small_side ||
      across < kSparseMinWidthRatio * std::max(0.0, small_side - 0.5 * line_m)) {
    info.rectangle_m = hi - lo;
    info.rejected_because =
        fmt("too small: %.2f m high, %.2f m wide with the sampling gaps (%.2f m between lines)",
            hi.y() - lo.y(), hi.x() - lo.x(), line_m);
    return c;
  }
  const Points2 hull = lidar_detail::convexHull(projected);
  info.fill_ratio = lidar_detail::polygonArea(hull) / (target.width * target.height);
  info.rectangle_m = lidar_detail::minAreaRectangle(hull);
  const double slack = 1.0 + o.sparse_size_slack;
  // Only the hull decides whether the points fit inside.
  const auto inside = lidar_detail::fitRectangle(hull, {}, {}, slack * target.width,
                                                 slack * target.height, tolerance);
  if (!inside.ok) {
    info.rejected_because =
        fmt("too large: %.2f x %.2f m does not fit in the board (sampling %.2f m across, %.2f m "
            "between lines)",
            info.rectangle_m.x(), info.rectangle_m.y(), column_m, line_m);
    return c;
  }
  info.score = info.num_points *
               std::exp(-kShapeErrorScale * kRmsWeight * info.rms_m / o.max_candidate_rms_m);
  return c;
}

// Far boards: scan lines spaced wider than a voxel leave no planar voxel; grow planes from
// scan-line segments instead. A board the voxels already found is not added twice.
void addSparseCandidates(const LidarCloud& cloud, const std::vector<ValidPoint>& pts,
                         const VoxelGrid& grid, const Target& target,
                         const LidarBoardDetectorOptions& options, std::vector<Region>* regions,
                         std::vector<Candidate>* candidates) {
  std::vector<int> cloud_index(pts.size());
  std::vector<Eigen::Vector3d> xyz(pts.size());
  for (size_t i = 0; i < pts.size(); ++i) {
    cloud_index[i] = pts[i].cloud_index;
    xyz[i] = pts[i].p;
  }
  std::string source;
  const std::vector<int> all_lines = lidar_detail::scanLinesOf(
      cloud, cloud_index, xyz, options.elevation_gap_deg * kRadPerDeg, &source);
  // Points the voxels already explain (floor, walls: larger than the board; boards they
  // accepted) need no second look: the segments run on the rest, which keeps this cheap.
  std::vector<uint8_t> explained(regions->size(), 0);
  const double big_side = std::max(target.width, target.height);
  for (const auto& c : *candidates)
    explained[static_cast<size_t>(c.region)] =
        c.info.score >= 0 || c.info.rectangle_m.x() > options.max_size_ratio * big_side;
  std::vector<uint8_t> skip(pts.size(), 0);
  for (const auto& v : grid.voxels)
    if (v.region >= 0 && explained[static_cast<size_t>(v.region)])
      for (int j = 0; j < v.count; ++j)
        skip[static_cast<size_t>(grid.sorted_points[v.first + j])] = 1;
  // Only where the lines are too far apart for the voxels (fewer than two lines in a voxel's
  // height can seed no plane) do the segments add anything.
  const std::vector<double> gap = lidar_detail::lineGaps(xyz, all_lines);
  std::vector<int> subset;  // indices into pts, in cloud order (lines come in firing order)
  subset.reserve(pts.size());
  for (size_t i = 0; i < pts.size(); ++i)
    if (!skip[i] && xyz[i].norm() * gap[static_cast<size_t>(all_lines[i])] >
                        kSparseLineGapVoxels * options.voxel_size_m)
      subset.push_back(static_cast<int>(i));
  xyz.resize(subset.size());
  std::vector<int> line(subset.size());
  for (size_t k = 0; k < subset.size(); ++k) {
    xyz[k] = pts[static_cast<size_t>(subset[k])].p;
    line[k] = all_lines[static_cast<size_t>(subset[k])];
  }
  lidar_detail::SegmentOptions so;
  so.max_length_m = (1.0 + options.sparse_size_slack) * std::hypot(target.width, target.height) +
                    options.voxel_size_m;
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
    Candidate c = scoreSparse(r, static_cast<int>(regions->size()), pts, target, options);
    bool known = false;
    for (const auto& other : *candidates)
      known = known || (other.info.score >= 0 &&
                        (other.info.centroid - c.info.centroid).norm() < kSameBoardDistanceM);
    if (known) continue;
    std::unordered_set<int> voxels;
    for (int i : sr.points) {
      const auto& p = pts[static_cast<size_t>(i)].p;
      voxels.insert(grid.find(static_cast<int>(std::floor(p.x() / options.voxel_size_m)),
                              static_cast<int>(std::floor(p.y() / options.voxel_size_m)),
                              static_cast<int>(std::floor(p.z() / options.voxel_size_m))));
    }
    r.voxels.assign(voxels.begin(), voxels.end());
    regions->push_back(std::move(r));
    candidates->push_back(std::move(c));
  }
}

}  // namespace lidar_detail
}  // namespace board_calib
