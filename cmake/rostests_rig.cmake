# MSG-Cal live end to end: the rig bag of the rig_bag fixture (cmake/tests_rig.cmake) played
# into four detector nodelets and the calibrator in rig mode; every sensor's TF vs the truth.
if(TARGET simulate_bag)
  set(BOARD_CALIB_RIG_DIR ${CMAKE_CURRENT_BINARY_DIR}/test_rig_e2e)
  add_executable(test_rig_live_e2e EXCLUDE_FROM_ALL test/rostest/rig_live_e2e.cpp)
  target_link_libraries(test_rig_live_e2e board_calib_ros board_calib_core ${catkin_LIBRARIES} GTest::gtest)
  add_dependencies(test_rig_live_e2e ${PROJECT_NAME}_generate_messages_cpp simulate_bag ${BOARD_CALIB_NODELET_LIBS})
  add_dependencies(tests test_rig_live_e2e)
  add_rostest(test/rostest/rig_live_e2e.test DEPENDENCIES test_rig_live_e2e)
  set_tests_properties(_ctest_board_calib_rostest_test_rostest_rig_live_e2e.test PROPERTIES
    FIXTURES_REQUIRED rig_bag ENVIRONMENT "BOARD_CALIB_RIG_DIR=${BOARD_CALIB_RIG_DIR}")
endif()

# publish_calibration: saved pair and rig result files broadcast as static TF.
if(TARGET publish_calibration)
  add_executable(test_publish_calibration EXCLUDE_FROM_ALL test/rostest/publish_calibration.cpp)
  target_compile_options(test_publish_calibration PRIVATE ${BOARD_CALIB_WARNINGS})
  target_link_libraries(test_publish_calibration board_calib_core ${catkin_LIBRARIES} GTest::gtest)
  add_dependencies(test_publish_calibration publish_calibration)
  add_dependencies(tests test_publish_calibration)
  add_rostest(test/rostest/publish_calibration.test DEPENDENCIES test_publish_calibration)
endif()
