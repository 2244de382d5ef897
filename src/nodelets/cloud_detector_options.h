// dynamic_reconfigure config -> core LiDAR detector options, shared by the nodelet and the test
// that keeps the .cfg defaults equal to the core defaults (test/ros/test_config_defaults.cpp). The
// X-list names each (cfg parameter, options member) pair once; the mapping and the test expand it.
#pragma once

#include <board_calib/CloudBoardDetectorConfig.h>
#include <board_calib/core/lidar_detection/lidar_board_detector.h>

// Scalars of cfg/CloudBoardDetector.cfg (the ROI box corners are mapped separately).
#define BOARD_CALIB_CLOUD_DETECTOR_FIELDS(X)                \
  X(min_range, min_range_m)                                 \
  X(max_range, max_range_m)                                 \
  X(use_roi, use_roi)                                       \
  X(voxel_size, voxel_size_m)                               \
  X(max_voxel_thickness, max_voxel_thickness_m)             \
  X(max_voxel_offset, max_voxel_offset_m)                   \
  X(max_voxel_normal_angle_deg, max_voxel_normal_angle_deg) \
  X(min_board_points, min_board_points)                     \
  X(min_size_ratio, min_size_ratio)                         \
  X(max_size_ratio, max_size_ratio)                         \
  X(min_fill_ratio, min_fill_ratio)                         \
  X(max_candidate_rms, max_candidate_rms_m)                 \
  X(reject_ambiguous, reject_ambiguous)                     \
  X(ambiguity_ratio, ambiguity_ratio)                       \
  X(plane_distance_threshold, plane_distance_threshold_m)   \
  X(ransac_iterations, ransac_iterations)                   \
  X(elevation_gap_deg, elevation_gap_deg)                   \
  X(min_edge_points, min_edge_points)                       \
  X(edge_inlier_threshold, edge_inlier_threshold_m)         \
  X(max_edge_rms, max_edge_rms_m)                           \
  X(max_corner_angle_error_deg, max_corner_angle_error_deg) \
  X(correct_edge_sampling_bias, correct_edge_sampling_bias) \
  X(beam_divergence_deg, beam_divergence_deg)               \
  X(size_doubt_ratio, size_doubt_ratio)

namespace board_calib {

inline LidarBoardDetectorOptions optionsFromConfig(const CloudBoardDetectorConfig& c) {
  LidarBoardDetectorOptions o;
#define BOARD_CALIB_ASSIGN(cfg, member) o.member = c.cfg;
  BOARD_CALIB_CLOUD_DETECTOR_FIELDS(BOARD_CALIB_ASSIGN)
#undef BOARD_CALIB_ASSIGN
  o.roi.min = {c.roi_min_x, c.roi_min_y, c.roi_min_z};
  o.roi.max = {c.roi_max_x, c.roi_max_y, c.roi_max_z};
  return o;
}

}  // namespace board_calib
