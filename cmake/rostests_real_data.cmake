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
else()
  message(STATUS "board_calib: ../shared/data not found: real-data tests are not registered")
endif()
