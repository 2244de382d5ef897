# rviz starts headless (Xvfb, software GL) with rviz/calibration.rviz, subscribes to every
# display's topic and logs no error; screenshot in <build>/rviz_check/calibration_rviz.png.
# Exit code 77 (rviz or xvfb-run missing) counts as skipped.
add_test(NAME rviz_headless_check
  COMMAND bash ${CMAKE_CURRENT_SOURCE_DIR}/test/rviz_headless_check.sh
          ${CMAKE_CURRENT_SOURCE_DIR}/rviz/calibration.rviz ${CMAKE_BINARY_DIR}/rviz_check)
set_tests_properties(rviz_headless_check PROPERTIES SKIP_RETURN_CODE 77 TIMEOUT 180)
