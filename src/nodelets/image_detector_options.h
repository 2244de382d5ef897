// dynamic_reconfigure config -> core image detector options, shared by the nodelet and the test
// that keeps the .cfg defaults equal to the core defaults (test/ros/test_config_defaults.cpp). The
// X-list names each (cfg parameter, options member) pair once; the mapping and the test expand it.
#pragma once

#include <board_calib/ImageBoardDetectorConfig.h>
#include <board_calib/core/image_detection/image_board_detector.h>

// Every parameter of cfg/ImageBoardDetector.cfg.
#define BOARD_CALIB_IMAGE_DETECTOR_FIELDS(X)                      \
  X(segmentation_width, segmentation_width_px)                    \
  X(min_board_area_fraction, min_board_area_fraction)             \
  X(min_solidity, min_solidity)                                   \
  X(max_flat_gradient, max_flat_gradient)                         \
  X(max_interior_texture, max_interior_texture)                   \
  X(max_board_candidates, max_board_candidates)                   \
  X(border_margin, border_margin_px)                              \
  X(coarse_search, coarse_search_px)                              \
  X(fine_search, fine_search_px)                                  \
  X(sample_step, sample_step_px)                                  \
  X(corner_exclusion, corner_exclusion_px)                        \
  X(min_edge_contrast, min_edge_contrast)                         \
  X(edge_snr, edge_snr)                                           \
  X(min_side_coverage, min_side_coverage)                         \
  X(max_plain_corner_rms_fraction, max_plain_corner_rms_fraction) \
  X(line_detection_width, line_detection_width_px)                \
  X(max_line_hypotheses, max_line_hypotheses)                     \
  X(max_board_tilt, max_board_tilt_deg)                           \
  X(max_board_distance, max_board_distance_m)                     \
  X(min_edge_length, min_edge_length_px)                          \
  X(min_edge_points, min_edge_points)                             \
  X(edge_inlier, edge_inlier_px)                                  \
  X(max_edge_rms, max_edge_rms_px)                                \
  X(max_edge_bow_fraction, max_edge_bow_fraction)                 \
  X(max_plain_corner_rms, max_plain_corner_rms_px)                \
  X(fast_check_width, fast_check_width_px)                        \
  X(subpix_window, subpix_window_px)                              \
  X(tag_decimate, tag_decimate)                                   \
  X(tag_sigma, tag_sigma)                                         \
  X(tag_threads, tag_threads)                                     \
  X(tag_refine_edges, tag_refine_edges)                           \
  X(tag_max_hamming, tag_max_hamming)                             \
  X(min_tags, min_tags)                                           \
  X(min_board_size, min_board_size_px)                            \
  X(max_reprojection_rms, max_reprojection_rms_px)                \
  X(pixel_sigma, pixel_sigma_px)

namespace board_calib {

inline ImageBoardDetectorOptions optionsFromConfig(const ImageBoardDetectorConfig& c) {
  ImageBoardDetectorOptions o;
#define BOARD_CALIB_ASSIGN(cfg, member) o.member = c.cfg;
  BOARD_CALIB_IMAGE_DETECTOR_FIELDS(BOARD_CALIB_ASSIGN)
#undef BOARD_CALIB_ASSIGN
  return o;
}

}  // namespace board_calib
