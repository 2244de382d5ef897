# rviz starts headless (Xvfb, software GL) with rviz/calibration.rviz, subscribes to every
# display's topic and logs no error; with ../shared present it shows basler_os1_plain played
# through the projection nodelet. Screenshot: <build>/rviz_check/calibration_rviz.png.
# Exit code 77 (rviz or xvfb-run missing) counts as skipped.
add_test(NAME rviz_headless_check
  COMMAND bash ${CMAKE_CURRENT_SOURCE_DIR}/test/rviz_headless_check.sh
          ${CMAKE_CURRENT_SOURCE_DIR}/rviz/calibration.rviz ${CMAKE_BINARY_DIR}/rviz_check
          ${CATKIN_DEVEL_PREFIX}/setup.bash)
set_tests_properties(rviz_headless_check PROPERTIES SKIP_RETURN_CODE 77 TIMEOUT 180)

# The projection nodelet: lazy subscription, overlay and coloured cloud on a synthetic frame.
add_rostest_gtest(test_projection_nodelet test/rostest/projection.test test/rostest/projection_nodelet.cpp)
target_compile_options(test_projection_nodelet PRIVATE ${BOARD_CALIB_WARNINGS})
target_link_libraries(test_projection_nodelet board_calib_ros board_calib_core ${catkin_LIBRARIES} ${GTEST_LIBRARIES})
add_dependencies(test_projection_nodelet ${PROJECT_NAME}_generate_messages_cpp board_calib_projection)
