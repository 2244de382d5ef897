# Simulator: camera rendering and LiDAR ray casting with ground truth, scenario timelines.
board_calib_core_module(sim
  src/core/sim/simulator.cpp
  src/core/sim/scenario.cpp)
target_include_directories(bc_sim SYSTEM PUBLIC ${OpenCV_INCLUDE_DIRS})
target_link_libraries(bc_sim PUBLIC bc_geometry yaml-cpp ${OpenCV_LIBRARIES} apriltag::apriltag
  apriltag::apriltag-utils)  # Debian ships image_u8_* (used by apriltag_to_image) in -utils
