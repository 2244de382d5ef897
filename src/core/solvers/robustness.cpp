// Robustness to random initialisation: Ceres started from random guesses, as in the paper.
#include "internal.h"

#include <board_calib/core/transform.h>

#include <cmath>

namespace board_calib {

RobustnessReport evaluateRandomInitialisation(const std::vector<View>& views, Method method,
                                              const SolverOptions& options,
                                              const RobustnessOptions& robustness,
                                              const std::optional<Eigen::Isometry3d>& reference) {
  RobustnessReport report;
  const std::string invalid = robustness.validate();
  if (!invalid.empty()) {
    report.reason = "invalid robustness options: " + invalid;
    return report;
  }
  SolverOptions trial_options = options;
  trial_options.compute_covariance = false;  // not needed per trial
  if (reference) {
    report.reference = *reference;
  } else {
    const CalibrationSolution base = calibrate(views, method, trial_options);
    if (!base.success) {
      report.reason = "reference solve failed: " + base.reason;
      return report;
    }
    report.reference = base.camera_T_lidar;
  }

  std::mt19937 rng(robustness.seed);
  const Eigen::Isometry3d centre =
      robustness.around_reference ? report.reference : Eigen::Isometry3d::Identity();
  std::vector<Eigen::Isometry3d> converged;
  double time_sum = 0.0;
  for (int i = 0; i < robustness.trials; ++i) {
    const Eigen::Isometry3d guess = perturb(centre, robustness.rotation_sigma_deg * kRadPerDeg,
                                            robustness.translation_sigma_m, rng);
    const CalibrationSolution sol = calibrate(views, method, trial_options, guess);
    time_sum += sol.solve_time_ms;
    const double rot = sol.success ? rotationErrorDeg(sol.camera_T_lidar, report.reference) : 180.0;
    const double trans = sol.success ? translationErrorM(sol.camera_T_lidar, report.reference)
                                     : std::numeric_limits<double>::infinity();
    report.rotation_error_deg.push_back(rot);
    report.translation_error_m.push_back(trans);
    if (sol.success && rot <= robustness.converged_rotation_deg &&
        trans <= robustness.converged_translation_m)
      converged.push_back(sol.camera_T_lidar);
  }
  report.trials = robustness.trials;
  report.converged = static_cast<int>(converged.size());
  report.convergence_rate = static_cast<double>(report.converged) / report.trials;
  report.mean_solve_time_ms = time_sum / report.trials;

  if (!converged.empty()) {
    // Mean of the converged results (rotation vectors about the reference are small here).
    Eigen::Vector3d mean_rv = Eigen::Vector3d::Zero(), mean_t = Eigen::Vector3d::Zero();
    for (const auto& T : converged) {
      mean_rv += logSO3(T.linear() * report.reference.linear().transpose());
      mean_t += T.translation();
    }
    mean_rv /= converged.size();
    mean_t /= converged.size();
    const Eigen::Matrix3d mean_R = expSO3(mean_rv) * report.reference.linear();
    double rot_sq = 0.0, trans_sq = 0.0;
    for (const auto& T : converged) {
      const double rot = logSO3(T.linear() * mean_R.transpose()).norm() * kDegPerRad;
      const double trans = (T.translation() - mean_t).norm();
      report.rotation_spread_max_deg = std::max(report.rotation_spread_max_deg, rot);
      report.translation_spread_max_m = std::max(report.translation_spread_max_m, trans);
      rot_sq += rot * rot;
      trans_sq += trans * trans;
    }
    report.rotation_spread_rms_deg = std::sqrt(rot_sq / converged.size());
    report.translation_spread_rms_m = std::sqrt(trans_sq / converged.size());
  }
  report.success = true;
  return report;
}

}  // namespace board_calib
