#include <board_calib/core/common/format.h>
#include <board_calib/core/common/statistics.h>
#include <board_calib/core/report/report.h>
#include <board_calib/core/transform.h>

#include <algorithm>
#include <cmath>
#include <iomanip>
#include <sstream>

namespace board_calib {
namespace {

constexpr double kSizeNoteThreshold = 0.02;  // relative size difference worth reporting
// Relative size difference a verdict's reason blames on the target file: past what LiDAR edge
// bloom or erosion gives (rs16_plain's 0.6 m side reads +5.3 %), as a wrong or swapped size does.
constexpr double kSizeDoubtThreshold = 0.10;

// The LiDAR-measured board size per side (median over views with a full outline). The detector
// pairs its two measured sides with the declared width and height (measured_size_m.x() is the
// side matched to the width), so a rectangular board is compared side by side.
struct MeasuredSize {
  size_t views = 0;
  double width = 0, height = 0;
  double width_off = 0, height_off = 0;  // relative to the declared size
  bool off() const {
    return std::abs(width_off) > kSizeNoteThreshold || std::abs(height_off) > kSizeNoteThreshold;
  }
  bool larger() const {
    return (std::abs(width_off) > kSizeNoteThreshold ? width_off : height_off) > 0;
  }
};

MeasuredSize lidarMeasuredSize(const std::vector<View>& views, const Target& target) {
  MeasuredSize m;
  std::vector<double> widths, heights;
  for (const auto& v : views)
    if (v.lidar.allEdgesValid() && v.lidar.measured_size_m.minCoeff() > 0) {
      widths.push_back(v.lidar.measured_size_m.x());
      heights.push_back(v.lidar.measured_size_m.y());
    }
  if (widths.empty() || !(target.width > 0) || !(target.height > 0)) return m;
  m.views = widths.size();
  m.width = medianOf(widths);
  m.height = medianOf(heights);
  m.width_off = m.width / target.width - 1.0;
  m.height_off = m.height / target.height - 1.0;
  return m;
}

std::string percent(double r) {
  return std::string(r > 0 ? "+" : "") + formatFixed(r * 100, 1) + " %";
}

}  // namespace

std::vector<std::string> consistencyNotes(const std::vector<View>& views, const Target& target,
                                          const CalibrationSolution& solution) {
  std::vector<std::string> notes;
  const MeasuredSize m = lidarMeasuredSize(views, target);
  if (m.off()) {
    std::vector<std::string> off;
    if (std::abs(m.width_off) > kSizeNoteThreshold) off.push_back("width " + percent(m.width_off));
    if (std::abs(m.height_off) > kSizeNoteThreshold)
      off.push_back("height " + percent(m.height_off));
    notes.push_back(
        "board size inconsistency: the LiDAR measures " + formatFixed(m.width, 3) + " x " +
        formatFixed(m.height, 3) + " m (median of " + std::to_string(m.views) +
        " views), the target declares " + formatFixed(target.width, 3) + " x " +
        formatFixed(target.height, 3) + " m (" + off.front() +
        (off.size() > 1 ? ", " + off.back() : "") + "): " +
        (m.larger() ? "either the board is larger than declared or the LiDAR's edge returns bloom"
                    : "either the board is smaller than declared or the LiDAR's edge returns are "
                      "eroded") +
        "; camera planes from the declared size are then biased in depth");
  }
  if (!solution.success) return notes;
  // Mean signed offset and RMS of the LiDAR board points from the camera planes, against the
  // declared-size planes and, when the solve estimated a plane scale, against the scaled planes
  // it actually used (so a note never calls a bias compensated and then quotes it raw).
  const double scale = solution.plane_scale;
  double sum_raw = 0, sum_scaled = 0, sq_scaled = 0;
  size_t n = 0;
  for (const auto& v : views) {
    if (!v.lidar.found || !v.camera.found) continue;
    for (const auto& p : v.lidar.board_points) {
      const Eigen::Vector3d q = solution.camera_T_lidar * p;
      const double raw = v.camera.plane.signedDistance(q);
      const double scaled = v.camera.plane.normal.dot(q) - scale * v.camera.plane.offset;
      sum_raw += raw;
      sum_scaled += scaled;
      sq_scaled += scaled * scaled;
      ++n;
    }
  }
  constexpr double kOffsetNote = 0.02;  // m
  const bool scaled = std::abs(scale - 1.0) > kSizeNoteThreshold;
  if (scaled) {
    std::string note = "camera board planes fit the LiDAR best with their distances scaled by " +
                       formatFixed(scale, 3) + ": the declared board size is likely off by " +
                       formatFixed((scale - 1) * 100, 1) +
                       " % (check target.yaml). The solve estimated this scale and used it";
    if (n > 0)
      note += ": against the scaled planes the LiDAR board points lie " +
              formatFixed(std::abs(sum_scaled / n) * 100, 1) + " cm " +
              (sum_scaled > 0 ? "behind" : "in front of") + " them on average (RMS " +
              formatFixed(std::sqrt(sq_scaled / n) * 1e3, 1) +
              " mm); the plane RMS of the summary is against the " + "declared-size planes (" +
              formatFixed(std::abs(sum_raw / n) * 100, 1) + " cm mean offset)";
    notes.push_back(note);
  } else if (n > 0 && std::abs(sum_raw / n) > kOffsetNote) {
    notes.push_back(
        "LiDAR board points lie on average " + formatFixed(std::abs(sum_raw / n) * 100, 1) +
        " cm " + (sum_raw > 0 ? "behind" : "in front of") +
        " the camera's board plane: the camera plane depth (from the declared board size) and the "
        "LiDAR disagree");
  }
  return notes;
}

std::string declaredSizeDoubt(const std::vector<View>& views, const Target& target,
                              const CalibrationSolution& solution) {
  const MeasuredSize m = lidarMeasuredSize(views, target);
  if (std::max(std::abs(m.width_off), std::abs(m.height_off)) > kSizeDoubtThreshold)
    return "the LiDAR measures the board " + formatFixed(m.width, 2) + " x " +
           formatFixed(m.height, 2) + " m, the target declares " + formatFixed(target.width, 2) +
           " x " + formatFixed(target.height, 2) + " m: check the target file";
  const double scale = solution.plane_scale;
  if (solution.success && std::isfinite(scale) && std::abs(scale - 1.0) > kSizeDoubtThreshold)
    return "the camera planes fit the LiDAR only scaled by " + formatFixed(scale, 3) +
           ", as if the board were " + formatFixed(std::abs(scale - 1.0) * 100, 1) + " % " +
           (scale > 1 ? "larger" : "smaller") + " than the target declares: check the target file";
  return "";
}

ResultFile makeResultFile(const CalibrationSolution& s, const std::vector<View>& views,
                          const Target& target, const std::string& camera_frame,
                          const std::string& lidar_frame) {
  ResultFile r;
  r.method = methodName(s.method);
  r.camera_frame = camera_frame;
  r.lidar_frame = lidar_frame;
  r.camera_T_lidar = s.camera_T_lidar;
  r.views_used = s.views_used;
  r.mlre_px = s.mlre_px;
  r.stddev = s.stddev;
  r.quality["plane_rms_mm"] = s.plane_rms_mm;
  if (s.line_rms_mm > 0) r.quality["line_rms_mm"] = s.line_rms_mm;
  r.quality["final_cost"] = s.final_cost;
  r.quality["iterations"] = s.iterations;
  r.quality["plane_scale"] = s.plane_scale;
  r.quality["information_min_eigenvalue"] = s.observability.min_eigenvalue;
  r.quality["information_condition"] = s.observability.condition_number;
  r.quality["solve_time_ms"] = s.solve_time_ms;
  r.notes = s.notes;
  for (const auto& n : consistencyNotes(views, target, s))
    if (std::find(r.notes.begin(), r.notes.end(), n) == r.notes.end()) r.notes.push_back(n);
  if (!s.observability.well_conditioned && !s.observability.weakest_description.empty())
    r.notes.push_back("weakly constrained: " + s.observability.weakest_description +
                      "; add views that vary it (tilt the board more, change distance)");
  return r;
}

std::string solutionSummary(const CalibrationSolution& s, const PoseStddev* judged) {
  std::ostringstream o;
  o << "method " << methodName(s.method) << ": ";
  if (!s.success) {
    o << "FAILED: " << s.reason << "\n";
    return o.str();
  }
  const Eigen::Vector3d t = s.camera_T_lidar.translation();
  const Eigen::Vector4d q = quaternionXyzw(s.camera_T_lidar);
  const Eigen::Vector3d rpy = rollPitchYaw(s.camera_T_lidar.rotation()) * kDegPerRad;
  o << s.views_used << " views, " << s.iterations << " iterations, "
    << formatFixed(s.solve_time_ms, 1) << " ms\n";
  o << "  camera_T_lidar translation [m]   " << formatFixed(t.x(), 4) << " "
    << formatFixed(t.y(), 4) << " " << formatFixed(t.z(), 4) << "\n";
  o << "  camera_T_lidar rotation xyzw     " << formatFixed(q[0], 5) << " " << formatFixed(q[1], 5)
    << " " << formatFixed(q[2], 5) << " " << formatFixed(q[3], 5) << "  (rpy deg "
    << formatFixed(rpy.x(), 2) << " " << formatFixed(rpy.y(), 2) << " " << formatFixed(rpy.z(), 2)
    << ")\n";
  if (s.mlre_px)
    o << "  MLRE                             " << formatFixed(*s.mlre_px, 2)
      << " px  (mean distance of LiDAR edge points to the image edge lines)\n";
  o << "  plane RMS                        " << formatFixed(s.plane_rms_mm, 1)
    << " mm  (LiDAR board points to the camera's board plane"
    << (std::abs(s.plane_scale - 1.0) > kSizeNoteThreshold
            ? " from the declared size, before the plane scale)\n"
            : ")\n");
  const PoseStddev& sd = judged ? *judged : s.stddev;
  auto triple = [](const Eigen::Vector3d& v, double scale, int digits) {
    return formatFixed(v.x() * scale, digits) + " " + formatFixed(v.y() * scale, digits) + " " +
           formatFixed(v.z() * scale, digits);
  };
  // The verdict grows the solver's 1 sigma (residuals beyond the noise model, left-out views,
  // LiDAR edge bias): the user reads the grown one, as in the result file.
  const bool grown = judged && !(judged->translation_m.isApprox(s.stddev.translation_m) &&
                                 judged->rotation_deg.isApprox(s.stddev.rotation_deg));
  o << "  1 sigma translation [mm]         " << triple(sd.translation_m, 1e3, 2)
    << (grown ? "  (solver alone " + triple(s.stddev.translation_m, 1e3, 2) + ")" : "") << "\n";
  o << "  1 sigma rotation [deg]           " << triple(sd.rotation_deg, 1.0, 3)
    << (grown ? "  (solver alone " + triple(s.stddev.rotation_deg, 1.0, 3) + ")" : "") << "\n";
  o << "  observability                    condition " << std::scientific << std::setprecision(2)
    << s.observability.condition_number << std::defaultfloat
    << (s.observability.well_conditioned ? " (well conditioned)"
                                         : " (WEAK: " + s.observability.weakest_description + ")")
    << "\n";
  if (std::abs(s.plane_scale - 1.0) > 1e-9)
    o << "  camera plane scale               " << formatFixed(s.plane_scale, 4) << "\n";
  for (const auto& n : s.notes) o << "  note: " << n << "\n";
  return o.str();
}

std::string comparisonTable(const std::vector<CalibrationSolution>& solutions,
                            const std::vector<PoseStddev>* judged) {
  std::ostringstream o;
  o << "| method | ok | views | MLRE px | plane RMS mm | sigma t mm (max) | sigma r deg (max) | dR "
       "deg | dt mm |\n";
  o << "|---|---|---|---|---|---|---|---|---|\n";
  const CalibrationSolution* first = nullptr;
  for (const auto& s : solutions)
    if (s.success) {
      first = &s;
      break;
    }
  for (size_t i = 0; i < solutions.size(); ++i) {
    const CalibrationSolution& s = solutions[i];
    const PoseStddev& sd = judged && i < judged->size() ? (*judged)[i] : s.stddev;
    o << "| " << methodName(s.method) << " | " << (s.success ? "yes" : "no") << " | "
      << s.views_used << " | ";
    if (!s.success) {
      o << "- | - | - | - | - | - |  (" << s.reason << ")\n";
      continue;
    }
    o << (s.mlre_px ? formatFixed(*s.mlre_px, 2) : std::string("-")) << " | "
      << formatFixed(s.plane_rms_mm, 1) << " | "
      << formatFixed(sd.translation_m.maxCoeff() * 1e3, 2) << " | "
      << formatFixed(sd.rotation_deg.maxCoeff(), 3) << " | "
      << formatFixed(rotationErrorDeg(s.camera_T_lidar, first->camera_T_lidar), 3) << " | "
      << formatFixed(translationErrorM(s.camera_T_lidar, first->camera_T_lidar) * 1e3, 1) << " |\n";
  }
  return o.str();
}

std::string perViewTable(const CalibrationSolution& s) {
  std::ostringstream o;
  o << "| view | used | plane RMS mm | MLRE px | UL px | UR px | LR px | LL px | note |\n";
  o << "|---|---|---|---|---|---|---|---|---|\n";
  for (const auto& v : s.views) {
    o << "| " << v.view_id << " | " << (v.used ? "yes" : "no") << " | "
      << formatFixed(v.plane.rms_m * 1e3, 1) << " | "
      << (v.mlre_px ? formatFixed(*v.mlre_px, 2) : std::string("-"));
    for (const auto& e : v.edges)
      o << " | " << (e.mlre_px ? formatFixed(*e.mlre_px, 2) : std::string("-"));
    o << " | " << v.reason << " |\n";
  }
  return o.str();
}

std::string staticTransformLaunchSnippet(const ResultFile& r, const std::string& child_frame) {
  // static_transform_publisher x y z qx qy qz qw parent child: the child (camera) in the parent
  // (LiDAR) frame, i.e. lidar_T_camera.
  const Eigen::Isometry3d lidar_T_camera = r.camera_T_lidar.inverse();
  const Eigen::Vector3d t = lidar_T_camera.translation();
  const Eigen::Vector4d q = quaternionXyzw(lidar_T_camera);
  std::ostringstream o;
  o << std::setprecision(9);
  o << "<launch>\n  <!-- board_calib " << r.method << " result: " << r.camera_frame << " in "
    << r.lidar_frame
    << " -->\n  <!-- Needs tf2_ros's static_transform_publisher (ROS Noetic; Debian's ROS packages "
       "lack it: there run"
    << "\n       roslaunch board_calib publish_calibration.launch result_file:=" << r.method
    << "_result.yaml) -->"
    << "\n  <node pkg=\"tf2_ros\" type=\"static_transform_publisher\" name=\"board_calib_"
    << child_frame << "_tf\"\n        args=\"" << t.x() << " " << t.y() << " " << t.z() << " "
    << q[0] << " " << q[1] << " " << q[2] << " " << q[3] << " " << r.lidar_frame << " "
    << child_frame << "\"/>\n</launch>\n";
  return o.str();
}

std::string urdfJointSnippet(const ResultFile& r, const std::string& child_frame) {
  const Eigen::Isometry3d lidar_T_camera = r.camera_T_lidar.inverse();
  const Eigen::Vector3d t = lidar_T_camera.translation();
  const Eigen::Vector3d rpy = rollPitchYaw(lidar_T_camera.rotation());
  std::ostringstream o;
  o << std::setprecision(9);
  o << "<!-- board_calib " << r.method << " result -->\n<joint name=\"" << r.lidar_frame << "_to_"
    << child_frame << "\" type=\"fixed\">\n  <parent link=\"" << r.lidar_frame
    << "\"/>\n  <child link=\"" << child_frame << "\"/>\n  <origin xyz=\"" << t.x() << " " << t.y()
    << " " << t.z() << "\" rpy=\"" << rpy.x() << " " << rpy.y() << " " << rpy.z()
    << "\"/>\n</joint>\n";
  return o.str();
}

int bestSolutionIndex(const std::vector<CalibrationSolution>& solutions) {
  int best = -1;
  for (int i = 0; i < static_cast<int>(solutions.size()); ++i) {
    const auto& s = solutions[i];
    if (!s.success) continue;
    if (best < 0) {
      best = i;
      continue;
    }
    const auto& b = solutions[best];
    const bool both_mlre = s.mlre_px && b.mlre_px;
    if ((both_mlre && *s.mlre_px < *b.mlre_px) || (!both_mlre && s.plane_rms_mm < b.plane_rms_mm))
      best = i;
  }
  return best;
}

}  // namespace board_calib
