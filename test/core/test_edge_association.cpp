// One edge association (core/common/edge_association.h): the PBPC solver, the MLRE figures and
// the projected-edges overlay pair LiDAR edges with image lines the same way, so the overlay
// shows the MLRE the solver reports, also when the detectors name the edges differently.
#include <board_calib/core/common/edge_association.h>
#include <board_calib/core/projection/projection.h>
#include <board_calib/core/solvers/solvers.h>
#include <board_calib/core/transform.h>
#include "support/synthetic_views.h"

#include <gtest/gtest.h>

#include <algorithm>

namespace board_calib {
namespace {

// Both computations sum the same point-to-line distances; only the summation order differs.
constexpr double kSameFigurePx = 1e-9;

struct Scene {
  std::vector<View> original;
  std::vector<View> views;
  Eigen::Isometry3d truth;
  CameraModel camera;
};

// Synthetic views whose LiDAR names every edge one step on (edge j's points under j + 1).
Scene renamedScene() {
  std::mt19937 rng(7);
  sim::SyntheticFeatureOptions o;
  o.num_views = 12;
  Scene s;
  s.truth = sim::randomCameraTLidar(rng);
  auto scene = sim::generateSyntheticViews(o, s.truth, rng);
  EXPECT_TRUE(scene.ok()) << scene.error();
  s.original = scene->views;
  s.views = scene->views;
  for (View& v : s.views) {
    std::rotate(v.lidar.edge_points.rbegin(), v.lidar.edge_points.rbegin() + 1,
                v.lidar.edge_points.rend());
    std::rotate(v.lidar.edge_valid.rbegin(), v.lidar.edge_valid.rbegin() + 1,
                v.lidar.edge_valid.rend());
  }
  CameraIntrinsics in;
  in.width = o.image_width;
  in.height = o.image_height;
  in.fx = o.fx;
  in.fy = o.fy;
  in.cx = o.cx;
  in.cy = o.cy;
  s.camera = *CameraModel::create(in);
  return s;
}

TEST(EdgeAssociation, RenamedLidarEdgesArePairedByProjection) {
  const Scene s = renamedScene();
  for (const View& v : s.views) {
    const EdgeAssociation a = associateEdges(v.camera, v.lidar, s.truth);
    EXPECT_TRUE(a.relabelled);
    for (int j = 0; j < kNumEdges; ++j) {
      if (a.scored[j]) {
        EXPECT_EQ(a.lidar_edge[j], (j + 1) % kNumEdges) << "view " << v.id << " edge " << j;
      }
    }
  }
  // Paired by projection, the renamed views score as the originals: sub-pixel at the truth
  // (0.3 px line noise, edge points up to one 0.2 deg step inside the edge).
  const auto mlre = meanLineReprojectionErrorPx(s.views, s.truth);
  ASSERT_TRUE(mlre.has_value());
  EXPECT_LT(*mlre, 3.0);
}

TEST(EdgeAssociation, OverlayAndSolverReportTheSameMlre) {
  const Scene s = renamedScene();
  SolverOptions options;
  options.compute_covariance = false;
  const CalibrationSolution sol = calibrate(s.views, Method::kPbpc, options);
  ASSERT_TRUE(sol.success) << sol.reason;
  ASSERT_TRUE(sol.mlre_px.has_value());
  const auto figure = meanLineReprojectionErrorPx(s.views, sol.camera_T_lidar);
  ASSERT_TRUE(figure.has_value());
  EXPECT_NEAR(*sol.mlre_px, *figure, kSameFigurePx);
  // Paired after the plane stage, the renamed views solve exactly as the originals do.
  const CalibrationSolution named = calibrate(s.original, Method::kPbpc, options);
  ASSERT_TRUE(named.success) << named.reason;
  EXPECT_LT(translationErrorM(sol.camera_T_lidar, named.camera_T_lidar), 1e-9);
  EXPECT_LT(rotationErrorDeg(sol.camera_T_lidar, named.camera_T_lidar), 1e-7);
  // A slightly wrong extrinsic (0.3 deg, 1 cm): the overlay of every view scores what the MLRE
  // figure of that view says, pair for pair.
  Eigen::Isometry3d off = sol.camera_T_lidar;
  off.linear() = expSO3(Eigen::Vector3d(0.0, 0.3 * kRadPerDeg, 0.0)) * off.linear();
  off.translation() += Eigen::Vector3d(0.01, 0.0, 0.0);
  for (size_t i = 0; i < s.views.size(); ++i) {
    const View& v = s.views[i];
    const auto check = checkProjectedEdges(v.lidar, v.camera, s.camera, off, EdgeCheckOptions());
    ASSERT_TRUE(check.ok()) << check.error();
    const auto view_mlre = viewLineReprojectionErrorPx(v, off);
    ASSERT_TRUE(view_mlre.has_value());
    EXPECT_NEAR(check->mlre_px, *view_mlre, kSameFigurePx) << "view " << v.id;
    const EdgeAssociation a = associateEdges(v.camera, v.lidar, off);
    for (int j = 0; j < kNumEdges; ++j) {
      if (a.scored[j]) {
        EXPECT_EQ(check->image_edge[a.lidar_edge[j]], j) << "view " << v.id;
      }
    }
    EXPECT_EQ(sol.views[i].edges[0].lidar_edge,
              associateEdges(v.camera, v.lidar, sol.camera_T_lidar).lidar_edge[0]);
  }
}

}  // namespace
}  // namespace board_calib
