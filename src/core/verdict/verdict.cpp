#include <board_calib/core/common/edge_association.h>
#include <board_calib/core/common/format.h>
#include <board_calib/core/common/statistics.h>
#include <board_calib/core/transform.h>
#include <board_calib/core/verdict/verdict.h>

#include <Eigen/QR>
#include <algorithm>
#include <cmath>
#include <functional>
#include <optional>
#include <sstream>

namespace board_calib {
namespace {

constexpr double kSqrtHalf = 0.7071067811865476;

// Camera plane error at a point of the board: the PnP's offset error grows as D^2 / size, its
// tilt error as D / size over the board's extent.
double cameraPlaneSigma(const CameraBoardFeatures& c, const Target& target,
                        double min_pixel_sigma_px) {
  const double fx = c.K(0, 0) > 0 ? c.K(0, 0) : 1.0;
  const double pixel_rad = std::max(c.reprojection_rms_px, min_pixel_sigma_px) / fx;
  const double range = (c.camera_T_board * target.center()).norm();
  const double half = 0.5 * std::max(1e-3, std::min(target.width, target.height));
  return pixel_rad * range * std::sqrt((range / half) * (range / half) + kSqrtHalf);
}

double boardSizePx(const View& v, const Target& target) {
  const double range = (v.camera.camera_T_board * target.center()).norm();
  return range > 0 ? v.camera.K(0, 0) * std::sqrt(target.width * target.height) / range : 0.0;
}

}  // namespace

const char* verdictName(Verdict verdict) {
  switch (verdict) {
    case Verdict::kGood: return "good";
    case Verdict::kDoubtful: return "doubtful";
    case Verdict::kFailed: return "failed";
  }
  return "unknown";
}

std::string VerdictOptions::validate() const {
  if (min_views < 1 || min_views_to_cross_validate < min_views)
    return "view counts must be >= 1 and ordered";
  if (max_leave_one_out_views < 2) return "max_leave_one_out_views must be >= 2";
  const double all[] = {max_outlier_edge_fraction,    doubtful_residual_ratio,
                        failed_residual_ratio,        failed_edge_fraction,
                        doubtful_heldout_ratio,       outlier_factor,
                        outlier_min_excess_px,        doubtful_inconsistent_fraction,
                        failed_inconsistent_fraction, doubtful_stddev_translation_m,
                        doubtful_stddev_rotation_deg, failed_stddev_translation_m,
                        failed_stddev_rotation_deg,   method_disagreement_sigmas,
                        min_pixel_sigma_px,           declared_scale_sigmas,
                        declared_size_tolerance,      lens_bias_sigmas,
                        lens_residual_sigmas,         lens_min_explained};
  for (double v : all)
    if (!std::isfinite(v) || !(v > 0)) return "verdict thresholds must be finite and > 0";
  return {};
}

double planeResidualRatio(const std::vector<View>& views, const Target& target,
                          const Eigen::Isometry3d& T, double plane_scale, const VerdictOptions& o,
                          std::vector<double>* per_view) {
  double sum = 0;
  int count = 0;
  if (per_view) per_view->assign(views.size(), 0.0);
  for (size_t i = 0; i < views.size(); ++i) {
    const View& v = views[i];
    if (!v.lidar.found || !v.camera.found || v.lidar.board_points.empty()) continue;
    double r2 = 0;
    for (const auto& p : v.lidar.board_points) {
      const double r = v.camera.plane.normal.dot(T * p) - plane_scale * v.camera.plane.offset;
      r2 += r * r;
    }
    r2 /= static_cast<double>(v.lidar.board_points.size());
    const double sc = cameraPlaneSigma(v.camera, target, o.min_pixel_sigma_px);
    const double expected2 = v.lidar.plane_rms_m * v.lidar.plane_rms_m + sc * sc;
    const double ratio2 = r2 / std::max(expected2, 1e-12);
    if (per_view) (*per_view)[i] = std::sqrt(ratio2);
    sum += ratio2;
    ++count;
  }
  return count ? std::sqrt(sum / count) : 0.0;
}

namespace {

// What a judgement found, by weight, and the views it names.
struct Findings {
  VerdictReport* report;
  std::vector<std::string> failed, doubtful;
  bool views_disagree = false;  ///< the consistency step failed or left views out
  void name(int id) {
    auto& ids = report->views_to_check;
    if (std::find(ids.begin(), ids.end(), id) == ids.end()) ids.push_back(id);
  }
};

// Consistency before solving: views left out, and whether enough agree.
void judgeConsistency(const ConsistencyReport& consistency, const VerdictOptions& o, Findings& f) {
  VerdictReport& r = *f.report;
  int usable = 0, inconsistent = 0;
  for (const auto& v : consistency.views) {
    usable += v.usable;
    if (consistency.ok && v.usable && !v.consistent) {
      ++inconsistent;
      f.name(v.view_id);
      r.details.push_back("view " + std::to_string(v.view_id) + " left out: " + v.reason);
    }
  }
  if (!consistency.ok) f.failed.push_back(consistency.reason);
  const double bad_fraction = usable ? static_cast<double>(inconsistent) / usable : 0.0;
  f.views_disagree = !consistency.ok || bad_fraction > o.doubtful_inconsistent_fraction;
  if (bad_fraction >= o.failed_inconsistent_fraction)
    f.failed.push_back(std::to_string(inconsistent) + " of " + std::to_string(usable) +
                       " views disagree with the others: no single calibration explains them");
  else if (bad_fraction > o.doubtful_inconsistent_fraction)
    f.doubtful.push_back(std::to_string(inconsistent) + " of " + std::to_string(usable) +
                         " views were left out as inconsistent");
  else if (inconsistent > 0)
    r.details.push_back(std::to_string(inconsistent) +
                        " inconsistent view(s) left out before solving");
  if (!consistency.checkable && consistency.ok)
    f.doubtful.push_back("only 3 usable views: nothing to check them against");
}

// Camera intrinsics that do not match the images (a camera_info without the lens distortion,
// a rectified image with the raw camera_info) bend the board's edges: the lines fitted to them
// sit off the true edges by an amount that grows as r^3 from the image centre. The solve
// absorbs part of it and the residuals stay small, but what is left keeps that shape: the
// LiDAR edge points' signed distances to their lines, fitted against f |rho|^2 (n . rho) (a
// radial term k1 would add, rho the normalized image position, n the line's outward normal),
// with a constant per view for the edge points' inward sampling bias.
// What both lens findings give as the cause.
// A lens left out of the camera_info moves the farthest edge point by a few per cent of the
// focal length (k1 = -0.1 at |rho| = 0.8: 5 %); beyond this share the edges lie elsewhere.
constexpr double kMaxLensShiftOfFocal = 0.1;
constexpr const char* kLensCause =
    ": the camera_info's distortion does not match the images (a raw image with a rectified "
    "camera_info, or none given)";
// LiDAR edges alone cannot tell a lens from edge returns that lie off the board's edges: a
// simulated LiDAR whose edge returns blend with the wall behind gave the same pattern (k1 -0.03
// with the camera_info right), and real LiDARs sit close to the threshold.
constexpr const char* kEdgeReturnsCause =
    ", or the LiDAR's edge returns lie off the board's edges (blended with what is behind it)";

// Per view, the sums a slope through the origin needs (y regressed on g).
struct SlopeSums {
  double gy = 0.0, gg = 0.0;
};

// The slope over every view and its cluster-robust 1 sigma: a sandwich over views, whose points
// share their pose error. False with fewer than 3 views or no spread in g.
bool clusterSlope(const std::vector<SlopeSums>& per_view, double* slope, double* stddev) {
  if (per_view.size() < 3) return false;
  double gy = 0.0, gg = 0.0;
  for (const auto& v : per_view) {
    gy += v.gy;
    gg += v.gg;
  }
  if (!(gg > 0.0)) return false;
  *slope = gy / gg;
  double b = 0.0;
  for (const auto& v : per_view) {
    const double score = v.gy - *slope * v.gg;
    b += score * score;
  }
  const double m = static_cast<double>(per_view.size());
  *stddev = std::sqrt(b * m / (m - 1.0)) / gg;
  return true;
}

struct LensResidual {
  double k = 0.0, k_stddev = 0.0;  ///< residual radial coefficient and its cluster-robust 1 sigma
  double corner_px = 0.0;          ///< what k moves a point at the farthest edge point, px
  double focal_px = 0.0;
  int views = 0;
};

std::optional<LensResidual> lensResidual(const std::vector<View>& views,
                                         const Eigen::Isometry3d& T) {
  std::vector<SlopeSums> per_view;
  double rho_max = 0.0, focal = 0.0;
  for (const View& v : views) {
    if (!v.camera.found || !v.lidar.found) continue;
    const Eigen::Matrix3d& K = v.camera.K;
    const double f = 0.5 * (K(0, 0) + K(1, 1));
    if (!(f > 0.0)) continue;
    const Eigen::Vector2d c(K(0, 2), K(1, 2));
    const EdgeAssociation a = associateEdges(v.camera, v.lidar, T);
    double n = 0.0, sy = 0.0, sg = 0.0;
    SlopeSums sums;
    for (int j = 0; j < kNumEdges; ++j) {
      if (!a.scored[j]) continue;
      const Eigen::Vector3d& line = v.camera.edge_lines[static_cast<size_t>(j)];
      for (const auto& p : v.lidar.edge_points[static_cast<size_t>(a.lidar_edge[j])]) {
        const Eigen::Vector3d q = T * p;
        if (!(q.z() > 0.0)) continue;
        const Eigen::Vector3d uh = K * q;
        const Eigen::Vector2d u = uh.head<2>() / uh.z();
        const Eigen::Vector2d rho = (u - c) / f;
        const double y = line.head<2>().dot(u) + line.z();
        const double g = f * rho.squaredNorm() * line.head<2>().dot(rho);
        if (!std::isfinite(y) || !std::isfinite(g)) continue;
        n += 1.0;
        sy += y;
        sg += g;
        sums.gy += g * y;
        sums.gg += g * g;
        rho_max = std::max(rho_max, rho.norm());
      }
    }
    if (n == 0.0) continue;
    // A per-view constant: the edge points' inward sampling bias is a share of the column step,
    // so its pixels change with the distance from view to view. Removed as each view's means.
    sums.gy -= sg * sy / n;
    sums.gg -= sg * sg / n;
    per_view.push_back(sums);
    focal = f;
  }
  double slope = 0.0, stddev = 0.0;
  if (!clusterSlope(per_view, &slope, &stddev)) return std::nullopt;
  LensResidual r;
  r.k = -slope;  // the lines sit where the bend put the edges: the LiDAR points off by -k g
  r.k_stddev = stddev;
  r.corner_px = std::abs(r.k) * focal * rho_max * rho_max * rho_max;
  r.focal_px = focal;
  r.views = static_cast<int>(per_view.size());
  return r;
}

// Pattern boards see the same bend in their corners: each corner's offset from the board pose's
// projection, against the radial term's f |rho|^2 rho, with the fields a homography makes
// removed from both (the pose absorbs them). `explained` is the share of the corners' residual
// the term carries: a camera_info that is right leaves only the detector's noise (0 % on the real
// checkerboard recording), one without its distortion most of it (79 %, simulated).
struct PatternLens {
  double k = 0.0, k_stddev = 0.0, explained = 0.0;
  int views = 0;
};

std::optional<PatternLens> patternLens(const std::vector<View>& views) {
  constexpr size_t kMinCorners = 8;  // 16 components against the 8 removed fields
  std::vector<SlopeSums> per_view;
  double ee = 0.0, gg = 0.0;
  for (const View& v : views) {
    const CameraBoardFeatures& cam = v.camera;
    if (!cam.found || cam.pattern.size() < kMinCorners) continue;
    const Eigen::Matrix3d& K = cam.K;
    const double f = 0.5 * (K(0, 0) + K(1, 1));
    if (!(f > 0.0)) continue;
    const Eigen::Vector2d c(K(0, 2), K(1, 2));
    const size_t n = cam.pattern.size();
    // Stacked x and y components; the fields a homography makes (affine, and the projective
    // d (h . d)) are what a board pose absorbs: removed from both before the fit.
    Eigen::MatrixXd X = Eigen::MatrixXd::Zero(2 * n, 8);
    Eigen::VectorXd E(2 * n), G(2 * n);
    Eigen::Vector2d mean_rho = Eigen::Vector2d::Zero();
    for (const auto& obs : cam.pattern) mean_rho += (obs.pixel - c) / f / static_cast<double>(n);
    bool finite = true;
    for (size_t i = 0; i < n; ++i) {
      const auto& obs = cam.pattern[i];
      const Eigen::Vector3d q = K * (cam.camera_T_board * obs.board_point);
      const Eigen::Vector2d predicted = q.head<2>() / q.z();
      const Eigen::Vector2d rho = (obs.pixel - c) / f;
      const Eigen::Vector2d d = rho - mean_rho;
      const auto rx = static_cast<Eigen::Index>(2 * i), ry = rx + 1;
      X.row(rx) << d.x(), d.y(), 1.0, 0.0, 0.0, 0.0, d.x() * d.x(), d.x() * d.y();
      X.row(ry) << 0.0, 0.0, 0.0, d.x(), d.y(), 1.0, d.x() * d.y(), d.y() * d.y();
      const Eigen::Vector2d e = obs.pixel - predicted, g = f * rho.squaredNorm() * rho;
      E(rx) = e.x();
      E(ry) = e.y();
      G(rx) = g.x();
      G(ry) = g.y();
      finite = finite && q.z() > 0.0 && e.allFinite() && g.allFinite();
    }
    if (!finite) continue;
    const auto qr = X.colPivHouseholderQr();
    if (qr.rank() < 8) continue;
    const Eigen::VectorXd Er = E - X * qr.solve(E), Gr = G - X * qr.solve(G);
    per_view.push_back({Gr.dot(Er), Gr.squaredNorm()});
    ee += Er.squaredNorm();
    gg += per_view.back().gg;
  }
  PatternLens out;
  if (!(ee > 0.0) || !clusterSlope(per_view, &out.k, &out.k_stddev)) return std::nullopt;
  out.explained = out.k * out.k * gg / ee;
  out.views = static_cast<int>(per_view.size());
  return out;
}

// Named when beyond lens_bias_sigmas and carrying lens_min_explained of the corners' residual.
void judgePatternLens(const std::vector<View>& views, const VerdictOptions& o, Findings& f) {
  const auto lens = patternLens(views);
  if (!lens || !(std::abs(lens->k) > o.lens_bias_sigmas * lens->k_stddev) ||
      !(lens->explained > o.lens_min_explained))
    return;
  // The cause the user can fix heads the verdict, a failure it contributes to as well.
  auto& list = f.failed.empty() ? f.doubtful : f.failed;
  list.insert(list.begin(),
              "the board's corners bend in the pattern of a lens distortion the images "
              "still have (radial k1 " +
                  formatFixed(lens->k, 3) + " +- " + formatFixed(lens->k_stddev, 3) + ", " +
                  formatFixed(100.0 * lens->explained, 0) + " % of the corners' residual)" +
                  kLensCause + "; give the camera_info that matches the image topic");
}

// What a lens residual does to a PBPC result: beyond lens_bias_sigmas of its noise, the views
// are solved again with each image line moved by what the fitted term puts at the middle of the
// side, and the move is returned as a covariance to add. Beyond lens_residual_sigmas, moving
// the result beyond its 1 sigma too (judged with it in judgeUncertainty), it is named.
struct LensCheck {
  Matrix6d covariance = Matrix6d::Zero();
  std::string text;  ///< empty: nothing beyond the noise
  bool nameable = false;
  Vector6d shift = Vector6d::Zero();
};

LensCheck checkLens(const CalibrationSolution& sol, const std::vector<View>& views,
                    const std::function<CalibrationSolution(const std::vector<View>&)>& solve,
                    const VerdictOptions& o, Findings& f) {
  LensCheck out;
  if (sol.method != Method::kPbpc) return out;  // the others do not fit the edges
  const auto lens = lensResidual(views, sol.camera_T_lidar);
  if (!lens || !(std::abs(lens->k) > o.lens_bias_sigmas * lens->k_stddev)) return out;
  const std::string measured =
      "the LiDAR edges sit off the image edges in the pattern of a lens "
      "distortion the images still have (radial k1 " +
      formatFixed(lens->k, 3) + " +- " + formatFixed(lens->k_stddev, 3) + ", " +
      formatFixed(lens->corner_px, 1) + " px at the farthest edge point)";
  if (!solve) {
    f.report->details.push_back(measured + "; its effect could not be assessed (no re-solve)");
    return out;
  }
  std::vector<View> corrected = views;
  for (View& v : corrected) {
    if (!v.camera.found) continue;
    const Eigen::Matrix3d& K = v.camera.K;
    const double focal = 0.5 * (K(0, 0) + K(1, 1));
    const Eigen::Vector2d c(K(0, 2), K(1, 2));
    Eigen::Vector2d centre = Eigen::Vector2d::Zero();
    for (const auto& corner : v.camera.corners_px) centre += 0.25 * corner;
    for (int j = 0; j < kNumEdges; ++j) {
      Eigen::Vector3d& line = v.camera.edge_lines[static_cast<size_t>(j)];
      if (!v.camera.edge_valid[static_cast<size_t>(j)] || !centre.allFinite()) continue;
      const Eigen::Vector2d n = line.head<2>();
      const Eigen::Vector2d mid = centre - (n.dot(centre) + line.z()) * n;
      const Eigen::Vector2d rho = (mid - c) / focal;
      line.z() += lens->k * focal * rho.squaredNorm() * n.dot(rho);
    }
  }
  const CalibrationSolution alt = solve(corrected);
  if (!alt.success) {
    f.report->details.push_back(measured + "; its effect could not be assessed (" + alt.reason +
                                ")");
    return out;
  }
  out.shift = poseDelta(alt.camera_T_lidar, sol.camera_T_lidar);
  out.covariance = out.shift * out.shift.transpose();
  // A camera_info that misses the images' distortion moves edges by some per cent of the focal
  // length; edges that far off lie on other objects than the board (wrong views), not a lens.
  out.nameable = std::abs(lens->k) > o.lens_residual_sigmas * lens->k_stddev &&
                 lens->corner_px <= kMaxLensShiftOfFocal * lens->focal_px;
  out.text = measured + kLensCause + kEdgeReturnsCause + "; corrected for it, the result moves " +
             formatFixed(out.shift.tail<3>().norm() * 1e3, 1) + " mm / " +
             formatFixed(out.shift.head<3>().norm() * kDegPerRad, 3) + " deg";
  return out;
}

// Residuals against the noise model, the board's size in the image, outlier edges.
void judgeResiduals(const CalibrationSolution& sol, const std::vector<View>& views,
                    const Target& target, const VerdictOptions& o, Findings& f) {
  VerdictReport& r = *f.report;
  std::vector<double> per_view;
  r.plane_residual_ratio =
      planeResidualRatio(views, target, sol.camera_T_lidar, sol.plane_scale, o, &per_view);
  const std::string ratio_text =
      "the LiDAR board points lie " + formatFixed(r.plane_residual_ratio, 1) +
      "x as far from the camera's board planes as the sensors' noise explains (plane RMS " +
      formatFixed(sol.plane_rms_mm, 1) + " mm)";
  if (r.plane_residual_ratio > o.failed_residual_ratio)
    f.failed.push_back(ratio_text);
  else if (r.plane_residual_ratio > o.doubtful_residual_ratio)
    f.doubtful.push_back(ratio_text);
  std::vector<double> sizes;
  for (const auto& v : views) sizes.push_back(boardSizePx(v, target));
  if (!sizes.empty()) r.board_size_px = medianOf(sizes);
  if (sol.mlre_px && r.board_size_px && *sol.mlre_px > o.failed_edge_fraction * *r.board_size_px)
    f.failed.push_back("LiDAR edges land " + formatFixed(*sol.mlre_px, 1) +
                       " px from the image edges on average, on a board about " +
                       formatFixed(*r.board_size_px, 0) + " px across");
  // Outlier views and edges (MATLAB-style error bars would show them).
  std::vector<double> view_mlre, edge_mlre;
  for (const auto& vr : sol.views) {
    if (vr.mlre_px) view_mlre.push_back(*vr.mlre_px);
    for (const auto& e : vr.edges)
      if (e.mlre_px) edge_mlre.push_back(*e.mlre_px);
  }
  const double med_edge = medianOf(edge_mlre);
  std::vector<std::string> outlier_edges;
  for (const auto& vr : sol.views)
    for (int j = 0; j < kNumEdges; ++j) {
      const auto& e = vr.edges[static_cast<size_t>(j)];
      if (e.mlre_px &&
          *e.mlre_px > std::max(o.outlier_factor * med_edge, med_edge + o.outlier_min_excess_px)) {
        f.name(vr.view_id);
        outlier_edges.push_back("view " + std::to_string(vr.view_id) + " edge " + edgeName(j) +
                                ": " + formatFixed(*e.mlre_px, 1) +
                                " px against a median edge error of " + formatFixed(med_edge, 1) +
                                " px (a hand, a wrong line?)");
      }
    }
  // A stray edge or two is what the robust loss is for: named, not doubted. Many are not.
  const bool many =
      static_cast<double>(outlier_edges.size()) >
      std::max(1.0, o.max_outlier_edge_fraction * static_cast<double>(edge_mlre.size()));
  for (const auto& text : outlier_edges) (many ? f.doubtful : r.details).push_back(text);
  if (!sol.observability.well_conditioned && sol.observability.max_eigenvalue > 0)
    f.doubtful.push_back("weakly observable: " + sol.observability.weakest_description);
}

// Each fold of views left out, solved on the rest, and predicted: the deltas to the full
// solution and the held-out figures go into `cv`.
std::vector<Vector6d> runFolds(
    const CalibrationSolution& sol, const std::vector<View>& views, const Target& target,
    const std::function<CalibrationSolution(const std::vector<View>&)>& solve,
    const VerdictOptions& o, CrossValidation& cv) {
  const int n = static_cast<int>(views.size());
  const int folds = std::min(n, o.max_leave_one_out_views);
  std::vector<Vector6d> deltas;
  std::vector<double> scales;  // the declared-size scale of each fold, where solved
  double heldout_mlre_sum = 0, heldout_ratio2_sum = 0;
  int heldout_mlre_n = 0, heldout_ratio_n = 0;
  for (int k = 0; k < folds; ++k) {
    std::vector<View> train, test;
    std::vector<size_t> test_index;
    for (int i = 0; i < n; ++i) {
      if (i % folds == k) {
        test.push_back(views[static_cast<size_t>(i)]);
        test_index.push_back(static_cast<size_t>(i));
      } else {
        train.push_back(views[static_cast<size_t>(i)]);
      }
    }
    const CalibrationSolution fold = solve(train);
    ++cv.solves;
    if (!fold.success) {
      ++cv.failed_solves;
      continue;
    }
    deltas.push_back(poseDelta(fold.camera_T_lidar, sol.camera_T_lidar));
    if (fold.declared_scale.estimated) scales.push_back(fold.declared_scale.scale);
    cv.max_rotation_dev_deg = std::max(cv.max_rotation_dev_deg,
                                       rotationErrorDeg(fold.camera_T_lidar, sol.camera_T_lidar));
    cv.max_translation_dev_m = std::max(cv.max_translation_dev_m,
                                        translationErrorM(fold.camera_T_lidar, sol.camera_T_lidar));
    std::vector<double> ratios;
    planeResidualRatio(test, target, fold.camera_T_lidar, fold.plane_scale, o, &ratios);
    for (size_t t = 0; t < test.size(); ++t) {
      cv.view_heldout_plane_ratio[test_index[t]] = ratios[t];
      heldout_ratio2_sum += ratios[t] * ratios[t];
      ++heldout_ratio_n;
      if (auto m = viewLineReprojectionErrorPx(test[t], fold.camera_T_lidar)) {
        cv.view_heldout_mlre_px[test_index[t]] = m;
        heldout_mlre_sum += *m;
        ++heldout_mlre_n;
      }
    }
  }
  cv.ran = cv.solves > 0;
  if (scales.size() >= 3) {
    const double m = static_cast<double>(scales.size());
    double mean = 0.0, sum2 = 0.0;
    for (double x : scales) mean += x / m;
    for (double x : scales) sum2 += (x - mean) * (x - mean);
    cv.declared_scale_stddev = std::sqrt(sum2 * (m - 1.0) / m);  // grouped jackknife
  }
  if (heldout_mlre_n) cv.heldout_mlre_px = heldout_mlre_sum / heldout_mlre_n;
  if (heldout_ratio_n) cv.heldout_plane_ratio = std::sqrt(heldout_ratio2_sum / heldout_ratio_n);
  return deltas;
}

// Cross-validation: each view (or fold) left out, solved on the rest, and predicted.
void crossValidate(const CalibrationSolution& sol, const std::vector<View>& views,
                   const Target& target,
                   const std::function<CalibrationSolution(const std::vector<View>&)>& solve,
                   const VerdictOptions& o, Findings& f) {
  VerdictReport& r = *f.report;
  const int n = static_cast<int>(views.size());
  CrossValidation& cv = r.cross_validation;
  cv.view_heldout_mlre_px.assign(views.size(), std::nullopt);
  cv.view_heldout_plane_ratio.assign(views.size(), 0.0);
  if (n < o.min_views_to_cross_validate) {
    cv.why_not = std::to_string(n) + " views: too few to leave any out";
    f.doubtful.push_back("too few views (" + std::to_string(n) +
                         ") to cross-validate: collect at least " +
                         std::to_string(o.min_views_to_cross_validate) +
                         " (the 1 sigma is the noise model's alone, unchecked)");
  } else if (solve) {
    const std::vector<Vector6d> deltas = runFolds(sol, views, target, solve, o, cv);
    if (cv.failed_solves * 2 > cv.solves)
      f.failed.push_back(std::to_string(cv.failed_solves) + " of " + std::to_string(cv.solves) +
                         " solves with a view left out failed: the result hangs on single views");
    else if (cv.failed_solves > 0)
      f.doubtful.push_back(std::to_string(cv.failed_solves) + " of " + std::to_string(cv.solves) +
                           " solves with a view left out failed");
    if (deltas.size() >= 2) {
      Vector6d mean = Vector6d::Zero();
      for (const auto& d : deltas) mean += d;
      mean /= static_cast<double>(deltas.size());
      Matrix6d c = Matrix6d::Zero();
      for (const auto& d : deltas) c += (d - mean) * (d - mean).transpose();
      const double m = static_cast<double>(deltas.size());
      cv.covariance = c * (m - 1.0) / m;  // grouped jackknife
    }
    // Prediction against fit: a model that only fits its own views does not generalise.
    if (cv.heldout_mlre_px && sol.mlre_px && *sol.mlre_px > 0 &&
        *cv.heldout_mlre_px > o.doubtful_heldout_ratio * std::max(*sol.mlre_px, 1.0))
      f.doubtful.push_back("left-out views' edges are predicted " +
                           formatFixed(*cv.heldout_mlre_px, 1) + " px off against " +
                           formatFixed(*sol.mlre_px, 1) + " px fitted");
    if (cv.heldout_plane_ratio > o.doubtful_heldout_ratio * std::max(r.plane_residual_ratio, 1.0))
      f.doubtful.push_back("left-out views' planes are predicted " +
                           formatFixed(cv.heldout_plane_ratio, 1) + "x the noise against " +
                           formatFixed(r.plane_residual_ratio, 1) + "x fitted");
    // Name the views whose prediction is far off the others'.
    std::vector<double> pred;
    for (const auto& m : cv.view_heldout_mlre_px)
      if (m) pred.push_back(*m);
    const double med_pred = medianOf(pred);
    for (size_t i = 0; i < views.size(); ++i) {
      const auto& m = cv.view_heldout_mlre_px[i];
      if (m && *m > std::max(o.outlier_factor * med_pred, med_pred + o.outlier_min_excess_px)) {
        f.name(views[i].id);
        f.doubtful.push_back("view " + std::to_string(views[i].id) + " is predicted " +
                             formatFixed(*m, 1) + " px off by the others (median " +
                             formatFixed(med_pred, 1) + " px)");
      }
    }
  }
}

// A systematic move of the result beyond its 1 sigma so far on any axis.
bool movesBeyond(const Vector6d& shift, const Matrix6d& covariance) {
  for (int i = 0; i < 6; ++i)
    if (shift(i) * shift(i) > covariance(i, i)) return true;
  return false;
}

// PPC with a declared board size the LiDAR disputes: the planes' depth, and so the translation,
// is off by the scale's share of the board distance. Beyond the scale's noise, the result's move
// with it is a likely bias and is returned as a covariance to add. Beyond the tolerance of a
// declared size too, and moving the result beyond `sigma` (its 1 sigma so far), it is named:
// doubtful, or the headline of a failure (a wrong size makes far and near views disagree).
// The scale's 1 sigma is never below its spread over the cross-validation's folds: the noise
// model's alone called a right size on far, noisy views wrong (1.006 +- 0.0007, the folds'
// spread 0.0027); a wrong size moves every fold alike. `finding` receives the named finding
// (empty when only a detail).
Matrix6d judgeDeclaredScale(const CalibrationSolution& sol, const Target& target,
                            const Matrix6d& sigma, const VerdictOptions& o, Findings& f,
                            std::string* finding) {
  const DeclaredScaleCheck& c = sol.declared_scale;
  const double off = std::abs(c.scale - 1.0);
  const double stddev = std::max(c.stddev, f.report->cross_validation.declared_scale_stddev);
  if (!c.checked || !(off > o.declared_scale_sigmas * stddev)) return Matrix6d::Zero();
  const bool moves = movesBeyond(c.shift, sigma);
  // s = LiDAR distance / camera distance: the declared size is 1/s of the true one.
  const double percent = (1.0 / c.scale - 1.0) * 100.0;
  std::string size = "board size";
  if (target.type == TargetType::kCheckerboard && target.checkerboard.square > 0)
    size = "square (" + formatFixed(target.checkerboard.square, 4) +
           " m; the LiDAR's: " + formatFixed(target.checkerboard.square * c.scale, 4) + " m)";
  else if (target.type == TargetType::kAprilTagGrid && target.apriltag_grid.tag_size > 0)
    size = "tag_size (" + formatFixed(target.apriltag_grid.tag_size, 4) +
           " m; the LiDAR's: " + formatFixed(target.apriltag_grid.tag_size * c.scale, 4) + " m)";
  const std::string text =
      "the LiDAR sees the boards at " + formatFixed(c.scale, 3) + " +- " + formatFixed(stddev, 4) +
      " of the distance the declared size gives: the target's " + size + " is declared " +
      formatFixed(std::abs(percent), 1) + " % too " + (percent > 0 ? "large" : "small") +
      ", or the camera's focal length or the LiDAR's range offset is off" +
      (c.shift.isZero()
           ? std::string("; the result (solved with the scale) does not move with it")
           : "; corrected, the result moves " + formatFixed(c.shift.tail<3>().norm() * 1e3, 1) +
                 " mm / " + formatFixed(c.shift.head<3>().norm() * kDegPerRad, 3) + " deg");
  // The consistency step places the camera's boards with the declared size: a wrong one makes
  // near and far views disagree even when the result (PBPC's edges) barely moves with it.
  if (off > o.declared_size_tolerance && (moves || f.views_disagree)) {
    *finding = text + ": measure the board and fix the target file, or recalibrate the camera";
    if (!moves) *finding += " (the views disagree because of it)";
  } else {
    f.report->details.push_back(text + " (the 1 sigma includes it)");
  }
  return c.shift * c.shift.transpose();
}

// Reported uncertainty: never below the cross-validation's spread, nor below the model's
// scaled by how much the residuals exceed the noise model.
void judgeUncertainty(const CalibrationSolution& sol, const Target& target, const VerdictOptions& o,
                      const LensCheck& lens, Findings& f) {
  VerdictReport& r = *f.report;
  const CrossValidation& cv = r.cross_validation;
  Matrix6d model_cov = sol.covariance;
  double inflation2 = std::max(1.0, r.plane_residual_ratio * r.plane_residual_ratio);
  if (!model_cov.allFinite()) model_cov = cv.covariance;
  for (int i = 0; i < 6; ++i)
    if (model_cov(i, i) > 0 && cv.covariance(i, i) > 0)
      inflation2 = std::max(inflation2, cv.covariance(i, i) / model_cov(i, i));
  // The edge sampling bias is a systematic term: residuals and left-out views do not show it.
  r.covariance = model_cov * inflation2 + sol.edge_bias_covariance;
  std::string size_finding;
  r.covariance += judgeDeclaredScale(sol, target, r.covariance, o, f, &size_finding);
  std::string lens_finding;
  if (!lens.text.empty()) {
    if (lens.nameable && movesBeyond(lens.shift, r.covariance))
      lens_finding = lens.text +
                     ": give the camera_info that matches the image topic; if it does, look "
                     "at the LiDAR's returns at the board's edges";
    else
      r.details.push_back(lens.text + " (the 1 sigma includes it)");
    r.covariance += lens.covariance;
  }
  if (!r.covariance.allFinite() || r.covariance.diagonal().maxCoeff() <= 0)
    r.covariance = cv.covariance;
  r.stddev_inflation = std::sqrt(inflation2);
  r.stddev = stddevFromCovariance(r.covariance);
  const double st = r.stddev.translation_m.maxCoeff(), sr = r.stddev.rotation_deg.maxCoeff();
  const std::string sigma_text =
      "1 sigma " + formatFixed(st * 1e3, 1) + " mm / " + formatFixed(sr, 3) + " deg";
  // Neither the solver's covariance nor a cross-validation gave one: the uncertainty is unknown,
  // not zero (seen: 4 far views, a covariance that Ceres could not compute, none left out; or a
  // solve run without covariance). No measured variance is exactly zero.
  const bool unknown = !r.covariance.allFinite() || !(r.covariance.diagonal().minCoeff() > 0.0);
  // With fewer views than a cross-validation needs, the count is the cause, not the geometry:
  // the covariance is robust to errors shared within a view, which takes more views than the
  // pose's 6 unknowns.
  if (unknown && sol.views_used < o.min_views_to_cross_validate)
    f.failed.push_back("no uncertainty could be computed: " + std::to_string(sol.views_used) +
                       " views are too few (the solver's covariance needs more views than the "
                       "pose's 6 unknowns, a cross-validation at least " +
                       std::to_string(o.min_views_to_cross_validate) + "); collect more views");
  else if (unknown)
    f.failed.push_back(
        "no uncertainty could be computed (the solver's covariance failed and "
        "the views are too few to cross-validate): the views do not determine "
        "the calibration");
  else if (!std::isfinite(st) || !std::isfinite(sr) || st > o.failed_stddev_translation_m ||
           sr > o.failed_stddev_rotation_deg)
    f.failed.push_back(sigma_text + ": the views do not determine the calibration");
  else if (st > o.doubtful_stddev_translation_m || sr > o.doubtful_stddev_rotation_deg)
    f.doubtful.push_back(sigma_text +
                         ": loosely determined; add views with other tilts and distances");
  // A wrong size or lens model is the cause the user can fix: it heads a failure it contributes
  // to.
  r.scale_finding = size_finding;
  for (const std::string* finding : {&size_finding, &lens_finding}) {
    if (finding->empty()) continue;
    if (f.failed.empty())
      f.doubtful.insert(f.doubtful.begin(), *finding);
    else
      f.failed.insert(f.failed.begin(), *finding);
  }
  if (r.stddev_inflation > 1.5)
    r.details.push_back(
        "1 sigma scaled by " + formatFixed(r.stddev_inflation, 1) +
        " (residuals beyond the noise model, or the spread of the cross-validation)");
}

// The verdict from the findings: any failure fails, any doubt doubts; every finding in the details.
void conclude(Findings& f) {
  VerdictReport& r = *f.report;
  std::vector<std::string>& failed = f.failed;
  std::vector<std::string>& doubtful = f.doubtful;
  if (!failed.empty()) {
    r.verdict = Verdict::kFailed;
    r.reason = failed.front();
  } else if (!doubtful.empty()) {
    r.verdict = Verdict::kDoubtful;
    r.reason = doubtful.front();
  } else {
    r.verdict = Verdict::kGood;
    std::ostringstream why;
    why << "residuals as the noise predicts (" << formatFixed(r.plane_residual_ratio, 1) << "x)";
    if (r.cross_validation.ran)
      why << ", left-out views predicted (" << r.cross_validation.solves << " solves)";
    if (!r.views_to_check.empty())
      why << "; " << r.views_to_check.size() << " view(s) named in the details";
    r.reason = why.str();
  }
  std::vector<std::string> all = failed;
  all.insert(all.end(), doubtful.begin(), doubtful.end());
  all.insert(all.end(), r.details.begin(), r.details.end());
  r.details = all;
}

}  // namespace

VerdictReport judgeSolution(
    const CalibrationSolution& sol, const std::vector<View>& views, const Target& target,
    const ConsistencyReport& consistency,
    const std::function<CalibrationSolution(const std::vector<View>&)>& solve,
    const VerdictOptions& o) {
  VerdictReport r;
  Findings f{&r, {}, {}};
  if (auto why = o.validate(); !why.empty()) f.failed.push_back("invalid verdict options: " + why);
  if (!sol.success) f.failed.push_back(sol.reason.empty() ? "the solve failed" : sol.reason);
  judgeConsistency(consistency, o, f);
  const int n = static_cast<int>(views.size());
  if (n < o.min_views)
    f.failed.push_back(std::to_string(n) + " view(s): at least " + std::to_string(o.min_views) +
                       " needed");
  if (sol.success) {
    judgeResiduals(sol, views, target, o, f);
    crossValidate(sol, views, target, solve, o, f);
    const LensCheck lens = checkLens(sol, views, solve, o, f);
    judgeUncertainty(sol, target, o, lens, f);
    judgePatternLens(views, o, f);
  }
  conclude(f);
  return r;
}

void judgeMethodAgreement(const std::vector<CalibrationSolution>& solutions,
                          std::vector<VerdictReport>* verdicts, const VerdictOptions& o) {
  // A depth scale another method names holds for this one too: PBPC absorbs a wrong board size
  // but not a wrong focal length, which moves every method alike, so they agree with each other
  // (a 2 % focal length: PPC and MSG doubtful naming it, PBPC "good" 75 mm off, chosen).
  for (size_t a = 0; a < solutions.size(); ++a) {
    auto& va = (*verdicts)[a];
    if (va.verdict != Verdict::kGood || !va.scale_finding.empty()) continue;
    for (size_t b = 0; b < solutions.size(); ++b) {
      const auto& vb = (*verdicts)[b];
      if (a == b || vb.scale_finding.empty()) continue;
      const std::string text = std::string(methodName(solutions[b].method)) + " finds " +
                               vb.scale_finding +
                               "; a wrong focal length moves this result too, a wrong board size "
                               "does not: measure the board";
      va.details.push_back(text);
      va.verdict = Verdict::kDoubtful;
      va.reason = text;
      break;
    }
  }
  for (size_t a = 0; a < solutions.size(); ++a) {
    auto& va = (*verdicts)[a];
    if (va.verdict == Verdict::kFailed) continue;
    for (size_t b = 0; b < solutions.size(); ++b) {
      const auto& vb = (*verdicts)[b];
      if (a == b || vb.verdict == Verdict::kFailed) continue;
      const Vector6d d = poseDelta(solutions[b].camera_T_lidar, solutions[a].camera_T_lidar);
      const Matrix6d c = va.covariance + vb.covariance;
      double worst = 0;
      for (int i = 0; i < 6; ++i)
        if (c(i, i) > 0) worst = std::max(worst, std::abs(d(i)) / std::sqrt(c(i, i)));
      if (worst > o.method_disagreement_sigmas) {
        const std::string text =
            std::string(methodName(solutions[b].method)) + " differs by " +
            formatFixed(rotationErrorDeg(solutions[a].camera_T_lidar, solutions[b].camera_T_lidar),
                        2) +
            " deg / " +
            formatFixed(
                translationErrorM(solutions[a].camera_T_lidar, solutions[b].camera_T_lidar) * 1e3,
                0) +
            " mm (" + formatFixed(worst, 1) + " sigma)";
        va.details.push_back(text);
        if (va.verdict == Verdict::kGood) {
          va.verdict = Verdict::kDoubtful;
          va.reason = text;
        }
      }
    }
  }
}

int chooseMethod(const std::vector<CalibrationSolution>& solutions,
                 const std::vector<VerdictReport>& verdicts, std::string* why) {
  bool all_edges = true;
  for (size_t i = 0; i < solutions.size(); ++i)
    if (verdicts[i].verdict != Verdict::kFailed && !verdicts[i].cross_validation.heldout_mlre_px)
      all_edges = false;
  auto score = [&](size_t i) {
    const auto& cv = verdicts[i].cross_validation;
    if (all_edges && cv.heldout_mlre_px) return *cv.heldout_mlre_px;
    if (cv.ran) return cv.heldout_plane_ratio;
    return solutions[i].mlre_px && all_edges ? *solutions[i].mlre_px
                                             : verdicts[i].plane_residual_ratio;
  };
  int best = -1;
  for (size_t i = 0; i < solutions.size(); ++i) {
    if (verdicts[i].verdict == Verdict::kFailed) continue;
    if (best < 0) {
      best = static_cast<int>(i);
      continue;
    }
    const auto& vb = verdicts[static_cast<size_t>(best)];
    const bool better_verdict =
        verdicts[i].verdict == Verdict::kGood && vb.verdict != Verdict::kGood;
    const bool same_verdict = verdicts[i].verdict == vb.verdict;
    if (better_verdict || (same_verdict && score(i) < score(static_cast<size_t>(best))))
      best = static_cast<int>(i);
  }
  if (why) {
    std::ostringstream s;
    if (best < 0) {
      s << "every method failed";
    } else if (solutions.size() == 1) {
      s << methodName(solutions[0].method) << ": the method asked for";
    } else {
      s << methodName(solutions[static_cast<size_t>(best)].method) << ": "
        << (all_edges ? "lowest held-out edge error (MLRE of left-out views)"
                      : "lowest held-out plane residual")
        << " among the methods not failed, good before doubtful (";
      for (size_t i = 0; i < solutions.size(); ++i) {
        if (i) s << ", ";
        s << methodName(solutions[i].method) << " " << verdictName(verdicts[i].verdict);
        if (verdicts[i].verdict != Verdict::kFailed)
          s << " " << formatFixed(score(i), 2) << (all_edges ? " px" : "x");
      }
      s << ")";
    }
    *why = s.str();
  }
  return best;
}

}  // namespace board_calib
