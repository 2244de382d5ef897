# ROS side: the conversions unit, nodelets and command-line tools. Everything here is thin
# wiring around board_calib_core.
include_directories(include)
include_directories(SYSTEM ${catkin_INCLUDE_DIRS} ${EIGEN3_INCLUDE_DIRS} ${PCL_INCLUDE_DIRS} ${OpenCV_INCLUDE_DIRS})

# The one conversions unit where ROS messages meet core types.
add_library(board_calib_ros SHARED src/ros/conversions.cpp src/ros/result_conversions.cpp src/ros/bag_reader.cpp)
target_compile_options(board_calib_ros PRIVATE ${BOARD_CALIB_WARNINGS})
target_link_libraries(board_calib_ros board_calib_core ${catkin_LIBRARIES} ${OpenCV_LIBRARIES})
add_dependencies(board_calib_ros ${PROJECT_NAME}_generate_messages_cpp)

# One shared library per nodelet (src/nodelets/<name>.cpp -> libboard_calib_<name>.so), each
# listed in nodelet_plugins.xml; separate libraries keep compile units small and independent.
set(BOARD_CALIB_NODELET_LIBS)
foreach(nodelet cloud_board_detector image_board_detector calibrator projection)
  if(EXISTS ${CMAKE_CURRENT_SOURCE_DIR}/src/nodelets/${nodelet}.cpp)
    add_library(board_calib_${nodelet} SHARED src/nodelets/${nodelet}.cpp)
    target_compile_options(board_calib_${nodelet} PRIVATE ${BOARD_CALIB_WARNINGS})
    target_link_libraries(board_calib_${nodelet} board_calib_ros board_calib_core ${catkin_LIBRARIES}
      ${OpenCV_LIBRARIES})
    add_dependencies(board_calib_${nodelet} ${PROJECT_NAME}_generate_messages_cpp)
    if(TARGET ${PROJECT_NAME}_gencfg)
      add_dependencies(board_calib_${nodelet} ${PROJECT_NAME}_gencfg)
    endif()
    list(APPEND BOARD_CALIB_NODELET_LIBS board_calib_${nodelet})
  endif()
endforeach()

# Command-line tools (src/tools/<name>.cpp), run with rosrun.
set(BOARD_CALIB_TOOLS)
foreach(tool board_info calibrate_bag simulate_bag publish_calibration rig_bringup bench_solvers bench_lidar_detector bench_image_detector
        bench_projection bench_sim bench_msg_graph bench_capture)
  if(EXISTS ${CMAKE_CURRENT_SOURCE_DIR}/src/tools/${tool}.cpp)
    add_executable(${tool} src/tools/${tool}.cpp)
    target_compile_options(${tool} PRIVATE ${BOARD_CALIB_WARNINGS})
    target_link_libraries(${tool} board_calib_ros board_calib_core ${catkin_LIBRARIES} ${OpenCV_LIBRARIES})
    add_dependencies(${tool} ${PROJECT_NAME}_generate_messages_cpp)
    list(APPEND BOARD_CALIB_TOOLS ${tool})
  endif()
endforeach()

install(TARGETS board_calib_core board_calib_ros ${BOARD_CALIB_NODELET_LIBS}
  ARCHIVE DESTINATION ${CATKIN_PACKAGE_LIB_DESTINATION}
  LIBRARY DESTINATION ${CATKIN_PACKAGE_LIB_DESTINATION}
  RUNTIME DESTINATION ${CATKIN_GLOBAL_BIN_DESTINATION})
if(BOARD_CALIB_TOOLS)
  install(TARGETS ${BOARD_CALIB_TOOLS} RUNTIME DESTINATION ${CATKIN_PACKAGE_BIN_DESTINATION})
endif()

# Multi-sensor rig mode of the calibrator nodelet (~rig_file).
if(TARGET board_calib_calibrator)
  target_sources(board_calib_calibrator PRIVATE src/nodelets/calibrator_rig_mode.cpp)
endif()

# The capture benchmark runs simulated sessions through the test support's driver.
if(TARGET bench_capture)
  target_sources(bench_capture PRIVATE test/support/sim_session.cpp)
  target_include_directories(bench_capture PRIVATE ${CMAKE_CURRENT_SOURCE_DIR}/test)
  target_compile_definitions(bench_capture PRIVATE BOARD_CALIB_SOURCE_DIR="${CMAKE_CURRENT_SOURCE_DIR}")
endif()

# Multi-sensor rig mode of calibrate_bag (--config RIG.yaml --method msg).
if(TARGET calibrate_bag)
  target_sources(calibrate_bag PRIVATE src/tools/calibrate_rig.cpp)
endif()
