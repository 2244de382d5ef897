// Consistency of the views before any solve, without an extrinsic.
//
// Every good view obeys the same rigid motion: the camera's board normal is R times the LiDAR's,
// and the plane offsets differ by the camera normal times t (d_c = d_l + n_c . t, up to a global
// factor on d_c when the declared board size is off). A view whose board was taken from another
// object, whose camera plane came from the wrong region, or whose two sensors saw a moving board
// breaks that. A consensus over view triples (RANSAC: R by Kabsch on the normals, t from the
// offsets) finds the views that agree; tolerances follow the residuals' robust spread, growing
// with the distance as a PnP plane's error does (normal ~ D, offset ~ D^2), never below a
// floor. Then the LiDAR board points, mapped by the consensus, must land on the camera's board.
// The consensus pose is also the robust start of the solvers.
#pragma once

#include <board_calib/core/features.h>
#include <board_calib/core/target.h>

#include <string>
#include <vector>

namespace board_calib {

struct ConsistencyOptions {
  double inlier_sigmas = 4.0;  ///< tolerance in robust sigmas of the consensus residuals
  double min_normal_tolerance_deg =
      1.0;  ///< deg, floor of the normal tolerance (at the median distance)
  double min_offset_tolerance_m =
      0.02;  ///< m, floor of the offset tolerance (at the median distance)
  double max_normal_tolerance_deg = 6.0;  ///< deg, ceiling: beyond this a view is never consistent
  double max_offset_tolerance_m = 0.3;    ///< m, ceiling
  double first_normal_tolerance_deg =
      3.0;  ///< deg, tolerance of the first consensus (before any spread is known)
  double first_offset_tolerance_m = 0.10;  ///< m
  double min_sample_spread_deg = 10.0;  ///< a sample's three camera normals must span at least this
  double on_board_margin_m = 0.10;      ///< m, margin around the board for the LiDAR points
  double min_on_board_fraction = 0.6;   ///< LiDAR board points that must land on the camera's board
  int max_samples = 4000;               ///< triples tried (all when fewer exist)
  unsigned seed = 1;
  std::string validate() const;
};

struct ViewConsistency {
  int view_id = 0;
  bool usable = false;  ///< both sensors found the board with finite planes
  bool consistent = false;
  double normal_residual_deg = 0.0;  ///< angle between n_c and R n_l under the consensus
  double offset_residual_m = 0.0;    ///< |s d_c - d_l - n_c . t|
  double on_board_fraction = 0.0;    ///< LiDAR board points on the camera's board
  std::string reason;                ///< why it is inconsistent, in words
};

struct ConsistencyReport {
  bool ok = false;         ///< a consensus of at least 3 views exists
  bool checkable = false;  ///< more views than the minimal 3, so the consensus was tested
  std::string reason;      ///< why there is no consensus
  Eigen::Isometry3d camera_T_lidar = Eigen::Isometry3d::Identity();  ///< the consensus pose
  double plane_scale = 1.0;           ///< factor on the camera plane offsets (board size off)
  double normal_tolerance_deg = 0.0;  ///< at the median distance
  double offset_tolerance_m = 0.0;    ///< at the median distance
  int consistent_views = 0;
  std::vector<ViewConsistency> views;        ///< in input order
  std::vector<int> inconsistentIds() const;  ///< usable views the consensus left out
};

ConsistencyReport checkViewConsistency(const std::vector<View>& views, const Target& target,
                                       const ConsistencyOptions& options = {});

/// The views the report found consistent, in input order.
std::vector<View> consistentViews(const std::vector<View>& views, const ConsistencyReport& report);

}  // namespace board_calib
