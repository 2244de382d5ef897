// Text summary of a rig solve (see rig_report.h).
#include <board_calib/core/rig/rig_summary.h>
#include <board_calib/core/transform.h>

#include <iomanip>
#include <optional>
#include <sstream>

namespace board_calib {

std::string poseLine(const Eigen::Isometry3d& T) {
  const Eigen::Quaterniond q(T.linear());
  const Eigen::Vector3d t = T.translation();
  std::ostringstream os;
  os << std::fixed << std::setprecision(4) << "t [" << t.x() << ", " << t.y() << ", " << t.z()
     << "] m, q_xyzw [" << std::setprecision(5) << q.x() << ", " << q.y() << ", " << q.z() << ", "
     << q.w() << "]";
  return os.str();
}

std::string rigSolutionSummary(const RigConfig& rig, const multi_sensor::MsgSolution& solution,
                               const ResultFile& result) {
  std::ostringstream out;
  out << std::fixed;
  out << "MSG-Cal: " << solution.sensors.size() << " sensors, " << solution.poses_used
      << " board poses, reference " << solution.sensors[solution.reference_sensor].frame
      << ", solved in " << std::setprecision(1) << solution.solve_time_ms << " ms\n";
  out << "sensors (reference_T_sensor, 1-sigma max rotation / translation):\n";
  for (const auto& s : solution.sensors) {
    out << "  " << std::left << std::setw(16) << s.frame << std::right << " " << std::setw(6)
        << multi_sensor::sensorKindName(s.kind) << "  " << poseLine(s.reference_T_sensor);
    if (&s != &solution.sensors[solution.reference_sensor])
      out << "  +-" << std::setprecision(3) << s.stddev.rotation_deg.maxCoeff() << " deg / "
          << std::setprecision(1) << 1000.0 * s.stddev.translation_m.maxCoeff() << " mm";
    out << "  (" << s.observations << " poses, " << s.observations_rejected << " rejected)\n";
  }
  out << "camera <- LiDAR pairs (camera_T_lidar, MLRE, 1-sigma max rotation / translation):\n";
  for (const auto& p : result.pairs) {
    out << "  " << p.camera_frame << " <- " << p.lidar_frame << ": " << poseLine(p.camera_T_lidar)
        << ", MLRE ";
    if (p.mlre_px)
      out << std::setprecision(2) << *p.mlre_px << " px";
    else
      out << "n/a (no shared edges)";
    if (p.stddev)
      out << "  +-" << std::setprecision(3) << p.stddev->rotation_deg.maxCoeff() << " deg / "
          << std::setprecision(1) << 1000.0 * p.stddev->translation_m.maxCoeff() << " mm";
    out << "\n";
  }
  out << std::setprecision(3) << "loop consistency (max over " << solution.loops.size()
      << " triangles of pairwise estimates): " << solution.loop_rotation_max_deg << " deg, "
      << std::setprecision(1) << solution.loop_translation_max_mm << " mm\n";
  out << std::setprecision(3) << "graph residuals: plane normal "
      << solution.residuals.normal_rms_deg << " deg rms, offset "
      << solution.residuals.offset_rms_mm << " mm rms";
  if (solution.residuals.corner_terms)
    out << ", corners " << solution.residuals.corner_rms_px << " px rms";
  if (solution.residuals.line_terms)
    out << ", lines " << solution.residuals.line_rms_mm << " mm rms";
  out << "\n";
  for (const auto& k : rig.known_extrinsics) {
    const int a = rig.sensorIndex(k.a), b = rig.sensorIndex(k.b);
    const int n = static_cast<int>(solution.sensors.size());
    if (a < 0 || b < 0 || a >= n || b >= n) {
      out << "known-extrinsic consistency " << k.a << " <- " << k.b
          << ": n/a (not sensors of this solve)\n";
      continue;
    }
    const bool both_cameras = solution.sensors[a].kind == multi_sensor::SensorKind::kCamera &&
                              solution.sensors[b].kind == multi_sensor::SensorKind::kCamera;
    std::optional<multi_sensor::StereoConsistency> c;
    std::string why;
    if (both_cameras) {
      auto s = multi_sensor::stereoConsistency(solution, a, b, k.a_T_b);
      if (s)
        c = *s;
      else
        why = s.error();
    } else {
      auto T = multi_sensor::sensorTSensor(solution, a, b);
      if (T)
        c = multi_sensor::StereoConsistency{rotationErrorDeg(*T, k.a_T_b),
                                            1000.0 * translationErrorM(*T, k.a_T_b)};
      else
        why = T.error();
    }
    out << (both_cameras ? "stereo consistency " : "known-extrinsic consistency ") << k.a << " <- "
        << k.b << " (graph vs known): ";
    if (c)
      out << std::setprecision(3) << c->rotation_deg << " deg, " << std::setprecision(1)
          << c->translation_mm << " mm\n";
    else
      out << "n/a (" << why << ")\n";
  }
  for (const auto& n : solution.notes) out << "note: " << n << "\n";
  return out.str();
}

}  // namespace board_calib
