# MSG-Cal live end to end: the rig bag of the rig_bag fixture (cmake/tests_rig.cmake) played
# into the example rig's bring-up (four detector nodelets, four projections) and the calibrator in rig mode; every sensor's TF vs the truth.
if(TARGET simulate_bag)
  set(BOARD_CALIB_RIG_DIR ${CMAKE_CURRENT_BINARY_DIR}/test_rig_e2e)
  add_executable(test_rig_live_e2e EXCLUDE_FROM_ALL test/rostest/rig_live_e2e.cpp)
  target_link_libraries(test_rig_live_e2e board_calib_ros board_calib_core ${catkin_LIBRARIES} GTest::gtest)
  add_dependencies(test_rig_live_e2e ${PROJECT_NAME}_generate_messages_cpp simulate_bag rig_bringup ${BOARD_CALIB_NODELET_LIBS})
  add_dependencies(tests test_rig_live_e2e)
  add_rostest(test/rostest/rig_live_e2e.test DEPENDENCIES test_rig_live_e2e)
  set_tests_properties(_ctest_board_calib_rostest_test_rostest_rig_live_e2e.test PROPERTIES
    FIXTURES_REQUIRED rig_bag ENVIRONMENT "BOARD_CALIB_RIG_DIR=${BOARD_CALIB_RIG_DIR}")
endif()

# Any rig from its rig file (issue 17): 1 camera + 2 LiDARs and 3 cameras + 1 LiDAR with names and
# topics found only in test/data, live through the one-line bring-up (rig_calibration.launch).
if(TARGET simulate_bag AND TARGET rig_bringup AND TARGET test_rig_live_e2e)
  set(_custom_dir ${CMAKE_CURRENT_BINARY_DIR}/test_rig_custom)
  file(MAKE_DIRECTORY ${_custom_dir})
  add_dependencies(test_rig_live_e2e rig_bringup)
  foreach(_rig 1cam_2lidar 3cam_1lidar)
    add_test(NAME rig_custom_simulate_${_rig}
      COMMAND $<TARGET_FILE:simulate_bag>
        --scenario ${CMAKE_CURRENT_SOURCE_DIR}/test/data/rig_${_rig}_scenario.yaml
        --out ${_custom_dir}/rig_${_rig}.bag --quiet)
    set_tests_properties(rig_custom_simulate_${_rig} PROPERTIES FIXTURES_SETUP rig_custom_${_rig} TIMEOUT 120)
  endforeach()
  add_rostest(test/rostest/rig_custom_live.test ARGS rig:=1cam_2lidar sensors:=3 pairs:=2
    DEPENDENCIES test_rig_live_e2e)
  add_rostest(test/rostest/rig_custom_live.test ARGS rig:=3cam_1lidar sensors:=4 pairs:=3
    DEPENDENCIES test_rig_live_e2e)
  set_tests_properties(_ctest_board_calib_rostest_rig_custom_live__rig_1cam_2lidar__sensors_3__pairs_2.test
    PROPERTIES FIXTURES_REQUIRED rig_custom_1cam_2lidar ENVIRONMENT "BOARD_CALIB_RIG_CUSTOM_DIR=${_custom_dir}")
  set_tests_properties(_ctest_board_calib_rostest_rig_custom_live__rig_3cam_1lidar__sensors_4__pairs_3.test
    PROPERTIES FIXTURES_REQUIRED rig_custom_3cam_1lidar ENVIRONMENT "BOARD_CALIB_RIG_CUSTOM_DIR=${_custom_dir}")
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
