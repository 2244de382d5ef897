# Simulator: rendering and ray-casting against ground truth.
board_calib_core_gtest(test_sim
  SOURCES test/core/test_sim.cpp
  MODULES bc_sim bc_geometry
  LIBS ${OpenCV_LIBRARIES} apriltag::apriltag apriltag::apriltag-utils)
board_calib_core_gtest(test_sim_scenario
  SOURCES test/core/test_sim_scenario.cpp
  MODULES bc_sim bc_geometry
  LIBS ${OpenCV_LIBRARIES} apriltag::apriltag apriltag::apriltag-utils yaml-cpp)
