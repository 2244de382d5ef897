# End-to-end tests on simulated sessions; the bags are generated first by CTest fixtures.
#  * rostest: checkerboard + VLP-16 bag -> rosbag play -> detectors -> calibrator -> ~calibrate (PPC) -> TF vs truth
#  * calibrate_bag: plain board + VLP-32C bag -> PPC/PBPC/MSG -> reported result vs truth
set(BOARD_CALIB_E2E_DIR ${CMAKE_CURRENT_BINARY_DIR}/test_data/e2e)
set(BOARD_CALIB_E2E_PLAIN_DIR ${CMAKE_CURRENT_BINARY_DIR}/test_data/e2e_plain)
file(MAKE_DIRECTORY ${BOARD_CALIB_E2E_DIR} ${BOARD_CALIB_E2E_PLAIN_DIR})
add_test(NAME generate_e2e_bag
  COMMAND ${CMAKE_COMMAND} -E env ROS_HOME=${CMAKE_CURRENT_BINARY_DIR}/ros_home
    $<TARGET_FILE:simulate_bag> --quiet --scenario ${CMAKE_CURRENT_SOURCE_DIR}/config/scenarios/checker_vlp16_1280.yaml
    --out ${BOARD_CALIB_E2E_DIR}/session.bag)
set_tests_properties(generate_e2e_bag PROPERTIES FIXTURES_SETUP e2e_bag)
add_test(NAME generate_e2e_plain_bag
  COMMAND ${CMAKE_COMMAND} -E env ROS_HOME=${CMAKE_CURRENT_BINARY_DIR}/ros_home
    $<TARGET_FILE:simulate_bag> --quiet --scenario ${CMAKE_CURRENT_SOURCE_DIR}/config/scenarios/plain_vlp32c_1920.yaml
    --out ${BOARD_CALIB_E2E_PLAIN_DIR}/session.bag)
set_tests_properties(generate_e2e_plain_bag PROPERTIES FIXTURES_SETUP e2e_plain_bag)

# The .test file finds the generated session through BOARD_CALIB_E2E_DIR.
add_executable(test_pipeline_e2e EXCLUDE_FROM_ALL test/rostest/pipeline_e2e.cpp)
target_link_libraries(test_pipeline_e2e board_calib_ros board_calib_core ${catkin_LIBRARIES} GTest::gtest)
add_dependencies(test_pipeline_e2e ${PROJECT_NAME}_generate_messages_cpp simulate_bag calibrate_bag
  ${BOARD_CALIB_NODELET_LIBS})
add_dependencies(tests test_pipeline_e2e)
add_rostest(test/rostest/pipeline_e2e.test DEPENDENCIES test_pipeline_e2e)
set_tests_properties(_ctest_board_calib_rostest_test_rostest_pipeline_e2e.test PROPERTIES
  FIXTURES_REQUIRED e2e_bag ENVIRONMENT "BOARD_CALIB_E2E_DIR=${BOARD_CALIB_E2E_DIR}")

# The plain-board session through calibrate_bag: exits non-zero when the reported result misses the truth.
add_test(NAME calibrate_bag_sim_e2e
  COMMAND ${CMAKE_COMMAND} -E env ROS_HOME=${CMAKE_CURRENT_BINARY_DIR}/ros_home
    $<TARGET_FILE:calibrate_bag> --quiet --bag ${BOARD_CALIB_E2E_PLAIN_DIR}/session.bag
    --target ${BOARD_CALIB_E2E_PLAIN_DIR}/session.target.yaml --image-topic /camera/image_raw
    --camera-info-topic /camera/camera_info --cloud-topic /lidar/points --method all
    --output ${BOARD_CALIB_E2E_PLAIN_DIR}/result.yaml --truth ${BOARD_CALIB_E2E_PLAIN_DIR}/session.truth.yaml
    --check-truth 0.2 0.01)
set_tests_properties(calibrate_bag_sim_e2e PROPERTIES FIXTURES_REQUIRED e2e_plain_bag)
