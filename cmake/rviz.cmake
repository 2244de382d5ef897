# The rviz calibration panel (src/rviz): one Qt 5 plugin library listed in rviz_plugins.xml.
# Only light headers (rviz/panel.h, Qt widgets, messages): no PCL, Ceres or OGRE work here.
find_package(rviz REQUIRED)
find_package(Qt5 REQUIRED COMPONENTS Widgets)

add_library(board_calib_rviz SHARED src/rviz/calibration_panel.cpp src/rviz/calibration_panel.h)
set_target_properties(board_calib_rviz PROPERTIES AUTOMOC ON)
target_compile_options(board_calib_rviz PRIVATE ${BOARD_CALIB_WARNINGS})
target_include_directories(board_calib_rviz SYSTEM PRIVATE ${rviz_INCLUDE_DIRS})
target_link_libraries(board_calib_rviz ${rviz_LIBRARIES} ${catkin_LIBRARIES} Qt5::Widgets)
add_dependencies(board_calib_rviz ${PROJECT_NAME}_generate_messages_cpp)

install(TARGETS board_calib_rviz LIBRARY DESTINATION ${CATKIN_PACKAGE_LIB_DESTINATION})
install(FILES rviz_plugins.xml DESTINATION ${CATKIN_PACKAGE_SHARE_DESTINATION})

# Headless: rviz under Xvfb with the shipped config, the panel clicked through with xdotool
# against a fake calibrator (every service call checked) and the real calibrator nodelet.
# Screenshot: <build>/rviz_panel_check/panel.png. Exit code 77 (rviz, xvfb-run or xdotool
# missing) counts as skipped.
if(CATKIN_ENABLE_TESTING)
  add_test(NAME rviz_panel_check
    COMMAND /usr/bin/python3 ${CMAKE_CURRENT_SOURCE_DIR}/test/rviz_panel_check.py
            ${CMAKE_CURRENT_SOURCE_DIR}/rviz/calibration.rviz ${CMAKE_BINARY_DIR}/rviz_panel_check
            ${CATKIN_DEVEL_PREFIX}/setup.bash)
  set_tests_properties(rviz_panel_check PROPERTIES SKIP_RETURN_CODE 77 TIMEOUT 240)
endif()
