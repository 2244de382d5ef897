// Solve results -> CalibrationResult / SensorPose messages (declared in conversions.h). Apart
// from conversions.cpp so the message-level fuzzer links without the solver and graph modules.
#include <board_calib/conversions.h>
#include <board_calib/core/common/statistics.h>
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

visualization_msgs::MarkerArray toViewMarkers(const std::vector<View>& views,
                                              const CalibrationSolution* solution) {
  // One marker per kept view: its LiDAR board points, coloured by the view's plane residual
  // under the last solution relative to the median view's (green at or below the median, red
  // at kRedAtMedianFactor x the median or worse), white before any solve. Relative, because
  // the absolute plane RMS follows the LiDAR's range noise and a declared-size bias: an
  // absolute scale painted every view of a noisy real LiDAR red.
  constexpr double kRedAtMedianFactor = 3.0;  // the report's outlier factor for edges
  std::vector<double> rms;
  if (solution)
    for (const auto& vr : solution->views)
      if (vr.used) rms.push_back(vr.plane.rms_m);
  const double median_rms = medianOf(rms);
  visualization_msgs::MarkerArray array;
  visualization_msgs::Marker clear;
  clear.action = visualization_msgs::Marker::DELETEALL;
  array.markers.push_back(clear);
  for (const auto& v : views) {
    visualization_msgs::Marker m;
    m.header.frame_id = v.lidar.frame_id;
    m.header.stamp = ros::Time(0);
    m.ns = "views";
    m.id = v.id;
    m.type = visualization_msgs::Marker::POINTS;
    m.scale.x = m.scale.y = 0.02;
    m.pose.orientation.w = 1.0;
    m.color.a = 1.0;
    m.color.r = m.color.g = m.color.b = 1.0;
    if (solution) {
      for (const auto& vr : solution->views)
        if (vr.view_id == v.id && vr.used) {
          const double x =
              median_rms > 0
                  ? std::clamp((vr.plane.rms_m / median_rms - 1.0) / (kRedAtMedianFactor - 1.0),
                               0.0, 1.0)
                  : 0.0;
          m.color.r = static_cast<float>(x);
          m.color.g = static_cast<float>(1.0 - x);
          m.color.b = 0.0f;
        }
    }
    for (const auto& p : v.lidar.board_points) {
      geometry_msgs::Point q;
      q.x = p.x();
      q.y = p.y();
      q.z = p.z();
      m.points.push_back(q);
    }
    array.markers.push_back(m);
  }
  return array;
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
