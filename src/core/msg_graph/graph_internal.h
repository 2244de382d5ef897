// Private pieces of the MSG graph shared by its translation units: per-sensor sigmas and
// observations, the pose blocks, the plane-pair error, the Graph state of the global solve and
// the stages solveMsgGraph runs (msg_graph.cpp).
#pragma once

#include "msg_costs.h"

#include <board_calib/core/common/ceres_helpers.h>
#include <board_calib/core/msg_graph/msg_graph.h>
#include <board_calib/core/transform.h>

#include <ceres/product_manifold.h>

#include <chrono>
#include <memory>
#include <set>
#include <string>
#include <vector>

namespace board_calib {
namespace multi_sensor {
namespace graph_detail {

constexpr double kUnitTolerance = 1e-3;    // |n| - 1 accepted for a plane normal
constexpr double kMinCornerDepthM = 1e-3;  // corner terms reject steps putting a corner behind
constexpr double kSqrtHalf = 0.70710678118654752;
constexpr int kMinSensors = 2;
constexpr double kRotationPerQuaternionTangent =
    2.0;  // EigenQuaternionManifold: rotation vector = 2 d

constexpr int kPoseDim = 6;  // tangent size of a pose: rotation vector, translation

using Clock = std::chrono::steady_clock;
double msSince(Clock::time_point start);

// Sigmas of one sensor in use (normal as an RMS angle in rad).
struct Sigmas {
  double normal_rad = 0.0, offset_m = 0.0, pixel_px = 0.0, edge_m = 0.0;
};

// One sensor's usable observation of one board pose.
struct Obs {
  bool active = false;
  Plane plane;
  Eigen::Vector3d point = Eigen::Vector3d::Zero();  // board point on the plane (boardPoint)
  const CameraBoardFeatures* camera = nullptr;
  const LidarBoardFeatures* lidar = nullptr;
};

struct Pose7 {
  double q[4] = {0, 0, 0, 1};
  double t[3] = {0, 0, 0};
  Eigen::Isometry3d iso() const {
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    T.linear() = Eigen::Quaterniond(q[3], q[0], q[1], q[2]).normalized().toRotationMatrix();
    T.translation() = Eigen::Vector3d(t[0], t[1], t[2]);
    return T;
  }
  void set(const Eigen::Isometry3d& T) {
    Eigen::Quaterniond qq(T.linear());
    qq.normalize();
    q[0] = qq.x();
    q[1] = qq.y();
    q[2] = qq.z();
    q[3] = qq.w();
    for (int i = 0; i < 3; ++i) t[i] = T.translation()(i);
  }
};

// A board pose as one block (quaternion x y z w, translation) so board poses form an
// independent set for the Schur elimination.
struct BoardPose {
  double x[7] = {0, 0, 0, 1, 0, 0, 0};
  Eigen::Isometry3d iso() const {
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    T.linear() = Eigen::Quaterniond(x[3], x[0], x[1], x[2]).normalized().toRotationMatrix();
    T.translation() = Eigen::Vector3d(x[4], x[5], x[6]);
    return T;
  }
  void set(const Eigen::Isometry3d& T) {
    Eigen::Quaterniond q(T.linear());
    q.normalize();
    x[0] = q.x();
    x[1] = q.y();
    x[2] = q.z();
    x[3] = q.w();
    for (int i = 0; i < 3; ++i) x[4 + i] = T.translation()(i);
  }
};
using BoardManifold =
    ceres::ProductManifold<ceres::EigenQuaternionManifold, ceres::EuclideanManifold<3>>;

// Pair sigmas: normal per component (the RMS angle spreads over two components), offset.
double pairNormalSigmaComponent(const Sigmas& a, const Sigmas& b);
double pairOffsetSigma(const Sigmas& a, const Sigmas& b);

// Whitened magnitude (about 1 for an inlier) of a plane pair under a relative pose a_T_b.
struct PlanePairError {
  double angle_rad = 0.0, offset_m = 0.0, whitened = 0.0;
};
PlanePairError planePairError(const Obs& oa, const Obs& ob, const Eigen::Isometry3d& a_T_b,
                              const Sigmas& sa, const Sigmas& sb);

// The state of the global solve (graph_problem.cpp).
class Graph {
 public:
  Graph(const MsgProblem& problem, const MsgGraphOptions& options, std::vector<Sigmas> sigmas,
        std::vector<std::vector<Obs>> obs)
      : problem_(problem),
        options_(options),
        sigmas_(std::move(sigmas)),
        obs_(std::move(obs)),
        n_(static_cast<int>(problem.sensors.size())),
        poses_(n_),
        boards_(problem.poses.size()) {}

  std::vector<Pose7>& poses() { return poses_; }
  std::vector<std::vector<Obs>>& observations() { return obs_; }

  // Board poses with corner terms: >= 2 active cameras with enough pattern points.
  std::vector<int> cornerCameras(size_t p) const;
  // Image line matched to each LiDAR edge of (camera c, LiDAR l) at board pose p; -1 when
  // unmatched.
  std::array<int, kNumEdges> matchedLines(size_t p, int c, int l) const;

  using StageResult = ceres_common::SolveOutcome;
  // Builds and solves one stage. `planes_only`: squared loss, no corner or line terms.
  StageResult solve(bool planes_only, int reference, bool keep_problem);
  ceres::Problem* keptProblem() { return problem_kept_.get(); }

  // Whitened per-term magnitudes of each active observation, for rejection and statistics.
  // Fills `entries[p][s]` with one value per partner term (and one for the corners).
  void observationErrors(std::vector<std::vector<std::vector<double>>>* entries,
                         GraphResiduals* stats);

 private:
  static Eigen::Vector3d lineNormal(const CameraBoardFeatures& cam, int j);
  void addPlaneTerms(size_t p, const std::set<int>& corner_set, RobustLoss loss,
                     ceres::Problem* problem);
  void addCornerTerms(size_t p, const std::vector<int>& cams, RobustLoss loss,
                      ceres::Problem* problem);
  void addLineTerms(size_t p, ceres::Problem* problem, RobustLoss loss, double scale);

  const MsgProblem& problem_;
  const MsgGraphOptions& options_;
  std::vector<Sigmas> sigmas_;
  std::vector<std::vector<Obs>> obs_;  // [pose][sensor]
  int n_;
  std::vector<Pose7> poses_;
  std::vector<BoardPose> boards_;
  std::unique_ptr<ceres::Problem> problem_kept_;
};

// --- Stages of solveMsgGraph (pairwise_links.cpp unless noted) ---

// The problem's structure; empty when usable.
std::string checkProblem(const MsgProblem& problem,
                         const std::optional<std::vector<Eigen::Isometry3d>>& initial);
// Sigmas of a sensor: its spec, else the options' default for its kind.
Sigmas resolveSigmas(const SensorSpec& spec, const MsgGraphOptions& o);
// Usable observations [pose][sensor]; a note counts the skipped ones.
std::vector<std::vector<Obs>> collectObservations(const MsgProblem& problem,
                                                  std::vector<std::string>* notes);
// Pairwise links of every sensor pair (twice when the sensor noise is estimated: the second
// pass gates with it); `sigmas` receives the estimates.
void solveLinks(const MsgProblem& problem, const MsgGraphOptions& options,
                const std::vector<std::vector<Obs>>& obs, std::vector<Sigmas>* sigmas,
                MsgSolution* sol);
// Initial poses along a maximum spanning tree of the links from the reference; false (and
// sol->reason) when the graph is disconnected.
bool spanningTreeInit(const MsgProblem& problem, const MsgGraphOptions& options, MsgSolution* sol,
                      std::vector<Eigen::Isometry3d>* init);
// Loop consistency of the pairwise estimates: every triangle.
void loopErrors(int n, MsgSolution* sol);

// graph_results.cpp: the sensors' estimates (false and sol->reason when a sensor keeps too few
// board poses), their joint covariance, the camera <- LiDAR pairs, links against the graph.
bool fillSensors(const MsgProblem& problem, const MsgGraphOptions& options, Graph& graph,
                 const std::vector<Sigmas>& sigmas, const std::vector<Eigen::Isometry3d>& init,
                 MsgSolution* sol);
void poseCovariance(const MsgGraphOptions& options, Graph& graph, MsgSolution* sol);
void pairEstimates(MsgSolution* sol);
void finalNotes(const MsgProblem& problem, const MsgGraphOptions& options,
                const std::vector<Sigmas>& sigmas, MsgSolution* sol);
Matrix6d relativeCovarianceOf(const MsgSolution& sol, int a, int b);

}  // namespace graph_detail
}  // namespace multi_sensor
}  // namespace board_calib
