// Solve results -> CalibrationResult / SensorPose messages (declared in conversions.h). Apart
// from conversions.cpp so the message-level fuzzer links without the solver and graph modules.
#include <board_calib/conversions.h>
#include <board_calib/core/pipeline/rig_calibration.h>

#include <algorithm>
#include <cmath>

namespace board_calib {

CalibrationResult toResultMsg(const CalibrationSolution& s, const VerdictReport& verdict,
                              const ResultFile& file, const ros::Time& stamp) {
  CalibrationResult m;
  m.header.stamp = stamp;
  m.header.frame_id = file.lidar_frame;
  m.reason = s.reason;
  m.method = methodName(s.method);
  m.camera_frame = file.camera_frame;
  m.lidar_frame = file.lidar_frame;
  m.camera_T_lidar = toTransformMsg(s.camera_T_lidar);
  m.views_used = static_cast<uint32_t>(std::max(0, s.views_used));
  m.mlre_px = s.mlre_px ? *s.mlre_px : std::nan("");
  m.plane_rms_mm = s.plane_rms_mm;
  // The reported uncertainty is the verdict's: never below the cross-validation's spread.
  const bool judged = s.success && verdict.covariance.diagonal().maxCoeff() > 0;
  const PoseStddev& sd = judged ? verdict.stddev : s.stddev;
  const Matrix6d& cov = judged ? verdict.covariance : s.covariance;
  for (int i = 0; i < 3; ++i) {
    m.stddev_translation_m[i] = sd.translation_m[i];
    m.stddev_rotation_deg[i] = sd.rotation_deg[i];
  }
  for (int r = 0; r < 6; ++r)
    for (int c = 0; c < 6; ++c) m.covariance[r * 6 + c] = cov(r, c);
  m.verdict = verdictName(verdict.verdict);
  m.verdict_reason = verdict.reason;
  m.success = s.success && verdict.verdict != Verdict::kFailed;
  if (!m.success && m.reason.empty()) m.reason = verdict.reason;
  m.final_cost = s.final_cost;
  m.notes = file.notes;
  // Per-view residuals, parallel arrays (NaN where a view was skipped or has no edges).
  const double nan = std::nan("");
  for (const auto& v : s.views) {
    m.view_ids.push_back(v.view_id);
    m.view_mlre_px.push_back(v.used && v.mlre_px ? *v.mlre_px : nan);
    m.view_plane_rms_mm.push_back(v.used && v.plane.count > 0 ? v.plane.rms_m * 1000.0 : nan);
  }
  return m;
}

CalibrationResult toPairResultMsg(const PairEntry& p, const RigPairRun& pair,
                                  const multi_sensor::MsgSolution& s, const ros::Time& stamp) {
  CalibrationResult m;
  m.header.stamp = stamp;
  m.header.frame_id = p.lidar_frame;
  m.success = pair.verdict.verdict != Verdict::kFailed;
  m.verdict = p.verdict;
  m.verdict_reason = p.verdict_reason;
  m.method = "msg";
  m.camera_frame = p.camera_frame;
  m.lidar_frame = p.lidar_frame;
  m.camera_T_lidar = toTransformMsg(p.camera_T_lidar);
  m.views_used = static_cast<uint32_t>(std::max(0, s.poses_used));
  m.mlre_px = p.mlre_px ? *p.mlre_px : std::nan("");
  m.plane_rms_mm = std::nan("");
  m.final_cost = s.final_cost;
  m.covariance.fill(std::nan(""));
  m.stddev_translation_m.fill(std::nan(""));
  m.stddev_rotation_deg.fill(std::nan(""));
  // The verdict's uncertainty: grown with residuals beyond the noise model and the
  // cross-validation's spread.
  if (pair.verdict.covariance.diagonal().maxCoeff() > 0) {
    for (int i = 0; i < 3; ++i) {
      m.stddev_translation_m[i] = pair.verdict.stddev.translation_m[i];
      m.stddev_rotation_deg[i] = pair.verdict.stddev.rotation_deg[i];
    }
    for (int r = 0; r < 6; ++r)
      for (int c = 0; c < 6; ++c) m.covariance[r * 6 + c] = pair.verdict.covariance(r, c);
  }
  m.notes = s.notes;
  return m;
}

SensorPose toSensorPoseMsg(const multi_sensor::SensorEstimate& s) {
  SensorPose p;
  p.frame = s.frame;
  p.kind = multi_sensor::sensorKindName(s.kind);
  p.reference_T_sensor = toTransformMsg(s.reference_T_sensor);
  for (int i = 0; i < 3; ++i) {
    p.stddev_translation_m[i] = s.stddev.translation_m[i];
    p.stddev_rotation_deg[i] = s.stddev.rotation_deg[i];
  }
  p.poses_used = static_cast<uint32_t>(std::max(0, s.observations));
  p.poses_rejected = static_cast<uint32_t>(std::max(0, s.observations_rejected));
  return p;
}

}  // namespace board_calib
