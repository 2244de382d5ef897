# Real recordings (../shared/data, present in CI): calibrate_bag end to end, scored independently.
set(BOARD_CALIB_SHARED ${CMAKE_CURRENT_SOURCE_DIR}/../shared)
if(EXISTS ${BOARD_CALIB_SHARED}/data/basler_os1_plain/session.bag)
  foreach(case plain checker)
    add_test(NAME calibrate_bag_real_${case}
      COMMAND /usr/bin/python3 ${CMAKE_CURRENT_SOURCE_DIR}/test/check_real_data.py ${case}
        --tool $<TARGET_FILE:calibrate_bag> --shared ${BOARD_CALIB_SHARED}
        --out ${CMAKE_CURRENT_BINARY_DIR}/test_data/real)
    set_tests_properties(calibrate_bag_real_${case} PROPERTIES TIMEOUT 600
      ENVIRONMENT "ROS_HOME=${CMAKE_CURRENT_BINARY_DIR}/ros_home")
  endforeach()
  # The README's live commands replaying the bundled plain-board recording.
  add_executable(test_live_replay_real EXCLUDE_FROM_ALL test/rostest/live_replay_real.cpp)
  target_link_libraries(test_live_replay_real ${catkin_LIBRARIES} GTest::gtest)
  add_dependencies(test_live_replay_real ${PROJECT_NAME}_generate_messages_cpp ${BOARD_CALIB_NODELET_LIBS})
  add_dependencies(tests test_live_replay_real)
  add_rostest(test/rostest/live_replay_real.test DEPENDENCIES test_live_replay_real)
  set_tests_properties(_ctest_board_calib_rostest_test_rostest_live_replay_real.test PROPERTIES
    ENVIRONMENT "BOARD_CALIB_SHARED=${BOARD_CALIB_SHARED}" TIMEOUT 450)
else()
  message(STATUS "board_calib: ../shared/data not found: real-data tests are not registered")
endif()
