// PPC-Cal and PBPC-Cal views: checks and preparation, degeneracy checks, the closed-form
// initialiser, the residual clusters, edge re-association and the residual figures.
#include "calibrate_internal.h"

#include <board_calib/core/common/edge_association.h>
#include <board_calib/core/common/statistics.h>

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <limits>
#include <sstream>

#include "internal.h"

namespace board_calib {
namespace calibrate_detail {

namespace {

constexpr int kMinPpcViews = 3;   // 3 non-coplanar planes fix the translation
constexpr int kMinPbpcViews = 2;  // 8 line correspondences: DLT-lines needs 6
constexpr double kUnitNormalTolerance = 1e-3;
constexpr double kSameScanLineRad = 0.05 * kRadPerDeg;  // elevation gap that separates scan lines
constexpr size_t kMinScanLinePoints = 3;
constexpr double kMinAzimuthGapRad = 1e-4 * kRadPerDeg;  // duplicates are not a step
constexpr double kMaxPlausibleStepRad = 2.0 * kRadPerDeg;

bool finitePoints(const Points3& points, size_t* bad) {
  for (size_t i = 0; i < points.size(); ++i)
    if (!points[i].allFinite()) {
      *bad = i;
      return false;
    }
  return true;
}

bool unitNormal(const Plane& plane, Eigen::Vector3d* normal, double* offset) {
  if (!plane.normal.allFinite() || !std::isfinite(plane.offset)) return false;
  if (std::abs(plane.normal.norm() - 1.0) > kUnitNormalTolerance) return false;
  *normal = plane.normal.normalized();
  *offset = plane.offset;
  return true;
}

// Rotates a point about the LiDAR z axis (a horizontal step along its scan line).
Eigen::Vector3d rotateAboutZ(const Eigen::Vector3d& p, double angle) {
  const double c = std::cos(angle), s = std::sin(angle);
  return {c * p.x() - s * p.y(), s * p.x() + c * p.y(), p.z()};
}

double wrapAngle(double a) { return std::atan2(std::sin(a), std::cos(a)); }

PreparedView prepareView(const View& view, int index, Method method, const SolverOptions& options,
                         double horizontal_step_rad) {
  PreparedView pv;
  pv.index = index;
  pv.id = view.id;
  auto fail = [&](const std::string& why) {
    pv.reason = why;
    return pv;
  };
  if (!view.camera.found)
    return fail("camera found no board" +
                (view.camera.reason.empty() ? "" : ": " + view.camera.reason));
  if (!view.lidar.found)
    return fail("LiDAR found no board" +
                (view.lidar.reason.empty() ? "" : ": " + view.lidar.reason));
  const Eigen::Matrix3d& K = view.camera.K;
  if (!K.allFinite() || !(K(0, 0) > 0.0) || !(K(1, 1) > 0.0))
    return fail("camera K is not a valid intrinsic matrix");
  size_t bad = 0;
  if (view.lidar.board_points.empty()) return fail("no LiDAR board points");
  if (!finitePoints(view.lidar.board_points, &bad))
    return fail("LiDAR board point " + std::to_string(bad) + " is not finite");
  for (int j = 0; j < kNumEdges; ++j)
    if (!finitePoints(view.lidar.edge_points[j], &bad))
      return fail(std::string("LiDAR ") + edgeName(j) + " edge point " + std::to_string(bad) +
                  " is not finite");
  pv.board_points = &view.lidar.board_points;

  pv.plane_ok = unitNormal(view.camera.plane, &pv.cam_normal, &pv.cam_offset);
  pv.lidar_plane_ok = unitNormal(view.lidar.plane, &pv.lidar_normal, &pv.lidar_offset);
  if (method == Method::kPpc && !pv.plane_ok)
    return fail("camera board plane is not finite or its normal not unit");

  // LiDAR edges, optionally shifted outward along the scan line by a fraction of the step.
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  for (const auto& p : view.lidar.board_points) centroid += p;
  centroid /= static_cast<double>(view.lidar.board_points.size());
  const double centre_azimuth = std::atan2(centroid.y(), centroid.x());
  const double shift = options.edge_outward_shift_steps * horizontal_step_rad;
  for (int j = 0; j < kNumEdges; ++j) {
    pv.lidar_edge_ok[j] = view.lidar.edge_valid[j] &&
                          static_cast<int>(view.lidar.edge_points[j].size()) >= kMinEdgePoints;
    if (!pv.lidar_edge_ok[j]) continue;
    pv.lidar_edges[j] = view.lidar.edge_points[j];
    if (shift != 0.0) {
      for (auto& p : pv.lidar_edges[j]) {
        const double side =
            wrapAngle(std::atan2(p.y(), p.x()) - centre_azimuth) >= 0.0 ? 1.0 : -1.0;
        p = rotateAboutZ(p, side * shift);
      }
    }
  }
  for (int j = 0; j < kNumEdges; ++j) {
    const Eigen::Vector3d& l = view.camera.edge_lines[j];
    if (!view.camera.edge_valid[j] || !l.allFinite() || !(l.head<2>().norm() > 0.0)) continue;
    const Eigen::Vector3d N = K.transpose() * l;
    if (!(N.norm() > 0.0)) continue;
    pv.backprojected_normal[j] = N.normalized();
    pv.image_edge_ok[j] = true;
  }
  if (method == Method::kPbpc && pv.lineCount() == 0)
    return fail("no edge valid in both the image and the LiDAR");
  pv.used = true;
  return pv;
}

std::string usableSummary(const std::vector<PreparedView>& prepared) {
  std::ostringstream text;
  int shown = 0;
  constexpr int kMaxReasonsShown = 5;
  for (const auto& v : prepared) {
    if (v.used || v.reason.empty()) continue;
    if (shown++ < kMaxReasonsShown) text << "; view " << v.id << ": " << v.reason;
  }
  if (shown > kMaxReasonsShown) text << "; ... (" << shown - kMaxReasonsShown << " more)";
  return text.str();
}

// The LiDAR's horizontal step from the board points: points of one scan line share their
// elevation, and the smallest azimuth gaps along a line are one step (even after subsampling
// some neighbours survive). Median over scan lines; 0 when it cannot be told.
double estimateHorizontalStepRad(const std::vector<View>& views) {
  std::vector<double> line_minima;
  for (const View& v : views) {
    if (!v.lidar.found) continue;
    std::vector<std::pair<double, double>> elev_az;
    for (const auto& p : v.lidar.board_points) {
      if (!p.allFinite()) continue;
      elev_az.emplace_back(std::atan2(p.z(), p.head<2>().norm()), std::atan2(p.y(), p.x()));
    }
    std::sort(elev_az.begin(), elev_az.end());
    size_t begin = 0;
    for (size_t i = 1; i <= elev_az.size(); ++i) {
      if (i < elev_az.size() && elev_az[i].first - elev_az[i - 1].first < kSameScanLineRad)
        continue;
      if (i - begin >= kMinScanLinePoints) {
        std::vector<double> az;
        for (size_t k = begin; k < i; ++k) az.push_back(elev_az[k].second);
        std::sort(az.begin(), az.end());
        double gap = std::numeric_limits<double>::infinity();
        for (size_t k = 1; k < az.size(); ++k)
          if (az[k] - az[k - 1] > kMinAzimuthGapRad) gap = std::min(gap, az[k] - az[k - 1]);
        if (std::isfinite(gap)) line_minima.push_back(gap);
      }
      begin = i;
    }
  }
  if (line_minima.empty()) return 0.0;
  const double step = medianOf(std::move(line_minima));
  return step <= kMaxPlausibleStepRad ? step : 0.0;
}

}  // namespace

std::vector<PreparedView> prepareAll(const std::vector<View>& views, Method method,
                                     const SolverOptions& options, double* step_used) {
  double step = 0.0;
  if (options.edge_outward_shift_steps != 0.0)
    step = options.lidar_horizontal_resolution_deg > 0.0
               ? options.lidar_horizontal_resolution_deg * kRadPerDeg
               : estimateHorizontalStepRad(views);
  if (step_used) *step_used = step;
  std::vector<PreparedView> prepared;
  prepared.reserve(views.size());
  for (size_t i = 0; i < views.size(); ++i)
    prepared.push_back(prepareView(views[i], static_cast<int>(i), method, options, step));
  return prepared;
}

// Degeneracy checks; empty when the views can be solved.
std::string checkGeometry(const std::vector<PreparedView>& prepared, Method method,
                          const SolverOptions& options, int* used) {
  std::vector<Eigen::Vector3d> normals;
  *used = 0;
  for (const auto& v : prepared) {
    if (!v.used) continue;
    ++*used;
    if (v.plane_ok) normals.push_back(v.cam_normal);
  }
  const int needed = method == Method::kPpc ? kMinPpcViews : kMinPbpcViews;
  if (*used < needed) {
    std::ostringstream text;
    text << "only " << *used << " usable view(s) of " << prepared.size() << "; "
         << methodName(method) << " needs >= " << needed
         << (method == Method::kPpc ? " non-coplanar views" : " views with edges")
         << usableSummary(prepared);
    return text.str();
  }
  const double parallel = solvers_detail::normalSpreadDeg(normals, 1);
  if (normals.size() >= 2 && parallel < options.min_normal_spread_deg) {
    std::ostringstream text;
    text.precision(2);
    text << std::fixed << "all board normals are parallel (spread " << parallel << " deg < "
         << options.min_normal_spread_deg << " deg): tilt the board differently between views";
    return text.str();
  }
  if (method == Method::kPpc) {
    const double coplanar = solvers_detail::normalSpreadDeg(normals, 2);
    if (coplanar < options.min_normal_spread_deg) {
      std::ostringstream text;
      text.precision(2);
      text << std::fixed << "the board normals are coplanar (out-of-plane spread " << coplanar
           << " deg < " << options.min_normal_spread_deg
           << " deg): PPC needs >= 3 non-coplanar views; tilt the board about two different axes";
      return text.str();
    }
  }
  if (method == Method::kPbpc && normals.size() < 2) {
    // Rotation from lines alone is not attempted by the initialiser.
    return "PBPC needs the camera board plane in >= 2 views (for the initial rotation)";
  }
  return "";
}

Expected<Eigen::Isometry3d> closedForm(const std::vector<PreparedView>& prepared, Method method,
                                       const SolverOptions& options) {
  std::vector<Eigen::Vector3d> cam_normals, lidar_normals;
  std::vector<double> weights;
  for (const auto& v : prepared)
    if (v.used && v.plane_ok && v.lidar_plane_ok) {
      cam_normals.push_back(v.cam_normal);
      lidar_normals.push_back(v.lidar_normal);
      weights.push_back(1.0);
    }
  if (cam_normals.size() < 2)
    return Expected<Eigen::Isometry3d>::failure(
        "closed-form initialiser needs >= 2 views with planes in both sensors");
  auto R = solvers_detail::alignVectors(cam_normals, lidar_normals, weights);
  if (!R) return Expected<Eigen::Isometry3d>::failure("closed-form initialiser: " + R.error());
  // Translation: n_C . t = d_C - n_C . R (point on the LiDAR plane) per view; lines (PBPC):
  // N . t = -N . R Q for the centroid of each edge's points.
  Eigen::Matrix3d A = Eigen::Matrix3d::Zero();
  Eigen::Vector3d b = Eigen::Vector3d::Zero();
  for (const auto& v : prepared) {
    if (!v.used) continue;
    if (v.plane_ok && v.lidar_plane_ok) {
      const double rhs = v.cam_offset - v.lidar_offset * v.cam_normal.dot(*R * v.lidar_normal);
      A += v.cam_normal * v.cam_normal.transpose();
      b += v.cam_normal * rhs;
    }
    if (method == Method::kPbpc) {
      for (int j = 0; j < kNumEdges; ++j) {
        const int k = v.association[j];
        if (!v.image_edge_ok[j] || !v.lidar_edge_ok[k]) continue;
        Eigen::Vector3d c = Eigen::Vector3d::Zero();
        for (const auto& q : v.lidar_edges[k]) c += q;
        c /= static_cast<double>(v.lidar_edges[k].size());
        const Eigen::Vector3d& N = v.backprojected_normal[j];
        A += options.pbpc_line_weight * N * N.transpose();
        b += options.pbpc_line_weight * N * (-N.dot(*R * c));
      }
    }
  }
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(A);
  constexpr double kMinRelativeEigen = 1e-9;
  if (!(eig.eigenvalues()(0) > kMinRelativeEigen * eig.eigenvalues()(2)))
    return Expected<Eigen::Isometry3d>::failure(
        "closed-form initialiser: the translation is not constrained");
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = *R;
  T.translation() = A.ldlt().solve(b);
  return T;
}

std::vector<Cluster> buildClusters(const std::vector<PreparedView>& views, bool planes, bool lines,
                                   bool scaled, double line_weight) {
  std::vector<Cluster> clusters;
  for (const PreparedView& v : views) {
    if (!v.used) continue;
    if (planes && v.plane_ok)
      clusters.push_back({v.cam_normal, v.cam_offset,
                          1.0 / static_cast<double>(v.board_points->size()), scaled, true,
                          v.index * (kNumEdges + 1), v.board_points});
    if (lines) {
      for (int j = 0; j < kNumEdges; ++j) {
        const int k = v.association[j];
        if (!v.image_edge_ok[j] || k < 0 || !v.lidar_edge_ok[k]) continue;
        clusters.push_back({v.backprojected_normal[j], 0.0,
                            line_weight / static_cast<double>(v.lidar_edges[k].size()), false,
                            false, v.index * (kNumEdges + 1) + 1 + j, &v.lidar_edges[k]});
      }
    }
  }
  return clusters;
}

// Re-assigns LiDAR edges to image lines by projection (core/common/edge_association.h, the
// association the MLRE figures and the overlay use); true if any view changed.
bool reassociateEdges(const std::vector<View>& views, std::vector<PreparedView>* prepared,
                      const Eigen::Isometry3d& T, std::vector<std::string>* notes) {
  bool changed = false;
  for (PreparedView& v : *prepared) {
    if (!v.used) continue;
    const View& view = views[v.index];
    const EdgeAssociation a = associateEdges(view.camera, view.lidar, T, kMinEdgePoints);
    if (a.lidar_edge == v.association) continue;
    std::ostringstream note;
    note << "view " << v.id << ": LiDAR edges re-associated to image lines by projection (";
    for (int j = 0; j < kNumEdges; ++j)
      note << (j ? ", " : "") << edgeName(j) << "<-" << edgeName(a.lidar_edge[j]);
    note << ")";
    notes->push_back(note.str());
    v.association = a.lidar_edge;
    changed = true;
  }
  return changed;
}

void fillResidualFigures(const std::vector<View>& views, const std::vector<PreparedView>& prepared,
                         Method method, CalibrationSolution* sol) {
  const Eigen::Isometry3d& T = sol->camera_T_lidar;
  const Eigen::Matrix3d R = T.linear();
  double mlre_sum = 0.0, line_sq = 0.0, plane_sq = 0.0;
  int mlre_count = 0, line_count = 0, plane_count = 0;
  sol->views.clear();
  for (const PreparedView& v : prepared) {
    ViewResidual vr;
    vr.view_id = v.id;
    vr.used = v.used;
    vr.reason = v.reason;
    if (v.board_points && v.plane_ok) {
      std::vector<double> r;
      r.reserve(v.board_points->size());
      for (const auto& p : *v.board_points)
        r.push_back(v.cam_normal.dot(R * p + T.translation()) - v.cam_offset);
      vr.plane = residualStats(r);
      if (v.used) {
        plane_sq += vr.plane.rms_m * vr.plane.rms_m * vr.plane.count;
        plane_count += vr.plane.count;
      }
    }
    double view_sum = 0.0;
    int view_count = 0;
    // PBPC solved with its pairs (re-paired until they are the final pose's); a method without
    // edge terms is scored with the pairs at its pose, as the MLRE figures and the overlay pair
    // them: the detectors' names differ when a sensor is rolled (a portrait camera).
    std::array<int, kNumEdges> pairs = v.association;
    if (method != Method::kPbpc && v.used)
      pairs =
          associateEdges(views[v.index].camera, views[v.index].lidar, T, kMinEdgePoints).lidar_edge;
    for (int j = 0; j < kNumEdges; ++j) {
      const int k = pairs[j];
      EdgeResidual& er = vr.edges[j];
      er.lidar_edge = k;
      if (!v.used || !v.image_edge_ok[j] || !v.lidar_edge_ok[k]) continue;
      er.used = method == Method::kPbpc;
      std::vector<double> r;
      for (const auto& q : v.lidar_edges[k])
        r.push_back(v.backprojected_normal[j].dot(R * q + T.translation()));
      er.distance = residualStats(r);
      line_sq += er.distance.rms_m * er.distance.rms_m * er.distance.count;
      line_count += er.distance.count;
      int count = 0;
      const double mean = edgeLineDistancePx(views[v.index].camera, j,
                                             views[v.index].lidar.edge_points[k], T, &count);
      if (count > 0) {
        er.mlre_px = mean;
        view_sum += mean * count;
        view_count += count;
      }
    }
    if (view_count > 0) vr.mlre_px = view_sum / view_count;
    mlre_sum += view_sum;
    mlre_count += view_count;
    sol->views.push_back(vr);
  }
  if (mlre_count > 0) sol->mlre_px = mlre_sum / mlre_count;
  sol->plane_rms_mm = plane_count ? 1000.0 * std::sqrt(plane_sq / plane_count) : 0.0;
  sol->line_rms_mm = line_count ? 1000.0 * std::sqrt(line_sq / line_count) : 0.0;
}

}  // namespace calibrate_detail

ResidualStats residualStats(const std::vector<double>& r) {
  ResidualStats s;
  s.count = static_cast<int>(r.size());
  if (r.empty()) return s;
  double sq = 0.0, abs_sum = 0.0;
  for (double v : r) {
    sq += v * v;
    abs_sum += std::abs(v);
    s.max_abs_m = std::max(s.max_abs_m, std::abs(v));
  }
  s.rms_m = std::sqrt(sq / r.size());
  s.mean_abs_m = abs_sum / r.size();
  return s;
}

}  // namespace board_calib
