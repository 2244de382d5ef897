// LiDAR board detector, stage 3: the board plane refined from its region and the points around it.
#include "detector_internal.h"

#include <board_calib/core/common/statistics.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <unordered_set>

namespace board_calib {
namespace lidar_detail {

RefinedPlane refinePlane(const std::vector<int>& region_points, const std::vector<int>& gathered,
                         const std::vector<ValidPoint>& pts, const LidarBoardDetectorOptions& o,
                         std::mt19937& rng) {
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
    band_m = std::clamp(kAdaptiveBandSigmas * std::sqrt(sum_sq / inliers.size()), thr,
                        kMaxAdaptiveBandFactor * thr);
    best.inliers = std::move(inliers);
  }
  // Robust scale of the residuals: a tighter band drops mixed returns at the board's rim (they
  // lie between the board and whatever is behind it) that the fixed threshold let in.
  if (best.inliers.size() >= 3) {
    std::vector<double> abs_res;
    abs_res.reserve(best.inliers.size());
    for (int i : best.inliers) abs_res.push_back(std::abs(best_n.dot(pts[i].p) - best_d));
    const double sigma = kMadToSigma * medianOf(std::move(abs_res));
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

// Points of the winning region and of its neighbouring voxels (edge voxels mix the board
// with what lies behind it, so they rarely join the region).
void gatherRegionPoints(const std::vector<Region>& regions, int region_id, const VoxelGrid& grid,
                        const std::vector<ValidPoint>& pts,
                        const LidarBoardDetectorOptions& options, std::vector<int>* region_points,
                        std::vector<int>* gathered) {
  const Region& region = regions[static_cast<size_t>(region_id)];
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
      for (int j = 0; j < v.count; ++j) region_points->push_back(grid.sorted_points[v.first + j]);
  }
  if (region.sparse) *region_points = region.points;
  // A voxel region's own voxels carry its id; a sparse candidate's may have grown a region of
  // their own (a part of the board rejected as not rectangular: its lower half, seen by more
  // lines), and stay in too.
  std::unordered_set<int> own;
  if (region.sparse) own.insert(region.voxels.begin(), region.voxels.end());
  const PlaneFit board = fitPlane(region.stats);
  // The band follows the board's measured noise (3 sigma), not the looser RANSAC threshold.
  const double band =
      std::clamp(kAdaptiveBandSigmas * std::sqrt(board.eigenvalues[0]), kMinRobustBandM,
                 kMaxAdaptiveBandFactor * options.plane_distance_threshold_m);
  std::vector<int> on_board;
  for (int vi : gathered_voxels) {
    const Voxel& v = grid.voxels[vi];
    const bool other_plane = v.region >= 0 && v.region != region_id && !own.count(vi) &&
                             regions[v.region].stats.n >= options.min_board_points;
    if (!other_plane) {
      for (int j = 0; j < v.count; ++j) gathered->push_back(grid.sorted_points[v.first + j]);
      continue;
    }
    // A voxel of another large plane (a wall behind the board, the holder's body below it)
    // gives its returns on the board's plane only when its other returns lie in a layer of
    // their own, with a gap between: the board's rim in a voxel that straddles the board's side
    // and the body behind it. A surface that crosses the board's plane (a wall, a body touching
    // the board) has as many returns just outside the band as inside it, and gives none.
    on_board.clear();
    int in_gap = 0;
    for (int j = 0; j < v.count; ++j) {
      const int i = grid.sorted_points[v.first + j];
      const double d = std::abs(board.normal().dot(pts[i].p) - board.offset());
      if (d < band)
        on_board.push_back(i);
      else
        in_gap += d < 2.0 * band;
    }
    if (in_gap <= kMaxLayerGapShare * on_board.size())
      gathered->insert(gathered->end(), on_board.begin(), on_board.end());
  }
}

}  // namespace lidar_detail
}  // namespace board_calib
