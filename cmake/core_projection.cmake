# Projection of LiDAR data into images: overlays, the projected-edges check, coloured clouds.
board_calib_core_module(projection
  src/core/projection/projection.cpp
  src/core/projection/edge_check.cpp)
target_include_directories(bc_projection SYSTEM PUBLIC ${OpenCV_INCLUDE_DIRS})
target_link_libraries(bc_projection PUBLIC bc_geometry ${OpenCV_LIBRARIES})
