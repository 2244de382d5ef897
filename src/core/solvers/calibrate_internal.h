// Private pieces of PPC-Cal and PBPC-Cal shared by their translation units: the prepared views
// and their checks (prepared_views.cpp), the cluster solves (cluster_solve.cpp) and the
// orchestration (calibrate.cpp).
#pragma once

#include <board_calib/core/common/ceres_helpers.h>

#include <board_calib/core/solvers/solvers.h>
#include <board_calib/core/transform.h>

#include <cmath>
#include <string>
#include <vector>

namespace board_calib {
namespace calibrate_detail {

constexpr int kMinEdgePoints = 2;           // a line term needs two points to constrain anything
constexpr int kPlaneErrorRounds = 3;        // PPC: re-estimations of the camera plane error
constexpr int kMaxReassociationRounds = 3;  // PBPC: re-pair-and-solve rounds after the final solve

// A set of points that must lie on one plane n . x = s d in the camera frame: one view's board
// points (camera plane) or one edge's points (back-projected plane, d = 0). Points share the
// weight (1/p_i or line_weight/q_ij) and the plane's measurement error.
struct Cluster {
  Eigen::Vector3d normal;
  double offset = 0.0;
  double weight = 1.0;
  bool scaled = false;  // offset multiplied by the global factor s
  bool plane = false;   // a camera plane (not a back-projected line plane)
  int id = 0;
  const Points3* points = nullptr;
};

struct PreparedView {
  int index = 0;
  int id = 0;
  std::string reason;
  bool plane_ok = false;
  Eigen::Vector3d cam_normal = Eigen::Vector3d::UnitZ();
  double cam_offset = 0.0;
  bool lidar_plane_ok = false;
  Eigen::Vector3d lidar_normal = Eigen::Vector3d::UnitZ();
  double lidar_offset = 0.0;
  const Points3* board_points = nullptr;
  std::array<bool, kNumEdges> image_edge_ok{};
  std::array<Eigen::Vector3d, kNumEdges> backprojected_normal;  // unit K^T l
  std::array<bool, kNumEdges> lidar_edge_ok{};
  std::array<Points3, kNumEdges> lidar_edges;            // possibly shifted outward
  std::array<int, kNumEdges> association{{0, 1, 2, 3}};  // image edge -> LiDAR edge
  bool used = false;

  int lineCount() const {
    int n = 0;
    for (int j = 0; j < kNumEdges; ++j)
      if (image_edge_ok[j] && association[j] >= 0 && lidar_edge_ok[association[j]]) ++n;
    return n;
  }
};

struct Pose {
  double q[4] = {0, 0, 0, 1};  // x y z w
  double t[3] = {0, 0, 0};
  double s = 1.0;

  static Pose from(const Eigen::Isometry3d& T) {
    Pose p;
    Eigen::Quaterniond q(T.linear());
    q.normalize();
    Eigen::Map<Eigen::Quaterniond>(p.q) = q;
    Eigen::Map<Eigen::Vector3d>(p.t) = T.translation();
    return p;
  }
  Eigen::Isometry3d isometry() const {
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    T.linear() = Eigen::Map<const Eigen::Quaterniond>(q).normalized().toRotationMatrix();
    T.translation() = Eigen::Map<const Eigen::Vector3d>(t);
    return T;
  }
};

using SolveOutcome = ceres_common::SolveOutcome;

// Per-view error of the camera plane (PPC): variance of its offset (m^2) and of its tilt about
// each in-plane axis (rad^2), shared by all points of the view, at the reference distance and
// scaled by (distance / reference)^distance_power (0: the same for every view; 4: as a PnP's
// error, which grows with the square of the distance). Disabled: the paper's model (every
// point an independent residual, weight 1/p_i).
struct PlaneErrorModel {
  bool enabled = false;
  double offset_var = 0.0;
  double tilt_var = 0.0;
  double distance_power = 0.0;
  double reference_distance_m = 1.0;

  double factor(const Eigen::Vector3d& point_in_camera) const {
    return distance_power == 0.0
               ? 1.0
               : std::pow(point_in_camera.norm() / reference_distance_m, distance_power);
  }
};

// --- prepared_views.cpp ---
/// Every view checked and prepared (LiDAR edges shifted outward by the options' fraction of the
/// horizontal step, given or estimated; `step_used` receives it).
std::vector<PreparedView> prepareAll(const std::vector<View>& views, Method method,
                                     const SolverOptions& options, double* step_used = nullptr);
/// Degeneracy checks; empty when the views can be solved. `used` receives the usable views.
std::string checkGeometry(const std::vector<PreparedView>& prepared, Method method,
                          const SolverOptions& options, int* used);
/// Closed-form camera_T_lidar from the prepared views.
Expected<Eigen::Isometry3d> closedForm(const std::vector<PreparedView>& prepared, Method method,
                                       const SolverOptions& options);
/// The residual clusters of the used views: camera planes and/or back-projected line planes.
std::vector<Cluster> buildClusters(const std::vector<PreparedView>& views, bool planes, bool lines,
                                   bool scaled, double line_weight);
/// Re-assigns LiDAR edges to image lines by projection; true if any view changed.
bool reassociateEdges(const std::vector<View>& views, std::vector<PreparedView>* prepared,
                      const Eigen::Isometry3d& T, std::vector<std::string>* notes);
/// MLRE, plane and line RMS and the per-view residuals of sol->camera_T_lidar.
void fillResidualFigures(const std::vector<View>& views, const std::vector<PreparedView>& prepared,
                         Method method, CalibrationSolution* sol);

// --- cluster_solve.cpp ---
/// A solve with the requested loss (squared loss in closed form, robust losses by IRLS).
SolveOutcome solveStage(const std::vector<Cluster>& clusters, bool estimate_scale,
                        const SolverOptions& options, bool warm, Pose* pose,
                        const PlaneErrorModel& model = PlaneErrorModel());
/// The more likely of a distance-independent camera plane error and one growing as a PnP's.
PlaneErrorModel choosePlaneErrorModel(const std::vector<Cluster>& clusters, const Pose& pose,
                                      const SolverOptions& options);
/// Cluster-robust covariance of the final problem at `pose` (and the plane scale's variance
/// when it is estimated and `scale_variance` is given).
bool finalCovariance(const std::vector<Cluster>& clusters, bool estimate_scale,
                     const PlaneErrorModel& model, const SolverOptions& options, Pose pose,
                     Matrix6d* covariance, double* scale_variance = nullptr);

}  // namespace calibrate_detail
}  // namespace board_calib
