// The verdict on a calibration: good, doubtful or failed, with the reason in one line, the
// details, and the views to look at.
//
// It rests on three tests, none of which trusts the solver's own cost:
//  * residuals against the noise model: the LiDAR board points' distance to the camera plane
//    against what the two sensors' own noise explains (the LiDAR plane fit, the PnP plane's error
//    growing with distance), and the edge error (MLRE) against the board's size in the image;
//  * cross-validation: each view (or fold) left out, solved on the rest, and predicted; the
//    spread of those solves is an empirical covariance (grouped jackknife), and the reported 1
//    sigma never falls below it nor below the model's, scaled by how much the residuals exceed
//    the noise model;
//  * agreement between methods, where several ran, measured in their combined sigmas.
#pragma once

#include <board_calib/core/solvers/solvers.h>
#include <board_calib/core/target.h>
#include <board_calib/core/verdict/consistency.h>

#include <functional>
#include <optional>
#include <string>
#include <vector>

namespace board_calib {

enum class Verdict { kGood, kDoubtful, kFailed };
/// "good", "doubtful", "failed".
const char* verdictName(Verdict verdict);

struct VerdictOptions {
  int min_views = 3;                     ///< fewer: failed
  int min_views_to_cross_validate = 5;   ///< fewer: at best doubtful
  int max_leave_one_out_views = 40;      ///< more views: that many folds instead of one view each
  double doubtful_residual_ratio = 3.0;  ///< plane residual RMS / noise model
  double failed_residual_ratio = 10.0;
  double failed_edge_fraction =
      0.1;  ///< MLRE above this fraction of the board's size in the image: failed
  double doubtful_heldout_ratio = 2.0;  ///< held-out error / in-sample error
  double outlier_factor = 5.0;          ///< a view's or edge's error this many times the median ...
  double outlier_min_excess_px = 5.0;   ///< ... and this far above it is named
  double max_outlier_edge_fraction =
      0.1;  ///< more named edges than this fraction (and more than 1): doubtful
  double doubtful_inconsistent_fraction = 0.2;  ///< views dropped by the consistency check
  double failed_inconsistent_fraction =
      0.4;  ///< at this or more: the consensus is barely a majority
  double doubtful_stddev_translation_m = 0.02;  ///< 1 sigma (inflated) beyond this: doubtful
  double doubtful_stddev_rotation_deg = 0.3;
  double failed_stddev_translation_m = 0.10;  ///< beyond this: failed, the data do not determine it
  double failed_stddev_rotation_deg = 1.0;
  double method_disagreement_sigmas = 3.0;  ///< other methods further than this: doubtful
  double min_pixel_sigma_px = 0.3;          ///< px, floor of a camera board pose's pixel noise
  /// PPC: the LiDAR's board scale this many of its sigmas from the declared size: the move of
  /// the result with it enters the 1 sigma; and beyond the tolerance of a declared size (a
  /// printed pattern, a ruler), where it moves the result beyond its own 1 sigma: doubtful.
  double declared_scale_sigmas = 3.0;
  /// PBPC: the LiDAR edges' residuals fitted with a radial lens term (camera_info's distortion
  /// not matching the images). Beyond lens_bias_sigmas of its noise the result is solved again
  /// without it and the move enters the 1 sigma; beyond lens_residual_sigmas, moving the result
  /// beyond its 1 sigma, it is named: doubtful. The noise is a sandwich over 15-30 views, itself
  /// uncertain by a fifth or more, hence more than 3. Measured: under 1 sigma with the right
  /// distortion (simulated), under 4 on the real recordings, 8-12.6 sigma with half or none of
  /// the simulated lens's distortion given.
  double lens_bias_sigmas = 4.0;
  double lens_residual_sigmas = 5.0;
  /// Checkerboard and AprilTag corners: the same radial term fitted to their residuals from the
  /// board pose is named beyond lens_bias_sigmas when it carries this share of the residual
  /// (0 % on the real checkerboard recording, 79 % with the distortion left out, simulated).
  double lens_min_explained = 0.25;
  double declared_size_tolerance = 0.005;
  std::string validate() const;
};

struct CrossValidation {
  bool ran = false;
  std::string why_not;
  int solves = 0, failed_solves = 0;
  Matrix6d covariance = Matrix6d::Zero();  ///< grouped jackknife, solvers.h convention
  double max_rotation_dev_deg = 0.0;       ///< largest left-out solve's distance to the full solve
  double max_translation_dev_m = 0.0;
  std::optional<double> heldout_mlre_px;  ///< mean over the left-out views' edges
  double heldout_plane_ratio = 0.0;       ///< left-out plane residual / noise model
  std::vector<std::optional<double>> view_heldout_mlre_px;  ///< per input view
  std::vector<double> view_heldout_plane_ratio;  ///< per input view (0 when not predicted)
  /// Grouped-jackknife 1 sigma of the declared-size scale over the folds (0: not measured).
  double declared_scale_stddev = 0.0;
};

struct VerdictReport {
  Verdict verdict = Verdict::kFailed;
  std::string reason;                   ///< one line
  std::vector<std::string> details;     ///< every finding, in words
  std::vector<int> views_to_check;      ///< view ids named in the details
  double plane_residual_ratio = 0.0;    ///< in-sample plane residual / noise model
  std::optional<double> board_size_px;  ///< median board size in the image
  CrossValidation cross_validation;
  Matrix6d covariance = Matrix6d::Zero();  ///< reported: the model's, inflated (see the header)
  PoseStddev stddev;
  double stddev_inflation = 1.0;  ///< factor on the model's 1 sigma
  /// A named depth scale the LiDAR disputes (a declared size or a focal length off), in words;
  /// empty when none. The other methods of a run are judged with it (judgeMethodAgreement).
  std::string scale_finding;
};

/// Plane residual RMS of every view against its noise model (1 = as expected). `views` are the
/// views the solution used, in the solution's order.
double planeResidualRatio(const std::vector<View>& views, const Target& target,
                          const Eigen::Isometry3d& camera_T_lidar, double plane_scale,
                          const VerdictOptions& options, std::vector<double>* per_view = nullptr);

/// Judges one solution on `views` (the consistent views it was solved on); `consistency` is the
/// check they passed (inconsistent views count against the verdict); `solve` re-solves a subset
/// for the cross-validation (the same method, options and start as the solution).
VerdictReport judgeSolution(
    const CalibrationSolution& solution, const std::vector<View>& views, const Target& target,
    const ConsistencyReport& consistency,
    const std::function<CalibrationSolution(const std::vector<View>&)>& solve,
    const VerdictOptions& options = {});

/// Adds the agreement between methods to each verdict (only where both solutions are usable).
void judgeMethodAgreement(const std::vector<CalibrationSolution>& solutions,
                          std::vector<VerdictReport>* verdicts, const VerdictOptions& options = {});

/// The method to report: not failed, good before doubtful, then the lowest held-out error
/// (edge MLRE when every candidate has it, else the plane ratio). -1 when all failed. `why`
/// says so in words.
int chooseMethod(const std::vector<CalibrationSolution>& solutions,
                 const std::vector<VerdictReport>& verdicts, std::string* why);

}  // namespace board_calib
