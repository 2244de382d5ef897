# LiDAR board detector tests: core (synthetic scenes, bad input, background model) and real
# recordings read through the bag reader (skipped only when ../shared is absent).
set(BC_LIDAR_TEST_MODULES bc_lidar_detection bc_geometry)
set(BC_LIDAR_TEST_SOURCES test/core/test_lidar_detector.cpp)
if(TARGET bc_sim AND EXISTS ${CMAKE_CURRENT_SOURCE_DIR}/test/core/test_lidar_detector_sim.cpp)
  list(APPEND BC_LIDAR_TEST_MODULES bc_sim)
  list(APPEND BC_LIDAR_TEST_SOURCES test/core/test_lidar_detector_sim.cpp)
endif()
board_calib_core_gtest(test_lidar_detector
  SOURCES ${BC_LIDAR_TEST_SOURCES}
  MODULES ${BC_LIDAR_TEST_MODULES}
  LIBS ${OpenCV_LIBRARIES})
if(TARGET test_lidar_detector)
  target_include_directories(test_lidar_detector SYSTEM PRIVATE ${OpenCV_INCLUDE_DIRS})
endif()

catkin_add_gtest(test_lidar_detector_real test/ros/test_lidar_detector_real.cpp
  WORKING_DIRECTORY ${CMAKE_CURRENT_SOURCE_DIR})
if(TARGET test_lidar_detector_real)
  target_compile_options(test_lidar_detector_real PRIVATE ${BOARD_CALIB_WARNINGS})
  target_compile_definitions(test_lidar_detector_real PRIVATE
    BOARD_CALIB_SOURCE_DIR="${CMAKE_CURRENT_SOURCE_DIR}"
    BOARD_CALIB_SHARED_DIR="${CMAKE_CURRENT_SOURCE_DIR}/../shared")
  target_link_libraries(test_lidar_detector_real board_calib_ros board_calib_core ${catkin_LIBRARIES}
    GTest::gtest_main)
  add_dependencies(test_lidar_detector_real ${PROJECT_NAME}_generate_messages_cpp)
endif()
