# Test pyramid: gtests on the core (no ROS), gtests on the conversions (no master),
# rostests for plugin loading and the running graph, launch files parse-checked.
find_package(rostest REQUIRED)
find_package(roslaunch REQUIRED)

# Core gtests: board_calib_core_gtest(name module... SOURCES files...)
function(board_calib_core_gtest name)
  cmake_parse_arguments(ARG "" "" "MODULES;SOURCES;LIBS" ${ARGN})
  catkin_add_gtest(${name} ${ARG_SOURCES} WORKING_DIRECTORY ${CMAKE_CURRENT_SOURCE_DIR})
  if(TARGET ${name})
    target_compile_options(${name} PRIVATE ${BOARD_CALIB_WARNINGS})
    target_include_directories(${name} PRIVATE ${CMAKE_CURRENT_SOURCE_DIR}/test)
    target_compile_definitions(${name} PRIVATE
      BOARD_CALIB_SOURCE_DIR="${CMAKE_CURRENT_SOURCE_DIR}"
      BOARD_CALIB_SHARED_DIR="${CMAKE_CURRENT_SOURCE_DIR}/../shared")
    target_link_libraries(${name} ${ARG_MODULES} ${ARG_LIBS} GTest::gtest_main)
  endif()
endfunction()

board_calib_core_gtest(test_core_geometry
  SOURCES test/core/test_target.cpp test/core/test_camera_model.cpp test/core/test_transform_result.cpp
    test/core/test_file_io.cpp
  MODULES bc_geometry
  LIBS ${OpenCV_LIBRARIES})
target_include_directories(test_core_geometry SYSTEM PRIVATE ${OpenCV_INCLUDE_DIRS})

# Module test fragments (cmake/tests_<module>.cmake), added by each module.
foreach(module solvers sim lidar_detection image_detection session verdict report pipeline projection msg_graph rig)
  if(EXISTS ${CMAKE_CURRENT_SOURCE_DIR}/cmake/tests_${module}.cmake)
    include(cmake/tests_${module}.cmake)
  endif()
endforeach()

# The core must stay ROS-free: no ROS header may be included from include/board_calib/core
# or src/core (include paths cannot enforce it: ROS headers live in /usr/include on Debian).
add_test(NAME core_is_ros_free
  COMMAND /usr/bin/python3 ${CMAKE_CURRENT_SOURCE_DIR}/test/check_core_ros_free.py ${CMAKE_CURRENT_SOURCE_DIR})

# Conversions: ROS messages <-> core types, without a master.
catkin_add_gtest(test_conversions test/ros/test_conversions.cpp)
if(TARGET test_conversions)
  target_compile_options(test_conversions PRIVATE ${BOARD_CALIB_WARNINGS})
  target_link_libraries(test_conversions board_calib_ros board_calib_core ${catkin_LIBRARIES} GTest::gtest_main)
endif()

# Deterministic fuzzers (label fuzz; issue 15). test_fuzz_inputs: the conversions unit (compiled
# in, so the sanitizer build needs only bc_geometry/bc_session), target/session/result YAML and
# non-files; test_fuzz_rig: the rig YAML reader.
catkin_add_gtest(test_fuzz_inputs test/fuzz/fuzz_inputs.cpp src/ros/conversions.cpp)
if(TARGET test_fuzz_inputs)
  target_compile_options(test_fuzz_inputs PRIVATE ${BOARD_CALIB_WARNINGS})
  target_compile_definitions(test_fuzz_inputs PRIVATE BOARD_CALIB_SOURCE_DIR="${CMAKE_CURRENT_SOURCE_DIR}")
  target_link_libraries(test_fuzz_inputs bc_session bc_geometry ${catkin_LIBRARIES} ${OpenCV_LIBRARIES} yaml-cpp
    GTest::gtest_main)
  add_dependencies(test_fuzz_inputs ${PROJECT_NAME}_generate_messages_cpp)
  set_tests_properties(_ctest_board_calib_gtest_test_fuzz_inputs PROPERTIES LABELS "fuzz;unit")
endif()
board_calib_core_gtest(test_fuzz_rig
  SOURCES test/fuzz/fuzz_rig.cpp
  MODULES bc_rig bc_msg_graph bc_session bc_solvers bc_geometry
  LIBS Ceres::ceres yaml-cpp)
if(TARGET test_fuzz_rig)
  set_tests_properties(_ctest_board_calib_gtest_test_fuzz_rig PROPERTIES LABELS "fuzz;unit")
endif()

# The detector nodelets' dynamic_reconfigure defaults equal the core defaults.
catkin_add_gtest(test_config_defaults test/ros/test_config_defaults.cpp)
if(TARGET test_config_defaults)
  target_compile_options(test_config_defaults PRIVATE ${BOARD_CALIB_WARNINGS})
  target_include_directories(test_config_defaults PRIVATE ${CMAKE_CURRENT_SOURCE_DIR}/src/nodelets)
  target_link_libraries(test_config_defaults board_calib_core ${catkin_LIBRARIES} GTest::gtest_main)
  if(TARGET ${PROJECT_NAME}_gencfg)
    add_dependencies(test_config_defaults ${PROJECT_NAME}_gencfg)
  endif()
endif()

# Every class in nodelet_plugins.xml loads through pluginlib (a rostest: constructors may need a master).
add_rostest_gtest(test_nodelet_plugins test/rostest/nodelet_plugins.test test/ros/test_nodelet_plugins.cpp)
target_compile_definitions(test_nodelet_plugins PRIVATE BOARD_CALIB_SOURCE_DIR="${CMAKE_CURRENT_SOURCE_DIR}")
target_link_libraries(test_nodelet_plugins ${catkin_LIBRARIES} ${GTEST_LIBRARIES})
add_dependencies(test_nodelet_plugins ${BOARD_CALIB_NODELET_LIBS})

# Every launch file parses and its arguments resolve.
roslaunch_add_file_check(launch)

# rostests (each starts its own master).
add_rostest_gtest(test_message_roundtrip test/rostest/message_roundtrip.test test/rostest/message_roundtrip.cpp)
target_link_libraries(test_message_roundtrip board_calib_ros board_calib_core ${catkin_LIBRARIES} ${GTEST_LIBRARIES})
add_dependencies(test_message_roundtrip ${PROJECT_NAME}_generate_messages_cpp)
foreach(rostest_fragment pipeline projection real_data rig)
  if(EXISTS ${CMAKE_CURRENT_SOURCE_DIR}/cmake/rostests_${rostest_fragment}.cmake)
    include(cmake/rostests_${rostest_fragment}.cmake)
  endif()
endforeach()

# The README commands test: every command in README.md and docs/**/*.md runs as written on this
# build (a table in the script must cover each; live ones against a private master, rviz under
# Xvfb). Exit 77 (no ../shared/data) counts as skipped.
add_test(NAME readme_commands
  COMMAND /usr/bin/python3 ${CMAKE_CURRENT_SOURCE_DIR}/test/check_readme_commands.py
          ${CMAKE_CURRENT_SOURCE_DIR} ${CMAKE_BINARY_DIR})
set_tests_properties(readme_commands PROPERTIES SKIP_RETURN_CODE 77 TIMEOUT 900)

# Autosave + resume: the calibrator's manager is killed after 10 views and respawned; no view
# may be lost (issue 15). The folder is emptied first so a failed earlier run cannot leak in.
set(BOARD_CALIB_AUTOSAVE_DIR ${CMAKE_CURRENT_BINARY_DIR}/test_data/autosave)
add_test(NAME autosave_resume_clean COMMAND ${CMAKE_COMMAND} -E remove_directory ${BOARD_CALIB_AUTOSAVE_DIR})
set_tests_properties(autosave_resume_clean PROPERTIES FIXTURES_SETUP autosave_dir)
add_executable(test_autosave_resume EXCLUDE_FROM_ALL test/rostest/autosave_resume.cpp)
target_compile_options(test_autosave_resume PRIVATE ${BOARD_CALIB_WARNINGS})
target_link_libraries(test_autosave_resume board_calib_ros board_calib_core ${catkin_LIBRARIES} GTest::gtest)
add_dependencies(test_autosave_resume ${PROJECT_NAME}_generate_messages_cpp board_calib_calibrator)
add_dependencies(tests test_autosave_resume)
add_rostest(test/rostest/autosave_resume.test DEPENDENCIES test_autosave_resume)
set_tests_properties(_ctest_board_calib_rostest_test_rostest_autosave_resume.test PROPERTIES
  FIXTURES_REQUIRED autosave_dir ENVIRONMENT "BOARD_CALIB_AUTOSAVE_DIR=${BOARD_CALIB_AUTOSAVE_DIR}")

# The issue-15 crashing messages into the running detectors and projection: the manager survives.
add_rostest(test/rostest/hostile_messages.test DEPENDENCIES ${BOARD_CALIB_NODELET_LIBS})
