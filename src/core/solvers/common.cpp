// Names, option validation and the covariance / observability helpers of the solvers.
#include "internal.h"

#include <board_calib/core/transform.h>

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <sstream>

namespace board_calib {

namespace {
std::string lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return std::tolower(c); });
  return s;
}
}  // namespace

const char* methodName(Method method) {
  switch (method) {
    case Method::kPpc: return "ppc";
    case Method::kPbpc: return "pbpc";
    case Method::kMsgPair: return "msg";
  }
  return "unknown";
}

Expected<Method> parseMethod(const std::string& name) {
  const std::string n = lower(name);
  if (n == "ppc") return Method::kPpc;
  if (n == "pbpc") return Method::kPbpc;
  if (n == "msg" || n == "msg_pair") return Method::kMsgPair;
  return Expected<Method>::failure("unknown method '" + name + "' (expected ppc, pbpc or msg)");
}

const char* robustLossName(RobustLoss loss) {
  switch (loss) {
    case RobustLoss::kNone: return "none";
    case RobustLoss::kHuber: return "huber";
    case RobustLoss::kCauchy: return "cauchy";
    case RobustLoss::kTukey: return "tukey";
  }
  return "unknown";
}

Expected<RobustLoss> parseRobustLoss(const std::string& name) {
  const std::string n = lower(name);
  if (n == "none" || n == "") return RobustLoss::kNone;
  if (n == "huber") return RobustLoss::kHuber;
  if (n == "cauchy") return RobustLoss::kCauchy;
  if (n == "tukey") return RobustLoss::kTukey;
  return Expected<RobustLoss>::failure("unknown robust loss '" + name +
                                       "' (expected none, huber, cauchy or tukey)");
}

const char* pbpcScheduleName(PbpcSchedule schedule) {
  return schedule == PbpcSchedule::kJoint ? "joint" : "sequential";
}

Expected<PbpcSchedule> parsePbpcSchedule(const std::string& name) {
  const std::string n = lower(name);
  if (n == "joint") return PbpcSchedule::kJoint;
  if (n == "sequential" || n == "paper") return PbpcSchedule::kSequential;
  return Expected<PbpcSchedule>::failure("unknown PBPC schedule '" + name +
                                         "' (expected joint or sequential)");
}

Vector6d poseDelta(const Eigen::Isometry3d& a, const Eigen::Isometry3d& reference) {
  Vector6d d;
  const Eigen::AngleAxisd aa(a.linear() * reference.linear().transpose());
  d.head<3>() = aa.angle() * aa.axis();
  d.tail<3>() = a.translation() - reference.translation();
  return d;
}

SolverOptions realLidarSolverOptions() {
  SolverOptions o;
  o.edge_outward_shift_steps = 0.0;
  // Between no net bias (the footprint's bloom cancels the inset) and the whole half-step inset
  // (a thin beam): measured on the simulated OS1-64 (1024 columns), the result moved 19 -> 9 mm
  // from the truth over that range while its 1 sigma stayed at 6 mm; the real OS1-64 recording
  // scores best near 0.15 steps.
  o.edge_bias_range_steps = 0.5;
  o.loss = RobustLoss::kTukey;
  constexpr double kRealLossScaleM = 0.02;  // about twice a real LiDAR's range noise
  o.loss_scale_m = kRealLossScaleM;
  return o;
}

std::string SolverOptions::validate() const {
  auto positive = [](double v) { return std::isfinite(v) && v > 0.0; };
  if (!positive(loss_scale_m)) return "loss_scale_m must be > 0";
  if (max_iterations < 1) return "max_iterations must be >= 1";
  if (!positive(function_tolerance) || !positive(gradient_tolerance) ||
      !positive(parameter_tolerance))
    return "solver tolerances must be > 0";
  if (num_threads < 1) return "num_threads must be >= 1";
  if (!std::isfinite(pbpc_line_weight) || pbpc_line_weight <= 0.0)
    return "pbpc_line_weight must be > 0";
  if (!std::isfinite(plane_scale_note_threshold) || plane_scale_note_threshold < 0.0)
    return "plane_scale_note_threshold must be >= 0";
  if (!std::isfinite(lidar_horizontal_resolution_deg) || lidar_horizontal_resolution_deg < 0.0 ||
      lidar_horizontal_resolution_deg > 10.0)
    return "lidar_horizontal_resolution_deg must be in [0, 10]";
  if (!std::isfinite(edge_outward_shift_steps) || std::abs(edge_outward_shift_steps) > 2.0)
    return "edge_outward_shift_steps must be in [-2, 2]";
  if (!std::isfinite(edge_bias_range_steps) || edge_bias_range_steps < 0.0 ||
      edge_bias_range_steps > 2.0)
    return "edge_bias_range_steps must be in [0, 2]";
  if (!positive(msg_normal_sigma_deg) || !positive(msg_offset_sigma_m))
    return "msg sigmas must be > 0";
  if (!std::isfinite(min_normal_spread_deg) || min_normal_spread_deg < 0.0 ||
      min_normal_spread_deg >= 45.0)
    return "min_normal_spread_deg must be in [0, 45)";
  if (!positive(observability_max_stddev)) return "observability_max_stddev must be > 0";
  return "";
}

std::string RobustnessOptions::validate() const {
  if (trials < 1) return "trials must be >= 1";
  if (!std::isfinite(rotation_sigma_deg) || rotation_sigma_deg < 0.0)
    return "rotation_sigma_deg must be >= 0";
  if (!std::isfinite(translation_sigma_m) || translation_sigma_m < 0.0)
    return "translation_sigma_m must be >= 0";
  if (!std::isfinite(converged_rotation_deg) || converged_rotation_deg <= 0.0)
    return "converged_rotation_deg must be > 0";
  if (!std::isfinite(converged_translation_m) || converged_translation_m <= 0.0)
    return "converged_translation_m must be > 0";
  return "";
}

namespace solvers_detail {

double robustWeight(RobustLoss loss, double scale, double s) {
  const double a2 = scale * scale;
  switch (loss) {
    case RobustLoss::kNone: return 1.0;
    case RobustLoss::kHuber: return s <= a2 ? 1.0 : std::sqrt(a2 / s);
    case RobustLoss::kCauchy: return 1.0 / (1.0 + s / a2);
    case RobustLoss::kTukey: {
      if (s > a2) return 0.0;
      const double v = 1.0 - s / a2;
      return v * v;
    }
  }
  return 1.0;
}

Observability analyseObservability(const Matrix6d& covariance, bool ok, double max_weak_stddev,
                                   const std::string& frame_name) {
  Observability out;
  if (!ok || !covariance.allFinite()) {
    out.weakest_description = "unobservable: the information matrix is singular";
    return out;
  }
  Eigen::SelfAdjointEigenSolver<Matrix6d> eig(covariance);
  const auto& ev = eig.eigenvalues();  // ascending
  const double largest = std::max(ev(5), 0.0);
  const double smallest = std::max(ev(0), 0.0);
  constexpr double kTiny = 1e-30;
  out.min_eigenvalue = largest > kTiny ? 1.0 / largest : 0.0;
  out.max_eigenvalue = smallest > kTiny ? 1.0 / smallest : 0.0;
  out.condition_number =
      smallest > kTiny ? largest / smallest : std::numeric_limits<double>::infinity();
  out.weakest_direction = eig.eigenvectors().col(5);
  const Vector6d& v = out.weakest_direction;
  const double rot = v.head<3>().squaredNorm();
  const bool is_rotation = rot > 0.5;
  const Eigen::Vector3d part = is_rotation ? v.head<3>() : v.tail<3>();
  int axis = 0;
  part.cwiseAbs().maxCoeff(&axis);
  const char* axes = "xyz";
  std::ostringstream text;
  text.precision(2);
  text << std::fixed << (is_rotation ? "rotation about " : "translation along ") << frame_name
       << " " << axes[axis] << " (share " << part(axis) * part(axis)
       << " of the direction, 1 sigma ";
  if (is_rotation)
    text << std::sqrt(largest) * kDegPerRad << " deg)";
  else
    text << std::sqrt(largest) * 1000.0 << " mm)";
  out.weakest_description = text.str();
  out.well_conditioned = std::sqrt(largest) <= max_weak_stddev;
  return out;
}

Expected<Eigen::Matrix3d> alignVectors(const std::vector<Eigen::Vector3d>& a,
                                       const std::vector<Eigen::Vector3d>& b,
                                       const std::vector<double>& weights) {
  // Two independent directions fix a rotation; the third singular value may be zero.
  constexpr double kMinRelativeSecond = 1e-6;
  auto R = rotationAligning(b, a, weights, kMinRelativeSecond);
  if (!R)
    return Expected<Eigen::Matrix3d>::failure("the normals do not fix a rotation (all parallel)");
  return R;
}

double normalSpreadDeg(const std::vector<Eigen::Vector3d>& normals, int k) {
  if (normals.empty()) return 0.0;
  Eigen::Matrix3d S = Eigen::Matrix3d::Zero();
  for (const auto& n : normals) S += n * n.transpose();
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(S / static_cast<double>(normals.size()));
  // Eigenvalues ascending; descending index k maps to 2 - k. Singular value = sqrt(eigenvalue).
  const double sv = std::sqrt(std::max(eig.eigenvalues()(2 - k), 0.0));
  return std::asin(std::min(sv, 1.0)) * kDegPerRad;
}

}  // namespace solvers_detail

PoseStddev stddevFromCovariance(const Matrix6d& covariance) {
  PoseStddev s;
  for (int i = 0; i < 3; ++i) {
    s.rotation_deg(i) = std::sqrt(std::max(covariance(i, i), 0.0)) * kDegPerRad;
    s.translation_m(i) = std::sqrt(std::max(covariance(i + 3, i + 3), 0.0));
  }
  return s;
}

Matrix6d declaredScaleUncertainty(const DeclaredScaleCheck& c) {
  const double off = c.scale - 1.0;
  if (!c.checked || !c.shift.allFinite() || !(std::abs(off) > 0.1 * c.stddev))
    return Matrix6d::Zero();
  const Vector6d per_sigma = c.shift * (c.stddev / off);
  return per_sigma * per_sigma.transpose();
}

}  // namespace board_calib
