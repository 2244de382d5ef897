#include <board_calib/core/common/statistics.h>
#include <board_calib/core/pipeline/second_chance.h>

#include <algorithm>
#include <cmath>
#include <sstream>
#include <vector>

namespace board_calib {
namespace {

constexpr double kRadPerDeg = M_PI / 180.0;

// The sighting nearest to `stamp` within the tolerance, or nullptr.
template <typename Sighting>
const Sighting* nearest(const std::map<double, Sighting>& sightings, double stamp,
                        double tolerance_s) {
  const Sighting* best = nullptr;
  double best_dt = tolerance_s;
  for (auto it = sightings.lower_bound(stamp - tolerance_s);
       it != sightings.end() && it->first <= stamp + tolerance_s; ++it) {
    const double dt = std::abs(it->first - stamp);
    if (dt <= best_dt) {
      best_dt = dt;
      best = &it->second;
    }
  }
  return best;
}

// 1 sigma of where the prior puts a point at `range_m` from the LiDAR: its translation error plus
// its rotation error swung over the range.
double priorSigmaM(const SecondChancePrior& prior, double range_m) {
  return prior.translation_sigma_m + range_m * prior.rotation_sigma_rad;
}

}  // namespace

std::string SecondChanceOptions::validate() const {
  if (!(sigma_factor >= 1.0 && sigma_factor <= 10.0)) return "sigma_factor must be in [1, 10]";
  if (!(min_rotation_sigma_deg >= 0.0)) return "min_rotation_sigma_deg must be >= 0";
  if (!(min_translation_sigma_m >= 0.0)) return "min_translation_sigma_m must be >= 0";
  if (!(corner_sigma_px > 0.0)) return "corner_sigma_px must be > 0";
  if (!(min_tolerance_px >= 0.0)) return "min_tolerance_px must be >= 0";
  if (min_consensus_boards < 3) return "min_consensus_boards must be >= 3";
  return {};
}

ImageSighting imageSighting(const CameraBoardFeatures& features, const CameraModel& camera,
                            const Target& target, const SecondChanceOptions& options) {
  ImageSighting s;
  s.camera_T_board = features.camera_T_board;
  // Depth from the board's apparent size: d = f w / w_px, so sigma_d = d^2 sigma_px / (f w).
  const double depth = (features.camera_T_board * target.center()).z();
  const double f = camera.K()(0, 0);
  const double side = std::min(target.width, target.height);
  s.depth_sigma_m = depth * depth * options.corner_sigma_px / (f * side);
  return s;
}

LidarSighting lidarSighting(const LidarBoardFeatures& features) {
  LidarSighting s;
  s.corners = features.corners;
  s.corners_valid = features.allEdgesValid();
  if (!features.board_points.empty()) {
    for (const auto& p : features.board_points) s.centroid += p;
    s.centroid /= static_cast<double>(features.board_points.size());
  }
  // Consecutive extremes of one edge come from adjacent scan lines: their gap is the sampling.
  std::vector<double> gaps;
  for (const auto& edge : features.edge_points) {
    std::vector<Eigen::Vector3d> pts(edge.begin(), edge.end());
    if (pts.size() < 2) continue;
    const Eigen::Vector3d d = (pts.back() - pts.front()).normalized();
    std::sort(pts.begin(), pts.end(), [&](const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
      return a.dot(d) < b.dot(d);
    });
    for (size_t i = 1; i < pts.size(); ++i) gaps.push_back((pts[i] - pts[i - 1]).norm());
  }
  if (!gaps.empty()) s.line_spacing_m = medianOf(std::move(gaps));
  return s;
}

double secondChanceWindowS(const SessionOptions& session) {
  return session.still_window_s + session.sync_tolerance_s;
}

int secondChanceCandidates(const BoardSightings& sightings, double window_s, const Target& target) {
  int n = 0;
  if (target.type == TargetType::kPlain)
    for (double t : sightings.images_missed) n += nearest(sightings.clouds, t, window_s) != nullptr;
  for (double t : sightings.clouds_missed) n += nearest(sightings.images, t, window_s) != nullptr;
  return n;
}

std::optional<SecondChancePrior> secondChancePrior(const PairCalibration& run,
                                                   const BoardSightings& first_pass,
                                                   const SecondChanceOptions& options,
                                                   std::string* why_not) {
  const MethodRun* chosen = run.chosenRun();
  if (run.failed() || !chosen) {
    if (why_not) *why_not = "the first calibration failed: " + run.reason;
    return std::nullopt;
  }
  SecondChancePrior prior;
  prior.camera_T_lidar = chosen->solution.camera_T_lidar;
  const PoseStddev& sd = chosen->verdict.stddev;
  prior.rotation_sigma_rad =
      std::max(sd.rotation_deg.maxCoeff(), options.min_rotation_sigma_deg) * kRadPerDeg;
  prior.translation_sigma_m =
      std::max(sd.translation_m.maxCoeff(), options.min_translation_sigma_m);
  prior.first_pass = first_pass;
  return prior;
}

std::optional<ExpectedBoard> expectedImageBoard(const SecondChancePrior& prior, double stamp,
                                                double window_s, const CameraModel& camera,
                                                const SecondChanceOptions& options,
                                                std::string* why_not) {
  const LidarSighting* s = nearest(prior.first_pass.clouds, stamp, window_s);
  if (!s) {
    *why_not = "no LiDAR board around this time either";
    return std::nullopt;
  }
  if (!s->corners_valid) {
    *why_not = "the LiDAR board has no four edges to project";
    return std::nullopt;
  }
  ExpectedBoard expected;
  const double f = camera.K()(0, 0);
  double tolerance = 0.0;
  for (int j = 0; j < kNumEdges; ++j) {
    const Eigen::Vector3d p = prior.camera_T_lidar * s->corners[static_cast<size_t>(j)];
    if (!camera.projectUndistorted(p, &expected.corners_px[static_cast<size_t>(j)])) {
      *why_not = "the LiDAR board projects behind the camera";
      return std::nullopt;
    }
    // The prior's error and a LiDAR corner's (up to one scan-line gap: the corner is extrapolated
    // beyond the last line), seen at this corner's depth.
    const double range = s->corners[static_cast<size_t>(j)].norm();
    const double metres = options.sigma_factor * priorSigmaM(prior, range) + s->line_spacing_m;
    tolerance = std::max(tolerance, f * metres / p.z());
  }
  expected.tolerance_px = std::max(tolerance, options.min_tolerance_px);
  return expected;
}

std::optional<ExpectedLidarBoard> expectedLidarBoard(const SecondChancePrior& prior, double stamp,
                                                     double window_s, const Target& target,
                                                     const SecondChanceOptions& options,
                                                     std::string* why_not) {
  const ImageSighting* s = nearest(prior.first_pass.images, stamp, window_s);
  if (!s) {
    *why_not = "no image board around this time either";
    return std::nullopt;
  }
  const Eigen::Isometry3d lidar_T_board = prior.camera_T_lidar.inverse() * s->camera_T_board;
  ExpectedLidarBoard expected;
  const auto corners = target.outerCorners();
  for (int j = 0; j < kNumEdges; ++j)
    expected.corners[static_cast<size_t>(j)] = lidar_T_board * corners[static_cast<size_t>(j)];
  // The prior's error, the image pose's depth error, and the LiDAR's own sampling: a candidate's
  // centroid moves by up to a scan-line gap with the lines that fall on the board. The gap is
  // the one measured on the first pass's LiDAR boards, scaled to this range.
  const double range = (lidar_T_board * target.center()).norm();
  double spacing_per_m = 0.0;
  int n = 0;
  for (const auto& [t, c] : prior.first_pass.clouds)
    if (c.line_spacing_m > 0 && c.centroid.norm() > 0) {
      spacing_per_m += c.line_spacing_m / c.centroid.norm();
      ++n;
    }
  if (n > 0) spacing_per_m /= n;
  expected.tolerance_m =
      options.sigma_factor * (priorSigmaM(prior, range) + s->depth_sigma_m) + spacing_per_m * range;
  return expected;
}

std::string SecondChanceStats::summary() const {
  std::ostringstream s;
  s << "second chance: images " << images_recovered << "/" << images_tried << " recovered, clouds "
    << clouds_recovered << "/" << clouds_tried << " recovered";
  return s.str();
}

}  // namespace board_calib
