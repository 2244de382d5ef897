# LiDAR board detector: planar segmentation, board scoring, edges, background model.
# Eigen only at the moment; PCL stays available to this module's .cpp files.
board_calib_core_module(lidar_detection
  src/core/lidar_detection/lidar_board_detector.cpp
  src/core/lidar_detection/lidar_board_tracker.cpp
  src/core/lidar_detection/lidar_candidates.cpp
  src/core/lidar_detection/lidar_plane.cpp
  src/core/lidar_detection/lidar_edges.cpp
  src/core/lidar_detection/lidar_rectangle_edges.cpp
  src/core/lidar_detection/background_model.cpp
  src/core/lidar_detection/geometry_2d.cpp
  src/core/lidar_detection/scan_segments.cpp)
target_link_libraries(bc_lidar_detection PUBLIC bc_geometry)
