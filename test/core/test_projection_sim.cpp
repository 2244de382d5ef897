// End-to-end overlay check on simulated data with a known extrinsic: the board's LiDAR edge
// points, projected by the projection core, must land on the board edges of the rendered image
// within 1 px (issue 8).
//
// Per-scan-line extremes of the board returns lie inside the board by up to one column step
// (0.35 deg for an OS1-64: ~17 px at 4 m with fx 2814), so they cannot be held to 1 px. Each
// extreme is refined with the LiDAR's true geometry instead: its beam is bisected in azimuth
// between the last column on the board and the first one off it, giving the point where the
// scan line really crosses the board edge.
#include <board_calib/core/projection/projection.h>
#include <board_calib/core/sim/simulator.h>
#include <board_calib/core/transform.h>
#include "support/basler_camera.h"

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <cmath>
#include <random>

using namespace board_calib;

namespace {

CameraModel baslerCamera() { return CameraModel::create(sim::baslerIntrinsics()).value(); }

Eigen::Vector3d beam(double az, double el) {
  return {std::cos(el) * std::cos(az), std::cos(el) * std::sin(az), std::sin(el)};
}

struct BoardGeometry {
  Target target;
  Eigen::Isometry3d lidar_T_board;
  // Where the beam (az, el) from the LiDAR origin meets the board plane, in board coordinates.
  bool hit(double az, double el, Eigen::Vector3d* p_lidar, Eigen::Vector3d* p_board) const {
    const Eigen::Vector3d n = lidar_T_board.linear().col(2), o = lidar_T_board.translation();
    const Eigen::Vector3d d = beam(az, el);
    const double denom = n.dot(d);
    if (std::abs(denom) < 1e-12) return false;
    const double t = n.dot(o) / denom;
    if (t <= 0) return false;
    *p_lidar = t * d;
    *p_board = lidar_T_board.inverse() * *p_lidar;
    return p_board->x() >= 0 && p_board->y() >= 0 && p_board->x() < target.width &&
           p_board->y() < target.height;
  }
};

// Board side a point on the boundary lies on: 0 top (y = 0), 1 right (x = w), 2 bottom, 3 left.
int boardSide(const Target& target, const Eigen::Vector3d& p_board) {
  const double d[4] = {std::abs(p_board.y()), std::abs(p_board.x() - target.width),
                       std::abs(p_board.y() - target.height), std::abs(p_board.x())};
  return static_cast<int>(std::min_element(d, d + 4) - d);
}

// Sub-pixel position (px along the outward normal, 0 = at `undistorted`) where the grey level
// crosses half-way between the board and the background; NaN when the profile is unclear.
double edgeOffsetPx(const cv::Mat& grey, const CameraModel& camera,
                    const Eigen::Vector2d& undistorted, const Eigen::Vector2d& outward) {
  constexpr double kReach = 8.0, kStep = 0.125, kPlateau = 5.0;
  std::vector<double> s_values, profile;
  for (double s = -kReach; s <= kReach + 1e-9; s += kStep) {
    const Eigen::Vector2d raw = camera.distortPixel(undistorted + s * outward);
    if (raw.x() < 1 || raw.y() < 1 || raw.x() > grey.cols - 2 || raw.y() > grey.rows - 2)
      return NAN;
    cv::Mat patch;
    cv::getRectSubPix(grey, cv::Size(1, 1),
                      cv::Point2f(static_cast<float>(raw.x()), static_cast<float>(raw.y())), patch,
                      CV_32F);
    s_values.push_back(s);
    profile.push_back(patch.at<float>(0, 0));
  }
  double inside = 0, outside = 0;
  int n_in = 0, n_out = 0;
  for (size_t i = 0; i < s_values.size(); ++i) {
    if (s_values[i] <= -kPlateau) inside += profile[i], ++n_in;
    if (s_values[i] >= kPlateau) outside += profile[i], ++n_out;
  }
  inside /= n_in;
  outside /= n_out;
  if (inside - outside < 50) return NAN;  // not a clean white-board / dark-background edge
  const double half = 0.5 * (inside + outside);
  for (size_t i = 0; i + 1 < profile.size(); ++i)
    if (profile[i] >= half && profile[i + 1] < half)
      return s_values[i] + kStep * (profile[i] - half) / (profile[i] - profile[i + 1]);
  return NAN;
}

// Per-scan-line extremes of the board returns: raw (`measured`, grouped by board side) and
// refined on the true geometry by bisecting the beam azimuth (`refined`, its side per point).
struct EdgeSamples {
  LidarBoardFeatures measured;
  LidarCloud refined;
  std::vector<int> refined_side;
};
EdgeSamples edgeSamples(const LidarCloud& scan, const std::vector<sim::ReturnOrigin>& origins,
                        const sim::LidarSpec& lidar, const BoardGeometry& board,
                        const Target& target) {
  EdgeSamples out;
  LidarBoardFeatures& measured = out.measured;
  LidarCloud& refined = out.refined;
  std::vector<int>& refined_side = out.refined_side;
  measured.found = true;
  refined.frame_id = "lidar";
  const int cols = scan.width;
  for (int ring = 0; ring < scan.height; ++ring) {
    int lo = -1, hi = -1;
    for (int col = 0; col < cols; ++col) {
      const auto o = origins[static_cast<size_t>(ring) * cols + col];
      if (o != sim::ReturnOrigin::kBoard && o != sim::ReturnOrigin::kMixed) continue;
      if (lo < 0) lo = col;
      hi = col;
    }
    if (lo < 0) continue;
    const double el = lidar.elevations_deg[ring] * kRadPerDeg;
    for (const auto& [extreme, outward] :
         {std::pair<int, int>{lo, -1}, std::pair<int, int>{hi, +1}}) {
      // Step to the last column whose beam centre hits the board, then bisect towards the next.
      Eigen::Vector3d p_lidar, p_board;
      int in = extreme;
      while (!board.hit(lidar.azimuthRad(ring, in), el, &p_lidar, &p_board) && in != (lo + hi) / 2)
        in -= outward;
      if (!board.hit(lidar.azimuthRad(ring, in), el, &p_lidar, &p_board)) continue;
      int out = in + outward;
      while (board.hit(lidar.azimuthRad(ring, out), el, &p_lidar, &p_board)) out += outward;
      double a_in = lidar.azimuthRad(ring, in), a_out = lidar.azimuthRad(ring, out);
      for (int it = 0; it < 60; ++it) {
        const double mid = 0.5 * (a_in + a_out);
        (board.hit(mid, el, &p_lidar, &p_board) ? a_in : a_out) = mid;
      }
      board.hit(a_in, el, &p_lidar, &p_board);
      const int side = boardSide(target, p_board);
      LidarPoint lp;
      lp.x = static_cast<float>(p_lidar.x());
      lp.y = static_cast<float>(p_lidar.y());
      lp.z = static_cast<float>(p_lidar.z());
      refined.points.push_back(lp);
      refined_side.push_back(side);
      const LidarPoint& raw = scan.points[static_cast<size_t>(ring) * cols + extreme];
      measured.edge_points[side].emplace_back(raw.x, raw.y, raw.z);
      measured.edge_valid[side] = true;
    }
  }
  return out;
}

// The board's true image lines (undistorted px, outward normals), side by side.
CameraBoardFeatures trueImageLines(const CameraModel& camera,
                                   const Eigen::Isometry3d& camera_T_board, const Target& target) {
  const auto corners = target.outerCorners();
  CameraBoardFeatures truth;
  truth.found = true;
  Eigen::Vector2d centre_px;
  EXPECT_TRUE(camera.projectUndistorted(camera_T_board * target.center(), &centre_px));
  for (int side = 0; side < 4; ++side) {
    Eigen::Vector2d a, b;
    EXPECT_TRUE(camera.projectUndistorted(camera_T_board * corners[side], &a));
    EXPECT_TRUE(camera.projectUndistorted(camera_T_board * corners[(side + 1) % 4], &b));
    Eigen::Vector3d line(b.y() - a.y(), a.x() - b.x(), 0.0);
    line /= line.head<2>().norm();
    line.z() = -line.head<2>().dot(a);
    if (line.head<2>().dot(centre_px) + line.z() > 0) line = -line;
    truth.edge_lines[side] = line;
    truth.edge_valid[side] = true;
  }

  return truth;
}

// The projected edge points against the true lines (geometry) and against the rendered edges
// (the image's grey-level profile along the outward normal), away from the board corners.
struct EdgeOffsets {
  int measured = 0;
  double worst_image_px = 0, sum_image_px = 0, worst_line_px = 0;
};
EdgeOffsets measureEdgeOffsets(const cv::Mat& image, const CameraModel& camera,
                               const ProjectedCloud& projected,
                               const std::vector<int>& refined_side,
                               const CameraBoardFeatures& truth,
                               const Eigen::Isometry3d& camera_T_board,
                               const std::array<Eigen::Vector3d, 4>& corners) {
  EdgeOffsets out;
  int& measured_edges = out.measured;
  double &worst_image_px = out.worst_image_px, &sum_image_px = out.sum_image_px,
         &worst_line_px = out.worst_line_px;
  cv::Mat grey;
  cv::cvtColor(image, grey, cv::COLOR_BGR2GRAY);
  for (const ProjectedPoint& p : projected.points) {
    const int side = refined_side[p.index];
    const Eigen::Vector3d& line = truth.edge_lines[side];
    const Eigen::Vector2d u = camera.undistortPixel(Eigen::Vector2d(p.u, p.v));
    // Geometry: on the true line up to float storage of the points (~1e-3 px).
    worst_line_px = std::max(worst_line_px, std::abs(line.head<2>().dot(u) + line.z()));
    // Image: the rendered edge along the outward normal. Skip points near a board corner,
    // where the profile crosses the other edge too.
    bool near_corner = false;
    for (int c = 0; c < 4; ++c) {
      Eigen::Vector2d corner_px;
      camera.projectUndistorted(camera_T_board * corners[c], &corner_px);
      near_corner |= (corner_px - u).norm() < 20.0;
    }
    if (near_corner) continue;
    const double offset = edgeOffsetPx(grey, camera, u, line.head<2>());
    if (std::isnan(offset)) continue;
    ++measured_edges;
    worst_image_px = std::max(worst_image_px, std::abs(offset));
    sum_image_px += std::abs(offset);
  }
  return out;
}

// The overlay itself: the whole scan drawn, then the projected-edges check of the raw
// extremes against the true lines. Raw extremes sit inside the board by less than one column
// step, which bounds their mean residual.
void expectOverlayDrawn(const cv::Mat& image, const LidarCloud& scan,
                        const LidarBoardFeatures& measured, const CameraBoardFeatures& truth,
                        const CameraModel& camera, const Eigen::Isometry3d& camera_T_lidar,
                        const sim::LidarSpec& lidar) {
  ProjectionOptions options;
  cv::Mat overlay = image.clone();
  const auto scan_projected = projectCloud(scan, camera, camera_T_lidar, options);
  ASSERT_TRUE(scan_projected.ok());
  ASSERT_TRUE(drawProjectedCloud(*scan_projected, OverlayOptions(), &overlay).ok);
  EdgeCheckOptions edge_options;
  edge_options.reassociate = false;  // sides are named identically on both sensors here
  const auto check = checkProjectedEdges(measured, truth, camera, camera_T_lidar, edge_options);
  ASSERT_TRUE(check.ok()) << check.error();
  const double column_step_px =
      camera.intrinsics().fx * lidar.horizontal_resolution_deg * kRadPerDeg;
  EXPECT_LT(check->mlre_px, column_step_px);
  ASSERT_TRUE(drawEdgeCheck(truth, *check, camera, edge_options, &overlay).ok);
  const std::string out = ::testing::TempDir() + "board_calib_projection_sim_overlay.png";
  cv::imwrite(out, overlay);
  std::printf(
      "raw per-scan-line extremes: MLRE %.2f px (column step %.1f px); overlay saved to %s\n",
      check->mlre_px, column_step_px, out.c_str());
}

}  // namespace

TEST(ProjectionSim, ProjectedLidarEdgePointsLandOnTheRenderedBoardEdges) {
  const CameraModel camera = baslerCamera();
  auto spec = sim::lidarPreset("OS1-64");
  ASSERT_TRUE(spec.ok()) << spec.error();

  // LiDAR at the world origin (x forward, z up); camera optical frame near it, slightly tilted.
  const Eigen::Isometry3d world_T_lidar = Eigen::Isometry3d::Identity();
  Eigen::Matrix3d optical_R_lidar;
  optical_R_lidar << 0, -1, 0, 0, 0, -1, 1, 0, 0;
  const Eigen::Isometry3d camera_T_lidar =
      makeTransform(fromRollPitchYaw(Eigen::Vector3d(0.01, -0.02, 0.015)) * optical_R_lidar,
                    Eigen::Vector3d(0.06, -0.11, -0.07));
  const Eigen::Isometry3d world_T_camera = world_T_lidar * camera_T_lidar.inverse();

  // A plain board held as a diamond 4 m ahead, turned a little so no edge is parallel to the
  // scan lines and the plane is oblique.
  sim::SceneSpec scene;
  scene.target.type = TargetType::kPlain;
  scene.target.width = scene.target.height = 1.016;
  scene.room = false;  // board on black: a clean photometric edge to measure
  scene.occluder = false;
  Eigen::Matrix3d facing;  // board x = -y_world (right), y = -z_world (down), z = +x_world (away)
  facing << 0, 0, 1, -1, 0, 0, 0, -1, 0;
  const Eigen::Matrix3d R_board = fromRollPitchYaw(Eigen::Vector3d(0.0, 0.0, 12.0 * kRadPerDeg)) *
                                  facing * expSO3(Eigen::Vector3d(0, 0, 47.0 * kRadPerDeg)) *
                                  expSO3(Eigen::Vector3d(8.0 * kRadPerDeg, 0, 0));
  Eigen::Isometry3d world_T_board = makeTransform(R_board, Eigen::Vector3d(4.0, 0.1, 0.05));
  world_T_board.translation() -= R_board * scene.target.center();

  std::mt19937 rng(11);
  std::vector<sim::ReturnOrigin> origins;
  const LidarCloud scan =
      sim::simulateLidarScan(*spec, world_T_lidar, scene, world_T_board, rng, &origins);
  ASSERT_EQ(scan.points.size(), origins.size());
  ASSERT_TRUE(scan.organized());
  sim::RenderOptions render;
  const cv::Mat image =
      sim::renderCameraImage(camera, world_T_camera, scene, world_T_board, render, rng);
  ASSERT_FALSE(image.empty());

  // Per-scan-line extremes of the board returns, then refined on the true geometry.
  const BoardGeometry board{scene.target, world_T_lidar.inverse() * world_T_board};
  const EdgeSamples samples = edgeSamples(scan, origins, *spec, board, scene.target);
  const LidarBoardFeatures& measured = samples.measured;
  const LidarCloud& refined = samples.refined;
  const std::vector<int>& refined_side = samples.refined_side;
  ASSERT_GT(refined.points.size(), 40u) << "the board should span ~35 scan lines";

  // True image lines of the board sides (undistorted px), outward normals.
  const auto corners = scene.target.outerCorners();
  const Eigen::Isometry3d camera_T_board = world_T_camera.inverse() * world_T_board;
  const CameraBoardFeatures truth = trueImageLines(camera, camera_T_board, scene.target);

  // Project the refined edge points through the projection core.
  ProjectionOptions options;
  const auto projected = projectCloud(refined, camera, camera_T_lidar, options);
  ASSERT_TRUE(projected.ok()) << projected.error();
  ASSERT_GT(projected->points.size(), 30u);

  const EdgeOffsets m =
      measureEdgeOffsets(image, camera, *projected, refined_side, truth, camera_T_board, corners);
  const int measured_edges = m.measured;
  const double worst_image_px = m.worst_image_px, sum_image_px = m.sum_image_px,
               worst_line_px = m.worst_line_px;
  EXPECT_LT(worst_line_px, 0.01);
  ASSERT_GT(measured_edges, 25) << "too few edge profiles measurable in the rendered image";
  // The requirement: within 1 px of the image edges. The renderer's 4x4 supersampled
  // anti-aliasing and 2-grey-level noise locate the edge to ~0.1 px, so 1 px has ample margin
  // yet catches any half-pixel convention slip combined with a projection error.
  EXPECT_LT(worst_image_px, 1.0) << "mean " << sum_image_px / measured_edges;
  EXPECT_LT(sum_image_px / measured_edges, 0.35);
  std::printf("projected edge points vs rendered edges: %d points, mean %.3f px, worst %.3f px\n",
              measured_edges, sum_image_px / measured_edges, worst_image_px);

  expectOverlayDrawn(image, scan, measured, truth, camera, camera_T_lidar, *spec);
}
