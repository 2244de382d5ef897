// LiDAR board detector: options, reasons and the single-cloud detector (stages in
// lidar_candidates.cpp, lidar_plane.cpp, lidar_edges.cpp).
#include "detector_internal.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <unordered_set>

namespace board_calib {
namespace lidar_detail {

namespace {

// Options, target and cloud usable; false with the failure in det.
bool checkInputs(const LidarCloud& cloud, const Target& target,
                 const LidarBoardDetectorOptions& options, LidarBoardDetection* det) {
  auto& f = det->features;
  f.frame_id = cloud.frame_id;
  f.stamp = cloud.stamp;
  for (int j = 0; j < kNumEdges; ++j) {
    f.edge_line_point[j].setZero();
    f.edge_line_direction[j] = Eigen::Vector3d::UnitX();
    f.corners[j].setZero();
  }
  const std::string bad_options = options.validate();
  if (!bad_options.empty())
    *det = failure(std::move(*det), LidarDetectionCode::kInvalidOptions,
                   "invalid detector options: " + bad_options);
  else if (const std::string bad_target = target.validate(); !bad_target.empty())
    *det = failure(std::move(*det), LidarDetectionCode::kInvalidTarget,
                   "invalid target: " + bad_target);
  else if (cloud.points.empty())
    *det = failure(std::move(*det), LidarDetectionCode::kEmptyCloud, "empty cloud (0 points)");
  else
    return true;
  return false;
}

// History: board-like candidates at static places are background. When no moving one is left,
// says so (the board is what moves) and returns false.
bool dropStatic(const History& history, std::vector<Candidate>* candidates,
                LidarBoardDetection* det) {
  int accepted = 0, dropped = 0;
  for (auto& c : *candidates) {
    if (c.info.score < 0) continue;
    ++accepted;
    if (!history.is_static(c.info)) continue;
    c.info.score = -1.0;
    c.info.rejected_because = "static background (stayed put over the session)";
    ++dropped;
  }
  if (dropped == 0) return true;
  std::stable_sort(candidates->begin(), candidates->end(),
                   [](const Candidate& a, const Candidate& b) {
                     return (a.info.score >= 0) > (b.info.score >= 0);
                   });
  if (dropped < accepted) return true;
  for (const auto& c : *candidates) det->candidates.push_back(c.info);
  const auto& a = candidates->front().info.centroid;
  *det = failure(
      std::move(*det), LidarDetectionCode::kAmbiguous,
      "only static board-like planes (" + std::to_string(dropped) + ", nearest at " +
          fmt("(%.2f, %.2f, %.2f) m): they stayed put over the session, the board is what moves",
              a.x(), a.y(), a.z()));
  return false;
}

// Second chance: candidates outside the expected region are rejected with the reason; fails
// (with the nearest one's reason) when none is left.
bool keepExpected(const History& history, std::vector<Candidate>* candidates,
                  LidarBoardDetection* det) {
  std::string first_reason;
  for (auto& c : *candidates) {
    if (c.info.score < 0) continue;
    std::string why = history.outside_expected(c.info);
    if (why.empty()) continue;
    if (first_reason.empty()) first_reason = why;
    c.info.score = -1.0;
    c.info.rejected_because = std::move(why);
  }
  std::stable_sort(candidates->begin(), candidates->end(),
                   [](const Candidate& a, const Candidate& b) {
                     return (a.info.score >= 0) > (b.info.score >= 0);
                   });
  if (candidates->front().info.score >= 0) return true;
  for (const auto& c : *candidates) det->candidates.push_back(c.info);
  *det = failure(std::move(*det), LidarDetectionCode::kWrongSize,
                 first_reason.empty()
                     ? "no board-sized plane near the back-projected image board"
                     : "no board-sized plane near the back-projected image board (best: " +
                           first_reason + ")");
  return false;
}

// The best candidate must be board-like and, unless told otherwise, clearly ahead of any other
// board-like plane elsewhere.
bool chooseBest(const std::vector<Candidate>& candidates, const Target& target,
                const LidarBoardDetectorOptions& options, const History* history,
                LidarBoardDetection* det) {
  const Candidate& best = candidates.front();
  if (best.info.score < 0) {
    const auto& c = best.info;
    *det = failure(std::move(*det), LidarDetectionCode::kWrongSize,
                   "no board-sized plane: largest planar region (" + std::to_string(c.num_points) +
                       " points at " + fmt("%.1f m) is ", c.centroid.norm()) + c.rejected_because +
                       fmt("; declared %.3f x %.3f m", target.width, target.height));
    return false;
  }
  const double ratio = history && history->strict_ambiguity ? 0.0 : options.ambiguity_ratio;
  if (options.reject_ambiguous && candidates.size() > 1 && candidates[1].info.score >= 0 &&
      candidates[1].info.score >= ratio * best.info.score &&
      (candidates[1].info.centroid - best.info.centroid).norm() > kSameBoardDistanceM) {
    const auto& a = best.info.centroid;
    const auto& b = candidates[1].info.centroid;
    *det = failure(
        std::move(*det), LidarDetectionCode::kAmbiguous,
        "ambiguous: two board-like planes, at " + fmt("(%.2f, %.2f, %.2f)", a.x(), a.y(), a.z()) +
            " and " +
            fmt("(%.2f, %.2f, %.2f) m; set an ROI or capture a background", b.x(), b.y(), b.z()));
    return false;
  }
  return true;
}

// Second pass: whatever touches the board near its plane (a body, an arm) lies outside the
// quadrilateral of the four edges. Drops it, refits the plane and finds the edges again; returns
// `det` when that gives nothing better.
LidarBoardDetection refineWithoutTouching(
    const LidarCloud& cloud, const std::vector<ValidPoint>& pts, const RefinedPlane& refined,
    const Target& target, const LidarBoardDetectorOptions& options, int min_points,
    std::mt19937& rng, const LidarBoardDetection& before_edges, LidarBoardDetection det) {
  const auto& f = det.features;
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
    if (std::abs(r) >= options.plane_distance_threshold_m ||
        outside(pts[i].p) >= options.edge_inlier_threshold_m)
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

// Candidates of one cloud, best first: planar voxel regions, then scan-line segments.
std::vector<Candidate> findCandidates(const LidarCloud& cloud, const std::vector<ValidPoint>& pts,
                                      const Target& target,
                                      const LidarBoardDetectorOptions& options, VoxelGrid* grid,
                                      std::vector<Region>* regions) {
  *grid = buildVoxels(pts, options.voxel_size_m);
  *regions = growPlanarRegions(*grid, options);
  std::vector<Candidate> candidates;
  for (size_t r = 0; r < regions->size(); ++r) {
    if ((*regions)[r].stats.n < options.min_board_points) continue;  // not worth reporting
    candidates.push_back(
        scoreRegion((*regions)[r], static_cast<int>(r), *grid, pts, target, options));
  }
  if (options.sparse_candidates)
    addSparseCandidates(cloud, pts, *grid, target, options, regions, &candidates);
  std::sort(candidates.begin(), candidates.end(), [](const Candidate& a, const Candidate& b) {
    const bool pa = a.info.score >= 0, pb = b.info.score >= 0;
    if (pa != pb) return pa;
    if (pa) return a.info.score > b.info.score;
    return a.info.num_points > b.info.num_points;
  });
  return candidates;
}

}  // namespace

LidarBoardDetection detectImpl(const LidarCloud& cloud, const Target& target,
                               const LidarBoardDetectorOptions& options,
                               const BackgroundModel* background, const History* history) {
  LidarBoardDetection det;
  if (!checkInputs(cloud, target, options, &det)) return det;
  auto& f = det.features;
  const std::vector<ValidPoint> pts = validPoints(cloud, options, background);
  det.num_valid_points = static_cast<int>(pts.size());
  if (pts.size() < 3) {
    std::string why = "no valid returns among " + std::to_string(cloud.points.size()) +
                      " points (NaN, zero or out of " +
                      fmt("%.1f..%.1f m", options.min_range_m, options.max_range_m) + ")";
    if (options.use_roi) why += ", or outside the ROI";
    if (background && !background->empty()) why += ", or background";
    return failure(std::move(det), LidarDetectionCode::kNoValidPoints, why);
  }

  VoxelGrid grid;
  std::vector<Region> regions;
  std::vector<Candidate> candidates = findCandidates(cloud, pts, target, options, &grid, &regions);
  if (candidates.empty())
    return failure(std::move(det), LidarDetectionCode::kNoPlane,
                   "no planar region with at least " + std::to_string(options.min_board_points) +
                       " points among " + std::to_string(pts.size()) + " valid points");
  if (history && history->outside_expected && !keepExpected(*history, &candidates, &det))
    return det;
  if (history && history->is_static && !dropStatic(*history, &candidates, &det)) return det;
  for (const auto& c : candidates) det.candidates.push_back(c.info);
  if (!chooseBest(candidates, target, options, history, &det)) return det;

  const Region& region = regions[static_cast<size_t>(candidates.front().region)];
  const int min_points = region.sparse ? sparseMinPoints(options) : options.min_board_points;
  std::vector<int> region_points, gathered;
  gatherRegionPoints(regions, candidates.front().region, grid, pts, options, &region_points,
                     &gathered);
  std::mt19937 rng(options.random_seed);
  const RefinedPlane refined = refinePlane(region_points, gathered, pts, options, rng);
  if (static_cast<int>(refined.inliers.size()) < min_points)
    return failure(std::move(det), LidarDetectionCode::kTooFewPoints,
                   "board candidate has only " + std::to_string(refined.inliers.size()) +
                       " points on its plane (need " + std::to_string(min_points) + ")");
  // The refined plane is the candidate's own: a plane that keeps fewer than half of the points
  // the candidate was judged on belongs to something around it.
  const std::unordered_set<int> inlier_set(refined.inliers.begin(), refined.inliers.end());
  size_t kept = 0;
  for (int i : region_points) kept += inlier_set.count(i);
  if (2 * kept < region_points.size())
    return failure(std::move(det), LidarDetectionCode::kTooFewPoints,
                   "the board candidate's plane, refined, keeps only " + std::to_string(kept) +
                       " of its " + std::to_string(region_points.size()) + " points");
  f.found = true;
  det.code = LidarDetectionCode::kFound;
  const LidarBoardDetection before_edges = det;
  f.plane = refined.plane;
  f.plane_rms_m = refined.rms;
  for (int i : refined.inliers) f.board_points.push_back(pts[i].p);
  extractEdges(cloud, pts, refined.inliers, target, options, rng, &det);
  if (!det.features.allEdgesValid()) return det;
  return refineWithoutTouching(cloud, pts, refined, target, options, min_points, rng, before_edges,
                               std::move(det));
}

}  // namespace lidar_detail

using lidar_detail::failure;
using lidar_detail::kRadPerDeg;

std::string LidarBoardDetectorOptions::validate() const {
  if (!(min_range_m >= 0.0)) return "min_range_m must be >= 0";
  if (!(max_range_m > min_range_m)) return "max_range_m must be > min_range_m";
  if (use_roi && !(roi.min.array() < roi.max.array()).all())
    return "roi.min must be < roi.max on every axis";
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
  if (!(ambiguity_ratio > 0.0 && ambiguity_ratio <= 1.0))
    return "ambiguity_ratio must be in (0, 1]";
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
  if (!(beam_divergence_deg >= 0.0 && beam_divergence_deg < 5.0))
    return "beam_divergence_deg must be in [0, 5)";
  if (min_scan_lines < 3) return "min_scan_lines must be >= 3 (two lines give no edges)";
  if (!(range_noise_m >= 0.0 && range_noise_m < 1.0)) return "range_noise_m must be in [0, 1) m";
  if (!(sparse_size_slack >= 0.0 && sparse_size_slack <= 0.5))
    return "sparse_size_slack must be in [0, 0.5]";
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

LidarBoardDetection detectLidarBoard(const LidarCloud& cloud, const Target& target,
                                     const LidarBoardDetectorOptions& options,
                                     const BackgroundModel* background) {
  return lidar_detail::detectImpl(cloud, target, options, background, nullptr);
}

LidarBoardDetection detectLidarBoardNear(const LidarCloud& cloud, const Target& target,
                                         const LidarBoardDetectorOptions& options,
                                         const ExpectedLidarBoard& expected) {
  const auto& q = expected.corners;
  const Eigen::Vector3d centre = 0.25 * (q[0] + q[1] + q[2] + q[3]);
  Eigen::Vector3d normal = (q[2] - q[0]).cross(q[3] - q[1]);
  const bool flat = normal.norm() > 1e-9;
  if (flat) normal.normalize();
  lidar_detail::History history;
  history.outside_expected = [&](const LidarBoardCandidate& c) -> std::string {
    if (!flat) return "no expected board";
    const double off_plane = std::abs(normal.dot(c.centroid - centre));
    // In-plane distance outside the expected quadrilateral (negative inside).
    double outside = -std::numeric_limits<double>::infinity();
    for (int j = 0; j < kNumEdges; ++j) {
      const Eigen::Vector3d a = q[j], b = q[(j + 1) % kNumEdges];
      Eigen::Vector3d out = normal.cross(b - a).normalized();
      if (out.dot(centre - a) > 0) out = -out;
      outside = std::max(outside, out.dot(c.centroid - a));
    }
    if (off_plane <= expected.tolerance_m && outside <= expected.tolerance_m) return {};
    return lidar_detail::fmt(
        "centroid %.2f m off the expected plane and %.2f m outside the expected board "
        "(tolerance %.2f m)",
        off_plane, std::max(outside, 0.0), expected.tolerance_m);
  };
  return lidar_detail::detectImpl(cloud, target, options, nullptr, &history);
}

}  // namespace board_calib
