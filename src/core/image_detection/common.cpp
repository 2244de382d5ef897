// Helpers shared by the board detectors: PnP with covariance, edge naming, derived outer edges,
// debug drawing.
#include "detection_internal.h"

#include <Eigen/Eigenvalues>
#include <Eigen/LU>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include <cmath>
#include <limits>

namespace board_calib {
namespace image_detection {
namespace {

constexpr double kPi = 3.14159265358979323846;
// Ideal outward-normal angles (image v down) of UL, UR, LR, LL for a board held as a diamond.
constexpr double kIdealAngle[kNumEdges] = {-0.75 * kPi, -0.25 * kPi, 0.25 * kPi, 0.75 * kPi};
// Reciprocal condition number below which the PnP normal matrix is called degenerate.
constexpr double kMinReciprocalCondition = 1e-12;

double angleDiff(double a, double b) {
  double d = std::fmod(a - b, 2 * kPi);
  if (d > kPi) d -= 2 * kPi;
  if (d < -kPi) d += 2 * kPi;
  return d;
}

}  // namespace

namespace {

// IPPE gives both planar solutions; refine each (LM) and keep the better one: with few,
// extrapolated points (plain board corners) the first IPPE branch is not always the best.
// False (reason set) when no solution is usable.
bool solvePlanarPnP(const std::vector<cv::Point3d>& object, const std::vector<cv::Point2d>& image,
                    const cv::Matx33d& camera_matrix, cv::Mat* rvec, cv::Mat* tvec,
                    std::string* reason) {
  const cv::Mat no_distortion;
  bool solved = false;
  try {
    std::vector<cv::Mat> rvecs, tvecs;
    cv::solvePnPGeneric(object, image, camera_matrix, no_distortion, rvecs, tvecs, false,
                        cv::SOLVEPNP_IPPE);
    double best = std::numeric_limits<double>::max();
    for (size_t k = 0; k < rvecs.size(); ++k) {
      if (!cv::checkRange(rvecs[k]) || !cv::checkRange(tvecs[k]) || tvecs[k].at<double>(2) <= 0)
        continue;
      cv::solvePnPRefineLM(object, image, camera_matrix, no_distortion, rvecs[k], tvecs[k]);
      std::vector<cv::Point2d> proj;
      cv::projectPoints(object, rvecs[k], tvecs[k], camera_matrix, no_distortion, proj);
      const double err = cv::norm(proj, image, cv::NORM_L2SQR);
      if (err < best) {
        best = err;
        *rvec = rvecs[k];
        *tvec = tvecs[k];
        solved = true;
      }
    }
  } catch (const cv::Exception& e) {
    *reason = "PnP degenerate: " + e.err;  // err: the short text, what() adds source paths
    return false;
  }
  if (!solved || !cv::checkRange(*rvec) || !cv::checkRange(*tvec)) {
    *reason = "PnP degenerate: no solution";
    return false;
  }
  return true;
}

// Per-point errors, RMS and the pose covariance from the projection Jacobian; false (reason set)
// when the pose is not observable from these points.
bool residualsAndCovariance(const std::vector<cv::Point3d>& object,
                            const std::vector<cv::Point2d>& image, const cv::Matx33d& camera_matrix,
                            const cv::Mat& rvec, const cv::Mat& tvec, double sigma_floor_px,
                            PoseFit* fit) {
  std::vector<cv::Point2d> projected;
  cv::Mat jacobian;
  cv::projectPoints(object, rvec, tvec, camera_matrix, cv::Mat(), projected, jacobian);
  double sum_sq = 0;
  for (size_t i = 0; i < image.size(); ++i) {
    const double e = std::hypot(projected[i].x - image[i].x, projected[i].y - image[i].y);
    fit->errors_px.push_back(e);
    sum_sq += e * e;
  }
  fit->rms_px = std::sqrt(sum_sq / image.size());
  // Jacobian columns: rvec (3), tvec (3), then intrinsics we do not estimate.
  Eigen::MatrixXd J(2 * image.size(), 6);
  for (int r = 0; r < J.rows(); ++r)
    for (int c = 0; c < 6; ++c) J(r, c) = jacobian.at<double>(r, c);
  const Eigen::Matrix<double, 6, 6> normal = J.transpose() * J;
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, 6, 6>> eig(normal);
  const double max_ev = eig.eigenvalues().maxCoeff(), min_ev = eig.eigenvalues().minCoeff();
  if (!(max_ev > 0) || min_ev / max_ev < kMinReciprocalCondition) {
    fit->reason = "PnP degenerate: pose not observable from these points";
    return false;
  }
  // Unbiased residual scale with 6 estimated parameters; floor it so a 4-point exact fit does not
  // claim zero uncertainty.
  const double dof = std::max(1.0, 2.0 * image.size() - 6.0);
  const double sigma = std::max(std::sqrt(sum_sq / dof), sigma_floor_px);
  fit->covariance = sigma * sigma * normal.inverse();
  return true;
}

}  // namespace

PoseFit fitPose(const Points3& board_points, const Points2& pixels, const Eigen::Matrix3d& K,
                double sigma_floor_px) {
  PoseFit fit;
  if (board_points.size() != pixels.size() || board_points.size() < 4) {
    fit.reason = "PnP degenerate: " + std::to_string(board_points.size()) + " points (need >= 4)";
    return fit;
  }
  std::vector<cv::Point3d> object;
  std::vector<cv::Point2d> image;
  for (size_t i = 0; i < pixels.size(); ++i) {
    object.emplace_back(board_points[i].x(), board_points[i].y(), board_points[i].z());
    image.emplace_back(pixels[i].x(), pixels[i].y());
  }
  const cv::Matx33d camera_matrix(K(0, 0), K(0, 1), K(0, 2), K(1, 0), K(1, 1), K(1, 2), K(2, 0),
                                  K(2, 1), K(2, 2));
  cv::Mat rvec, tvec;
  if (!solvePlanarPnP(object, image, camera_matrix, &rvec, &tvec, &fit.reason)) return fit;
  cv::Matx33d R;
  cv::Rodrigues(rvec, R);
  Eigen::Matrix3d rotation;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) rotation(r, c) = R(r, c);
  fit.camera_T_board.linear() = rotation;
  fit.camera_T_board.translation() =
      Eigen::Vector3d(tvec.at<double>(0), tvec.at<double>(1), tvec.at<double>(2));
  if (fit.camera_T_board.translation().z() <= 0) {
    fit.reason = "PnP degenerate: board behind the camera";
    return fit;
  }
  fit.ok = residualsAndCovariance(object, image, camera_matrix, rvec, tvec, sigma_floor_px, &fit);
  return fit;
}

Plane planeFromPose(const Eigen::Isometry3d& camera_T_board) {
  Plane plane;
  plane.normal = camera_T_board.linear().col(2);
  plane.offset = plane.normal.dot(camera_T_board.translation());
  if (plane.offset < 0) {  // seen from the back: keep the package convention (away from the sensor)
    plane.normal = -plane.normal;
    plane.offset = -plane.offset;
  }
  return plane;
}

double facingCosine(const Eigen::Isometry3d& camera_T_board) {
  const double facing =
      std::abs(camera_T_board.linear().col(2).dot(camera_T_board.translation().normalized()));
  return std::isfinite(facing) ? facing : 0.0;
}

std::vector<int> nameEdges(const std::vector<double>& angles, const std::vector<double>& weights,
                           bool cyclic) {
  const int n = static_cast<int>(angles.size());
  std::vector<int> names(n, -1);
  if (cyclic && n == kNumEdges) {
    int best_shift = 0;
    double best_cost = std::numeric_limits<double>::max();
    for (int shift = 0; shift < kNumEdges; ++shift) {
      double cost = 0;
      for (int k = 0; k < n; ++k)
        cost += std::pow(angleDiff(angles[k], kIdealAngle[(k + shift) % kNumEdges]), 2);
      if (cost < best_cost) {
        best_cost = cost;
        best_shift = shift;
      }
    }
    for (int k = 0; k < n; ++k) names[k] = (k + best_shift) % kNumEdges;
    return names;
  }
  std::array<int, kNumEdges> owner;
  owner.fill(-1);
  for (int k = 0; k < n; ++k) {
    int best = 0;
    for (int j = 1; j < kNumEdges; ++j)
      if (std::abs(angleDiff(angles[k], kIdealAngle[j])) <
          std::abs(angleDiff(angles[k], kIdealAngle[best])))
        best = j;
    if (owner[best] < 0 || weights[k] > weights[owner[best]]) owner[best] = k;
  }
  for (int j = 0; j < kNumEdges; ++j)
    if (owner[j] >= 0) names[owner[j]] = j;
  return names;
}

int rotatedNamingShift(const std::array<Eigen::Vector3d, kNumEdges>& lines) {
  // Cost of renaming edge k+shift as k, for shift +1 (3 mod 4) and -1.
  double cost[2] = {0, 0};
  for (int s = 0; s < 2; ++s) {
    const int shift = s == 0 ? 1 : 3;
    for (int k = 0; k < kNumEdges; ++k) {
      const Eigen::Vector3d& l = lines[(k + shift) % kNumEdges];
      cost[s] += std::pow(angleDiff(std::atan2(l.y(), l.x()), kIdealAngle[k]), 2);
    }
  }
  return cost[0] <= cost[1] ? 1 : 3;
}

bool intersectLines(const Eigen::Vector3d& l1, const Eigen::Vector3d& l2, Eigen::Vector2d* point) {
  const Eigen::Vector3d x = l1.cross(l2);
  // |x.z| = |sin| of the angle between unit-normal lines; below ~0.06 deg the corner is
  // ill-defined.
  if (std::abs(x.z()) < 1e-3) return false;
  *point = x.head<2>() / x.z();
  return true;
}

void outerEdgesFromPose(const Target& target, CameraBoardFeatures* f) {
  const auto outer = target.outerCorners();
  Points2 px(4);
  for (int k = 0; k < 4; ++k) {
    const Eigen::Vector3d p = f->camera_T_board * outer[k];
    if (p.z() <= 0) {
      f->edge_valid.fill(false);
      return;
    }
    px[k] = (f->K * p).hnormalized();
  }
  Eigen::Vector3d c3 = f->camera_T_board * target.center();
  const Eigen::Vector2d center = (f->K * c3).hnormalized();
  // Board edge k runs from board corner k to k+1 (top, right, bottom, left as printed).
  std::vector<Eigen::Vector3d> lines(4);
  std::vector<double> angles(4), weights(4);
  for (int k = 0; k < 4; ++k) {
    lines[k] = lineThrough(px[k], px[(k + 1) % 4], center);
    angles[k] = std::atan2(lines[k].y(), lines[k].x());
    weights[k] = (px[(k + 1) % 4] - px[k]).norm();
  }
  const std::vector<int> names = nameEdges(angles, weights, true);
  for (int k = 0; k < 4; ++k) {
    f->edge_lines[names[k]] = lines[k];
    f->edge_valid[names[k]] = true;
    // Edge name j meets name j+1 at the board corner shared by board edges k and k+1.
    f->corners_px[names[k]] = px[(k + 1) % 4];
  }
}

double estimateNoiseSigma(const cv::Mat& gray) {
  // The mask [1 -2 1; -2 4 -2; 1 -2 1] cancels planes and straight ramps; on white noise its
  // response has sigma 6 x sigma. The median of |response| ignores the minority of edge and
  // texture pixels; |N(0, s)| has median 0.6745 s.
  constexpr int kRowStep = 3;
  constexpr int kMaxResponse = 16 * 255;
  std::vector<int> histogram(kMaxResponse + 1, 0);
  long count = 0;
  for (int y = 1; y + 1 < gray.rows; y += kRowStep) {
    const uchar* a = gray.ptr<uchar>(y - 1);
    const uchar* b = gray.ptr<uchar>(y);
    const uchar* c = gray.ptr<uchar>(y + 1);
    for (int x = 1; x + 1 < gray.cols; ++x) {
      const int r = a[x - 1] - 2 * a[x] + a[x + 1] - 2 * (b[x - 1] + b[x + 1]) + 4 * b[x] +
                    c[x - 1] - 2 * c[x] + c[x + 1];
      ++histogram[std::abs(r)];
      ++count;
    }
  }
  if (count == 0) return 0.0;
  long seen = 0;
  for (int v = 0; v <= kMaxResponse; ++v) {
    if (seen + histogram[v] >= count / 2) {
      // Interpolate inside the bin (integer responses): a clean image has most responses at 0.
      const double within =
          histogram[v] > 0 ? static_cast<double>(count / 2 - seen) / histogram[v] : 0.0;
      const double lower = v > 0 ? v - 0.5 : 0.0, width = v > 0 ? 1.0 : 0.5;  // bin of |r| = v
      return (lower + within * width) / (0.6745 * 6.0);
    }
    seen += histogram[v];
  }
  return 0.0;
}

cv::Mat toGray(const cv::Mat& image) {
  if (image.channels() == 1) return image;
  cv::Mat gray;
  cv::cvtColor(image, gray, cv::COLOR_BGR2GRAY);
  return gray;
}

}  // namespace image_detection

Eigen::Vector3d lineThrough(const Eigen::Vector2d& p, const Eigen::Vector2d& q,
                            const Eigen::Vector2d& inside) {
  Eigen::Vector2d d = q - p;
  Eigen::Vector2d n(-d.y(), d.x());
  n.normalize();
  double c = -n.dot(p);
  if (n.dot(inside) + c > 0) {
    n = -n;
    c = -c;
  }
  return {n.x(), n.y(), c};
}

namespace {

const cv::Scalar kEdgeColors[kNumEdges] = {
    {0, 0, 255}, {0, 200, 255}, {255, 0, 255}, {255, 128, 0}};
constexpr int kDrawShift = 4;  // fixed-point bits for sub-pixel drawing
constexpr double kDrawScale = 1 << kDrawShift;

cv::Point fixedPoint(const Eigen::Vector2d& p) {
  return {static_cast<int>(std::lround(p.x() * kDrawScale)),
          static_cast<int>(std::lround(p.y() * kDrawScale))};
}

// Draws an undistorted-pixel segment as the curve it is in the raw image.
void drawUndistortedSegment(cv::Mat* img, const CameraModel& camera, const Eigen::Vector2d& a,
                            const Eigen::Vector2d& b, const cv::Scalar& color, int thickness) {
  constexpr int kSteps = 64;
  std::vector<cv::Point> pts;
  for (int i = 0; i <= kSteps; ++i) {
    const Eigen::Vector2d u = a + (b - a) * (static_cast<double>(i) / kSteps);
    const Eigen::Vector2d r = camera.distortPixel(u);
    if (std::abs(r.x()) > 4 * img->cols || std::abs(r.y()) > 4 * img->rows) continue;
    pts.push_back(fixedPoint(r));
  }
  if (pts.size() >= 2) cv::polylines(*img, pts, false, color, thickness, cv::LINE_AA, kDrawShift);
}

// Clips an undistorted line to the image's undistorted bounding box (with margin) for drawing.
bool clipLine(const Eigen::Vector3d& l, const CameraModel& camera, Eigen::Vector2d* a,
              Eigen::Vector2d* b) {
  const double w = camera.width(), h = camera.height(), m = 0.25 * std::max(w, h);
  std::vector<Eigen::Vector2d> hits;
  for (double u : {-m, w + m})
    if (std::abs(l.y()) > 1e-9) {
      const double v = -(l.x() * u + l.z()) / l.y();
      if (v >= -m && v <= h + m) hits.emplace_back(u, v);
    }
  for (double v : {-m, h + m})
    if (std::abs(l.x()) > 1e-9) {
      const double u = -(l.y() * v + l.z()) / l.x();
      if (u >= -m && u <= w + m) hits.emplace_back(u, v);
    }
  if (hits.size() < 2) return false;
  *a = hits.front();
  *b = hits.back();
  return true;
}

}  // namespace

namespace {

// The quadrilaterals tried, and the one a miss's reason comes from (best_attempt).
const cv::Scalar kTriedColour(255, 80, 0), kBestAttemptColour(0, 140, 255);

// Plain board: line segments (thin grey) and the quadrilaterals tried (thin blue, with their
// verdicts; the best attempt of a miss in orange), drawn under the result.
void drawHypotheses(cv::Mat* image, const CameraModel& camera, const ImageDetectionDetails& details,
                    int thick) {
  cv::Mat& out = *image;

  for (const auto& s : details.segments_raw)
    cv::line(out, fixedPoint(s[0]), fixedPoint(s[1]), {160, 160, 160}, 1, cv::LINE_AA, kDrawShift);
  if (details.line_segments > 0)
    cv::putText(
        out,
        cv::format("noise %.1f, %d segments, %d lines, %d quadrilaterals", details.noise_sigma,
                   details.line_segments, details.straight_lines, details.line_quads),
        cv::Point(10, out.rows - 12 * thick), cv::FONT_HERSHEY_SIMPLEX, 0.5 * thick, {255, 80, 0},
        thick);
  for (size_t h = 0; h < details.hypotheses_px.size(); ++h) {
    const auto& c = details.hypotheses_px[h];
    const bool best = static_cast<int>(h) == details.best_attempt;
    const cv::Scalar& colour = best ? kBestAttemptColour : kTriedColour;
    for (int j = 0; j < kNumEdges; ++j)
      drawUndistortedSegment(&out, camera, c[j], c[(j + 1) % 4], colour, best ? thick : 1);
    if (h < details.hypothesis_reasons.size())
      cv::putText(out, std::to_string(h) + " " + details.hypothesis_reasons[h],
                  cv::Point(10, 30 * thick + static_cast<int>(h + 1) * 18 * thick),
                  cv::FONT_HERSHEY_SIMPLEX, 0.45 * thick, colour, thick);
  }
}

// The region outline, the edge points and lines by name, the corners.
void drawEdges(cv::Mat* image, const CameraModel& camera, const ImageDetection& det, int thick) {
  cv::Mat& out = *image;
  const CameraBoardFeatures& f = det.features;
  if (det.details.outline_raw.size() >= 2) {
    std::vector<cv::Point> outline;
    for (const auto& p : det.details.outline_raw) outline.push_back(fixedPoint(p));
    cv::polylines(out, outline, true, {0, 255, 255}, 1, cv::LINE_AA, kDrawShift);
  }
  for (int j = 0; j < kNumEdges; ++j) {
    for (const auto& p : det.details.edge_points_raw[j])
      cv::circle(out, fixedPoint(p), 1 << kDrawShift, {0, 255, 0}, cv::FILLED, cv::LINE_AA,
                 kDrawShift);
    if (!f.edge_valid[j]) continue;
    Eigen::Vector2d a, b;
    if (f.edge_valid[(j + 3) % 4] && f.edge_valid[(j + 1) % 4]) {
      a = f.corners_px[(j + 3) % 4];
      b = f.corners_px[j];
    } else if (!clipLine(f.edge_lines[j], camera, &a, &b)) {
      continue;
    }
    drawUndistortedSegment(&out, camera, a, b, kEdgeColors[j], thick);
    const Eigen::Vector2d mid =
        camera.distortPixel(0.5 * (a + b)) - 30.0 * f.edge_lines[j].head<2>();
    cv::putText(out, edgeName(j), cv::Point(int(mid.x()), int(mid.y())), cv::FONT_HERSHEY_SIMPLEX,
                0.6 * thick, kEdgeColors[j], thick);
  }
  for (int j = 0; j < kNumEdges; ++j)
    if (f.edge_valid[j] && f.edge_valid[(j + 1) % 4]) {
      const Eigen::Vector2d r = camera.distortPixel(f.corners_px[j]);
      cv::circle(out, fixedPoint(r), 6 << kDrawShift, {255, 255, 0}, thick, cv::LINE_AA,
                 kDrawShift);
    }
}

// Pattern corners and tag ids (checkerboard, AprilTag grid), and the board axes at its origin.
void drawPatternAndAxes(cv::Mat* image, const CameraModel& camera, const ImageDetection& det,
                        int thick) {
  cv::Mat& out = *image;
  const CameraBoardFeatures& f = det.features;
  for (const auto& p : det.details.pattern_raw)
    cv::circle(out, fixedPoint(p), 3 << kDrawShift, {0, 0, 255}, 1, cv::LINE_AA, kDrawShift);
  for (size_t i = 0; i < det.details.tag_ids.size(); ++i) {
    Eigen::Vector2d c = Eigen::Vector2d::Zero();
    for (const auto& p : det.details.tag_corners_raw[i]) c += 0.25 * p;
    cv::putText(out, std::to_string(det.details.tag_ids[i]), cv::Point(int(c.x()), int(c.y())),
                cv::FONT_HERSHEY_SIMPLEX, 0.5 * thick, {0, 0, 255}, thick);
  }
  if (f.found) {
    // Board axes at the board origin: x red, y green, z blue, 10 % of the distance long.
    const double len = 0.1 * f.camera_T_board.translation().norm();
    const Eigen::Vector3d o = f.camera_T_board.translation();
    Eigen::Vector2d po;
    if (camera.project(o, &po)) {
      const cv::Scalar colors[3] = {{0, 0, 255}, {0, 255, 0}, {255, 0, 0}};
      for (int a = 0; a < 3; ++a) {
        Eigen::Vector2d pa;
        if (camera.project(Eigen::Vector3d(o + len * f.camera_T_board.linear().col(a)), &pa))
          cv::line(out, fixedPoint(po), fixedPoint(pa), colors[a], thick + 1, cv::LINE_AA,
                   kDrawShift);
      }
    }
  }
}

}  // namespace

cv::Mat drawImageDetection(const cv::Mat& image, const CameraModel& camera,
                           const ImageDetection& det) {
  cv::Mat out;
  if (image.channels() == 1)
    cv::cvtColor(image, out, cv::COLOR_GRAY2BGR);
  else
    out = image.clone();
  const CameraBoardFeatures& f = det.features;
  const int thick = std::max(1, out.cols / 800);
  drawHypotheses(&out, camera, det.details, thick);
  drawEdges(&out, camera, det, thick);
  drawPatternAndAxes(&out, camera, det, thick);
  const std::string status =
      f.found
          ? "found" + (det.details.board_source.empty() ? "" : " by " + det.details.board_source) +
                cv::format(", rms %.2f px", f.reprojection_rms_px)
          : f.reason;
  cv::putText(out, status, cv::Point(10, 30 * thick), cv::FONT_HERSHEY_SIMPLEX, 0.7 * thick,
              f.found ? cv::Scalar(0, 255, 0) : cv::Scalar(0, 0, 255), thick);
  return out;
}

}  // namespace board_calib
