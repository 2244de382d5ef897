// SPDX-License-Identifier: BSD-3-Clause
// Synthetic board features at known ground truth (see synthetic_features.h).
#include "support/synthetic_views.h"
#include <board_calib/core/transform.h>

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <cmath>

namespace board_calib {
namespace sim {

namespace {

constexpr int kMaxAttemptsPerView = 200;
constexpr double kImageMarginPx = 10.0;     // corners this far inside the image
constexpr double kLidarFovMarginDeg = 0.5;  // corners this far inside the vertical FOV
constexpr int kMinRingPoints = 2;           // a ring needs a left and a right extreme
constexpr int kMinEdgePoints = 3;           // edge line fit

Eigen::Vector3d anyPerpendicular(const Eigen::Vector3d& v) {
  const Eigen::Vector3d a =
      std::abs(v.x()) < 0.9 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitY();
  return v.cross(a).normalized();
}

// Plane fit by SVD, normal oriented away from the origin (the sensor).
Plane fitPlane(const Points3& points, double* rms) {
  Eigen::Vector3d c = Eigen::Vector3d::Zero();
  for (const auto& p : points) c += p;
  c /= static_cast<double>(points.size());
  Eigen::Matrix3d S = Eigen::Matrix3d::Zero();
  for (const auto& p : points) S += (p - c) * (p - c).transpose();
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(S);
  Plane plane;
  plane.normal = eig.eigenvectors().col(0);
  plane.offset = plane.normal.dot(c);
  if (plane.offset < 0) {
    plane.normal = -plane.normal;
    plane.offset = -plane.offset;
  }
  *rms = std::sqrt(std::max(eig.eigenvalues()(0), 0.0) / points.size());
  return plane;
}

void fitLine(const Points3& points, Eigen::Vector3d* point, Eigen::Vector3d* direction) {
  Eigen::Vector3d c = Eigen::Vector3d::Zero();
  for (const auto& p : points) c += p;
  c /= static_cast<double>(points.size());
  Eigen::Matrix3d S = Eigen::Matrix3d::Zero();
  for (const auto& p : points) S += (p - c) * (p - c).transpose();
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(S);
  *point = c;
  *direction = eig.eigenvectors().col(2);
}

// Midpoint of the shortest segment between two 3D lines.
Eigen::Vector3d closestPoint(const Eigen::Vector3d& p1, const Eigen::Vector3d& d1,
                             const Eigen::Vector3d& p2, const Eigen::Vector3d& d2) {
  const Eigen::Vector3d w = p1 - p2;
  const double a = d1.dot(d1), b = d1.dot(d2), c = d2.dot(d2), d = d1.dot(w), e = d2.dot(w);
  const double den = a * c - b * b;
  if (std::abs(den) < 1e-12) return 0.5 * (p1 + p2);
  const double s = (b * e - c * d) / den, t = (a * e - b * d) / den;
  return 0.5 * ((p1 + s * d1) + (p2 + t * d2));
}

Eigen::Vector3d lineThrough(const Eigen::Vector2d& a, const Eigen::Vector2d& b,
                            const Eigen::Vector2d& inside) {
  Eigen::Vector3d l = Eigen::Vector3d(a.x(), a.y(), 1.0).cross(Eigen::Vector3d(b.x(), b.y(), 1.0));
  l /= l.head<2>().norm();
  if (l.dot(Eigen::Vector3d(inside.x(), inside.y(), 1.0)) > 0) l = -l;  // interior < 0
  return l;
}

Eigen::Vector2d intersect(const Eigen::Vector3d& l1, const Eigen::Vector3d& l2) {
  const Eigen::Vector3d p = l1.cross(l2);
  return p.head<2>() / p.z();
}

// PnP by Gauss-Newton on the reprojection error of the board corners, from a start near the
// optimum (the true pose): the pose the detector's PnP (IPPE + LM) converges to.
Eigen::Isometry3d refinePnp(const std::array<Eigen::Vector3d, 4>& object,
                            const std::array<Eigen::Vector2d, 4>& image, const Eigen::Matrix3d& K,
                            Eigen::Isometry3d T) {
  constexpr int kIterations = 20;
  constexpr double kStep = 1e-7;  // numerical derivative step, rad / m
  auto residuals = [&](const Eigen::Isometry3d& pose) {
    Eigen::Matrix<double, 8, 1> r;
    for (int i = 0; i < 4; ++i) {
      const Eigen::Vector3d uv = K * (pose * object[i]);
      r.segment<2>(2 * i) = uv.head<2>() / uv.z() - image[i];
    }
    return r;
  };
  auto perturbed = [](const Eigen::Isometry3d& pose, const Eigen::Matrix<double, 6, 1>& d) {
    Eigen::Isometry3d out = pose;
    out.linear() = expSO3(d.head<3>()) * pose.linear();
    out.translation() += d.tail<3>();
    return out;
  };
  for (int it = 0; it < kIterations; ++it) {
    const Eigen::Matrix<double, 8, 1> r = residuals(T);
    Eigen::Matrix<double, 8, 6> J;
    for (int k = 0; k < 6; ++k) {
      Eigen::Matrix<double, 6, 1> d = Eigen::Matrix<double, 6, 1>::Zero();
      d(k) = kStep;
      J.col(k) = (residuals(perturbed(T, d)) - r) / kStep;
    }
    const Eigen::Matrix<double, 6, 1> step = (J.transpose() * J).ldlt().solve(-J.transpose() * r);
    T = perturbed(T, step);
    if (step.norm() < 1e-12) break;
  }
  return T;
}

}  // namespace

std::string SyntheticFeatureOptions::validate() const {
  if (num_views < 1) return "num_views must be >= 1";
  if (!(board_width_m > 0) || !(board_height_m > 0)) return "board size must be > 0";
  if (!(declared_size_factor > 0)) return "declared_size_factor must be > 0";
  if (lidar_rings < 2) return "lidar_rings must be >= 2";
  if (!(lidar_vertical_fov_deg > 0) || lidar_vertical_fov_deg >= 180)
    return "lidar_vertical_fov_deg must be in (0, 180)";
  if (!(lidar_horizontal_resolution_deg > 0)) return "lidar_horizontal_resolution_deg must be > 0";
  if (lidar_range_noise_m < 0 || line_noise_px < 0 || camera_plane_normal_noise_deg < 0 ||
      camera_plane_offset_noise_m < 0)
    return "noise levels must be >= 0";
  if (max_board_points < 0) return "max_board_points must be >= 0";
  if (image_width < 2 || image_height < 2 || !(fx > 0) || !(fy > 0))
    return "camera intrinsics invalid";
  if (!(min_distance_m > 0) || max_distance_m < min_distance_m) return "distance range invalid";
  if (max_tilt_deg < 0 || max_tilt_deg >= 80) return "max_tilt_deg must be in [0, 80)";
  if (max_off_axis_fraction < 0 || max_off_axis_fraction > 1)
    return "max_off_axis_fraction must be in [0, 1]";
  return "";
}

Eigen::Isometry3d randomCameraTLidar(std::mt19937& rng, double max_extra_rotation_deg,
                                     double max_offset_m) {
  // camera x = -lidar y, camera y = -lidar z, camera z = lidar x.
  Eigen::Matrix3d base;
  base << 0, -1, 0, 0, 0, -1, 1, 0, 0;
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  Eigen::Vector3d axis(unit(rng), unit(rng), unit(rng));
  if (axis.norm() < 1e-6) axis = Eigen::Vector3d::UnitZ();
  const double angle = unit(rng) * max_extra_rotation_deg * kRadPerDeg;
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = expSO3(axis.normalized() * angle) * base;
  T.translation() = Eigen::Vector3d(unit(rng), unit(rng), unit(rng)) * max_offset_m;
  return T;
}

namespace {

// The board's geometry and the sensors' intrinsics every view is drawn with.
struct Setup {
  Eigen::Matrix3d K;
  double w = 0.0, h = 0.0;
  std::array<Eigen::Vector3d, 4> board_corners;
  double step = 0.0, half_fov = 0.0;  // rad: LiDAR horizontal step, half vertical field of view
};

// A random board pose in the camera frame (held as a diamond, tilted, off axis); `centre` is
// the board centre.
Eigen::Isometry3d drawBoardPose(const SyntheticFeatureOptions& o, const Setup& g, std::mt19937& rng,
                                Eigen::Vector3d* centre_out) {
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  const Eigen::Matrix3d& K = g.K;
  const double w = g.w, h = g.h;
  const double u = o.cx + (2 * uniform(rng) - 1) * o.max_off_axis_fraction * 0.5 * o.image_width;
  const double v = o.cy + (2 * uniform(rng) - 1) * o.max_off_axis_fraction * 0.5 * o.image_height;
  const Eigen::Vector3d ray = K.inverse() * Eigen::Vector3d(u, v, 1.0);
  const Eigen::Vector3d ray_dir = ray.normalized();
  const double dist = o.min_distance_m + uniform(rng) * (o.max_distance_m - o.min_distance_m);
  const Eigen::Vector3d centre = ray_dir * dist;
  *centre_out = centre;
  const Eigen::Vector3d tilt_axis =
      expSO3(ray_dir * uniform(rng) * 2 * M_PI) * anyPerpendicular(ray_dir);
  const Eigen::Vector3d z =
      expSO3(tilt_axis * uniform(rng) * o.max_tilt_deg * kRadPerDeg) * ray_dir;
  Eigen::Vector3d x = (Eigen::Vector3d::UnitX() - z * z.x()).normalized();
  const double spin = (45.0 + (2 * uniform(rng) - 1) * o.diamond_jitter_deg) * kRadPerDeg;
  x = expSO3(z * spin) * x;
  const Eigen::Vector3d y = z.cross(x);
  Eigen::Isometry3d camera_T_board = Eigen::Isometry3d::Identity();
  camera_T_board.linear().col(0) = x;
  camera_T_board.linear().col(1) = y;
  camera_T_board.linear().col(2) = z;
  camera_T_board.translation() =
      centre - camera_T_board.linear() * Eigen::Vector3d(w / 2, h / 2, 0);

  return camera_T_board;
}

// Every corner inside the image (with a margin) and the LiDAR's vertical field of view, in front
// of both; `px` the corners' pixels, `lc` the corners in the LiDAR frame.
bool visibleInBoth(const SyntheticFeatureOptions& o, const Setup& g,
                   const Eigen::Isometry3d& camera_T_board, const Eigen::Isometry3d& lidar_T_camera,
                   std::array<Eigen::Vector2d, 4>* px_out, std::array<Eigen::Vector3d, 4>* lc_out) {
  const Eigen::Matrix3d& K = g.K;
  const auto& board_corners = g.board_corners;
  std::array<Eigen::Vector2d, 4>& px = *px_out;
  std::array<Eigen::Vector3d, 4>& lc = *lc_out;
  // Camera: all corners inside the image.
  bool visible = true;
  for (int i = 0; i < 4; ++i) {
    const Eigen::Vector3d pc = camera_T_board * board_corners[i];
    if (pc.z() <= 0) visible = false;
    const Eigen::Vector3d uv = K * (pc / pc.z());
    px[i] = uv.head<2>();
    if (px[i].x() < kImageMarginPx || px[i].y() < kImageMarginPx ||
        px[i].x() > o.image_width - kImageMarginPx || px[i].y() > o.image_height - kImageMarginPx)
      visible = false;
  }
  if (!visible) return false;
  // LiDAR: all corners inside the vertical field of view, in front.
  const Eigen::Isometry3d lidar_T_board = lidar_T_camera * camera_T_board;
  for (int i = 0; i < 4; ++i) {
    lc[i] = lidar_T_board * board_corners[i];
    const double elev = std::atan2(lc[i].z(), lc[i].head<2>().norm());
    if (std::abs(elev) > g.half_fov - kLidarFovMarginDeg * kRadPerDeg || lc[i].x() <= 0)
      visible = false;
  }
  return visible;
}

// LiDAR ray casting: rings x azimuth grid with a random phase, range noise along the ray; the
// per-ring extremes are the edge points. False when the board got too few points.
bool castLidar(const SyntheticFeatureOptions& o, const Setup& g,
               const Eigen::Isometry3d& lidar_T_board, const std::array<Eigen::Vector3d, 4>& lc,
               std::mt19937& rng, std::normal_distribution<double>& normal, View* view_out) {
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  const double w = g.w, h = g.h, step = g.step, half_fov = g.half_fov;
  View& view = *view_out;
  // LiDAR ray casting: rings x azimuth grid with a random phase.
  const Eigen::Vector3d nL = lidar_T_board.linear().col(2);
  const double dL = nL.dot(lidar_T_board.translation());
  const Eigen::Isometry3d board_T_lidar = lidar_T_board.inverse();
  double az_min = 1e9, az_max = -1e9;
  const Eigen::Vector3d lcentre = lidar_T_board * Eigen::Vector3d(w / 2, h / 2, 0);
  const double az_centre = std::atan2(lcentre.y(), lcentre.x());
  for (const auto& c : lc) {
    const double a = std::remainder(std::atan2(c.y(), c.x()) - az_centre, 2 * M_PI);
    az_min = std::min(az_min, a);
    az_max = std::max(az_max, a);
  }
  // Corner elevations of the left-most (max azimuth) and right-most corners.
  int left_corner = 0, right_corner = 0;
  for (int i = 0; i < 4; ++i) {
    const double a = std::remainder(std::atan2(lc[i].y(), lc[i].x()) - az_centre, 2 * M_PI);
    const double al =
        std::remainder(std::atan2(lc[left_corner].y(), lc[left_corner].x()) - az_centre, 2 * M_PI);
    const double ar = std::remainder(
        std::atan2(lc[right_corner].y(), lc[right_corner].x()) - az_centre, 2 * M_PI);
    if (a > al) left_corner = i;
    if (a < ar) right_corner = i;
  }
  auto elevation = [](const Eigen::Vector3d& p) { return std::atan2(p.z(), p.head<2>().norm()); };
  const double left_elev = elevation(lc[left_corner]), right_elev = elevation(lc[right_corner]);

  LidarBoardFeatures& lidar = view.lidar;
  lidar.frame_id = "lidar";
  lidar.stamp = view.id;
  const double phase = uniform(rng) * step;
  const double az_grid0 = az_centre + phase;
  const int m_lo = static_cast<int>(std::floor(az_min / step)) - 1,
            m_hi = static_cast<int>(std::ceil(az_max / step)) + 1;
  Points3 board_points;
  for (int ring = 0; ring < o.lidar_rings; ++ring) {
    const double elev = -half_fov + 2 * half_fov * ring / (o.lidar_rings - 1);
    Points3 ring_points;  // in increasing azimuth
    for (int m = m_lo; m <= m_hi; ++m) {
      const double az = az_grid0 + m * step;
      const Eigen::Vector3d d(std::cos(elev) * std::cos(az), std::cos(elev) * std::sin(az),
                              std::sin(elev));
      const double denom = nL.dot(d);
      if (std::abs(denom) < 1e-9) continue;
      const double range = dL / denom;
      if (range <= 0) continue;
      const Eigen::Vector3d q = board_T_lidar * (range * d);
      if (q.x() < 0 || q.x() > w || q.y() < 0 || q.y() > h) continue;
      ring_points.push_back((range + o.lidar_range_noise_m * normal(rng)) * d);
    }
    if (static_cast<int>(ring_points.size()) < kMinRingPoints) {
      board_points.insert(board_points.end(), ring_points.begin(), ring_points.end());
      continue;
    }
    // Per-scan-line extremes: the last point (max azimuth) is the left one.
    const Eigen::Vector3d& left = ring_points.back();
    const Eigen::Vector3d& right = ring_points.front();
    lidar.edge_points[elev > left_elev ? kUpperLeft : kLowerLeft].push_back(left);
    lidar.edge_points[elev > right_elev ? kUpperRight : kLowerRight].push_back(right);
    board_points.insert(board_points.end(), ring_points.begin(), ring_points.end());
  }
  if (board_points.size() < 10) return false;
  std::shuffle(board_points.begin(), board_points.end(), rng);
  if (o.max_board_points > 0 && static_cast<int>(board_points.size()) > o.max_board_points)
    board_points.resize(o.max_board_points);
  lidar.board_points = board_points;
  return true;
}

// The LiDAR's plane, edge lines, corners and measured size from its points.
void fitLidarFeatures(LidarBoardFeatures& lidar) {
  lidar.plane = fitPlane(lidar.board_points, &lidar.plane_rms_m);
  lidar.found = true;
  for (int j = 0; j < kNumEdges; ++j) {
    lidar.edge_valid[j] = static_cast<int>(lidar.edge_points[j].size()) >= kMinEdgePoints;
    if (lidar.edge_valid[j])
      fitLine(lidar.edge_points[j], &lidar.edge_line_point[j], &lidar.edge_line_direction[j]);
  }
  for (int j = 0; j < kNumEdges; ++j) {
    const int k = (j + 1) % kNumEdges;
    if (lidar.edge_valid[j] && lidar.edge_valid[k])
      lidar.corners[j] = closestPoint(lidar.edge_line_point[j], lidar.edge_line_direction[j],
                                      lidar.edge_line_point[k], lidar.edge_line_direction[k]);
  }
  if (lidar.allEdgesValid())
    lidar.measured_size_m = Eigen::Vector2d(0.5 * ((lidar.corners[3] - lidar.corners[0]).norm() +
                                                   (lidar.corners[2] - lidar.corners[1]).norm()),
                                            0.5 * ((lidar.corners[1] - lidar.corners[0]).norm() +
                                                   (lidar.corners[3] - lidar.corners[2]).norm()));
}

// Camera: corners named top/right/bottom/left in the image, edge lines with pixel noise, the
// board plane as PnP with the declared board size gives it.
void observeCamera(const SyntheticFeatureOptions& o, const Setup& g,
                   const Eigen::Isometry3d& camera_T_board, const Eigen::Vector3d& centre,
                   const std::array<Eigen::Vector2d, 4>& px, std::mt19937& rng,
                   std::normal_distribution<double>& normal, CameraBoardFeatures* cam_out) {
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  const Eigen::Matrix3d& K = g.K;
  const double w = g.w, h = g.h;
  const auto& board_corners = g.board_corners;
  CameraBoardFeatures& cam = *cam_out;
  // Edge j runs from corner j-1 to j.
  cam.frame_id = "camera";
  cam.found = true;
  cam.K = K;
  cam.image_width = o.image_width;
  cam.image_height = o.image_height;
  std::array<int, 4> named{};  // top, right, bottom, left -> board corner index
  for (int i = 0; i < 4; ++i) {
    if (px[i].y() < px[named[0]].y()) named[0] = i;
    if (px[i].x() > px[named[1]].x()) named[1] = i;
    if (px[i].y() > px[named[2]].y()) named[2] = i;
    if (px[i].x() < px[named[3]].x()) named[3] = i;
  }
  const Eigen::Vector3d pcentre = K * (centre / centre.z());
  for (int j = 0; j < kNumEdges; ++j) {
    const Eigen::Vector2d a = px[named[(j + 3) % 4]], b = px[named[j]];
    const Eigen::Vector2d ab = (b - a).normalized();
    const Eigen::Vector2d perp(-ab.y(), ab.x());
    const Eigen::Vector2d an = a + perp * o.line_noise_px * normal(rng);
    const Eigen::Vector2d bn = b + perp * o.line_noise_px * normal(rng);
    cam.edge_lines[j] = lineThrough(an, bn, pcentre.head<2>());
    cam.edge_valid[j] = true;
  }
  for (int j = 0; j < kNumEdges; ++j)
    cam.corners_px[j] = intersect(cam.edge_lines[j], cam.edge_lines[(j + 1) % 4]);
  // Camera plane: what PnP with the declared board size gives (translation scales), plus noise.
  Eigen::Isometry3d declared = camera_T_board;
  declared.translation() *= o.declared_size_factor;
  Eigen::Vector3d n = camera_T_board.linear().col(2);
  const Eigen::Vector3d tilt_dir = anyPerpendicular(n);
  n = expSO3(expSO3(n * uniform(rng) * 2 * M_PI) * tilt_dir * o.camera_plane_normal_noise_deg *
             kRadPerDeg * normal(rng)) *
      n;
  cam.camera_T_board = declared;
  cam.plane.normal = n.normalized();
  cam.plane.offset = cam.plane.normal.dot(declared.linear() * Eigen::Vector3d(w / 2, h / 2, 0) *
                                              o.declared_size_factor +
                                          declared.translation()) +
                     o.camera_plane_offset_noise_m * normal(rng);
  if (o.camera_plane_from_pnp) {
    // corners_px[j] is the image corner named[j] (edges j and j + 1 meet there).
    std::array<Eigen::Vector3d, 4> object;
    std::array<Eigen::Vector2d, 4> image;
    for (int j = 0; j < 4; ++j) {
      object[j] = board_corners[named[j]] * o.declared_size_factor;
      image[j] = cam.corners_px[j];
    }
    Eigen::Isometry3d start = camera_T_board;
    start.translation() *= o.declared_size_factor;
    cam.camera_T_board = refinePnp(object, image, K, start);
    cam.plane.normal = cam.camera_T_board.linear().col(2);
    cam.plane.offset = cam.plane.normal.dot(cam.camera_T_board.translation());
    if (cam.plane.offset < 0) {
      cam.plane.normal = -cam.plane.normal;
      cam.plane.offset = -cam.plane.offset;
    }
  }
}

}  // namespace

Expected<SyntheticScene> generateSyntheticViews(const SyntheticFeatureOptions& o,
                                                const Eigen::Isometry3d& camera_T_lidar,
                                                std::mt19937& rng) {
  const std::string invalid = o.validate();
  if (!invalid.empty())
    return Expected<SyntheticScene>::failure("invalid synthetic options: " + invalid);
  Setup g;
  g.K << o.fx, 0, o.cx, 0, o.fy, o.cy, 0, 0, 1;
  g.w = o.board_width_m;
  g.h = o.board_height_m;
  g.board_corners = {Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(g.w, 0, 0),
                     Eigen::Vector3d(g.w, g.h, 0), Eigen::Vector3d(0, g.h, 0)};
  g.step = o.lidar_horizontal_resolution_deg * kRadPerDeg;
  g.half_fov = 0.5 * o.lidar_vertical_fov_deg * kRadPerDeg;
  const Eigen::Isometry3d lidar_T_camera = camera_T_lidar.inverse();
  // One normal distribution for the whole scene: it keeps a spare draw between calls, so the
  // sequence (and every seeded test's scene) stays the same.
  std::normal_distribution<double> normal(0.0, 1.0);

  SyntheticScene scene;
  scene.camera_T_lidar = camera_T_lidar;
  int attempts = 0;
  while (static_cast<int>(scene.views.size()) < o.num_views) {
    if (++attempts > kMaxAttemptsPerView * o.num_views)
      return Expected<SyntheticScene>::failure("only " + std::to_string(scene.views.size()) +
                                               " board poses fit both fields of view");
    Eigen::Vector3d centre;
    const Eigen::Isometry3d camera_T_board = drawBoardPose(o, g, rng, &centre);
    std::array<Eigen::Vector2d, 4> px;
    std::array<Eigen::Vector3d, 4> lc;
    if (!visibleInBoth(o, g, camera_T_board, lidar_T_camera, &px, &lc)) continue;
    View view;
    view.id = static_cast<int>(scene.views.size());
    if (!castLidar(o, g, lidar_T_camera * camera_T_board, lc, rng, normal, &view)) continue;
    fitLidarFeatures(view.lidar);
    view.camera.stamp = view.id;
    observeCamera(o, g, camera_T_board, centre, px, rng, normal, &view.camera);
    scene.views.push_back(view);
    scene.camera_T_board.push_back(camera_T_board);
  }
  return scene;
}

void lengthenRanges(LidarBoardFeatures* lidar, double delta_m) {
  const auto move = [delta_m](Eigen::Vector3d* p) {
    const double r = p->norm();
    if (r > 0.0) *p *= 1.0 + delta_m / r;
  };
  for (auto& p : lidar->board_points) move(&p);
  for (auto& edge : lidar->edge_points)
    for (auto& p : edge) move(&p);
  for (auto& p : lidar->edge_line_point) move(&p);
  for (auto& p : lidar->corners) move(&p);
  double offset = 0.0;
  for (const auto& p : lidar->board_points) offset += lidar->plane.normal.dot(p);
  if (!lidar->board_points.empty())
    lidar->plane.offset = offset / static_cast<double>(lidar->board_points.size());
}

}  // namespace sim
}  // namespace board_calib
