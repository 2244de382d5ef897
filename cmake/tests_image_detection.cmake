# Camera board detector tests: synthetic (core, no ROS) and the real recordings (via bag_reader).
board_calib_core_gtest(test_image_detector
  SOURCES test/core/test_image_detector.cpp
  MODULES bc_image_detection bc_sim bc_geometry
  LIBS ${OpenCV_LIBRARIES} opencv_imgcodecs)  # imgcodecs: optional debug PNGs

catkin_add_gtest(test_image_detector_real test/ros/test_image_detector_real.cpp
  WORKING_DIRECTORY ${CMAKE_CURRENT_SOURCE_DIR})
if(TARGET test_image_detector_real)
  target_compile_options(test_image_detector_real PRIVATE ${BOARD_CALIB_WARNINGS})
  target_compile_definitions(test_image_detector_real PRIVATE
    BOARD_CALIB_SHARED_DIR="${CMAKE_CURRENT_SOURCE_DIR}/../shared")
  target_link_libraries(test_image_detector_real board_calib_ros board_calib_core ${catkin_LIBRARIES} yaml-cpp
    ${OpenCV_LIBRARIES} opencv_imgcodecs GTest::gtest_main)
  add_dependencies(test_image_detector_real ${PROJECT_NAME}_generate_messages_cpp)
endif()

# Augmented real frames (issue 14): recoloured, textured, shrunk, occluded and blanked boards.
catkin_add_gtest(test_image_detector_augmented test/ros/test_image_detector_augmented.cpp
  WORKING_DIRECTORY ${CMAKE_CURRENT_SOURCE_DIR})
if(TARGET test_image_detector_augmented)
  target_compile_options(test_image_detector_augmented PRIVATE ${BOARD_CALIB_WARNINGS})
  target_compile_definitions(test_image_detector_augmented PRIVATE
    BOARD_CALIB_SHARED_DIR="${CMAKE_CURRENT_SOURCE_DIR}/../shared")
  target_link_libraries(test_image_detector_augmented board_calib_ros board_calib_core ${catkin_LIBRARIES} yaml-cpp
    ${OpenCV_LIBRARIES} opencv_imgcodecs opencv_photo GTest::gtest_main)
  add_dependencies(test_image_detector_augmented ${PROJECT_NAME}_generate_messages_cpp)
endif()
