# Rig YAML loader, and MSG-Cal end to end: simulate the multi-sensor rig bag (fixture), then
# calibrate_bag --config ... --method msg must put every camera<->LiDAR pair within 0.2 deg / 1 cm
# of the simulator's ground truth (the task's acceptance bound; measured 0.15 deg / 2 mm).
board_calib_core_gtest(test_rig_config
  SOURCES test/core/test_rig_config.cpp
  MODULES bc_rig bc_msg_graph bc_session bc_solvers bc_geometry
  LIBS Ceres::ceres yaml-cpp)
board_calib_core_gtest(test_rig_session
  SOURCES test/core/test_rig_session.cpp
  MODULES bc_rig bc_msg_graph bc_session bc_solvers bc_geometry
  LIBS Ceres::ceres yaml-cpp)

if(TARGET simulate_bag AND TARGET calibrate_bag)
  set(_rig_dir ${CMAKE_CURRENT_BINARY_DIR}/test_rig_e2e)
  file(MAKE_DIRECTORY ${_rig_dir})
  add_test(NAME rig_e2e_simulate
    COMMAND $<TARGET_FILE:simulate_bag>
      --scenario ${CMAKE_CURRENT_SOURCE_DIR}/test/data/msg_rig_scenario.yaml
      --out ${_rig_dir}/rig.bag --quiet)
  set_tests_properties(rig_e2e_simulate PROPERTIES FIXTURES_SETUP rig_bag TIMEOUT 120)
  add_test(NAME rig_e2e_calibrate
    COMMAND $<TARGET_FILE:calibrate_bag> --config ${CMAKE_CURRENT_SOURCE_DIR}/config/rigs/multi_rig_apriltag.yaml
      --bag ${_rig_dir}/rig.bag --method msg --truth ${_rig_dir}/rig.truth.yaml --check-truth 0.2 0.01
      --output ${_rig_dir}/result.yaml --report ${_rig_dir}/report --quiet)
  set_tests_properties(rig_e2e_calibrate PROPERTIES FIXTURES_REQUIRED rig_bag TIMEOUT 120)
  # The result file holds every pair; check it independently of the tool's own comparison.
  add_test(NAME rig_e2e_result_file
    COMMAND /usr/bin/python3 ${CMAKE_CURRENT_SOURCE_DIR}/test/check_rig_result.py
      ${_rig_dir}/result.yaml ${_rig_dir}/rig.truth.yaml 0.2 0.01)
  set_tests_properties(rig_e2e_result_file PROPERTIES FIXTURES_REQUIRED rig_bag DEPENDS rig_e2e_calibrate TIMEOUT 30)
  # The offline-only grouping (a pose per stamp group, --capture all): the same limits.
  add_test(NAME rig_e2e_calibrate_all
    COMMAND $<TARGET_FILE:calibrate_bag> --config ${CMAKE_CURRENT_SOURCE_DIR}/config/rigs/multi_rig_apriltag.yaml
      --bag ${_rig_dir}/rig.bag --method msg --capture all --truth ${_rig_dir}/rig.truth.yaml
      --check-truth 0.2 0.01 --quiet)
  set_tests_properties(rig_e2e_calibrate_all PROPERTIES FIXTURES_REQUIRED rig_bag TIMEOUT 120)
endif()
# The rig run (core/pipeline/rig_calibration.h): verdict on a clean rig and the fault sweep.
board_calib_core_gtest(test_rig_calibration
  SOURCES test/core/test_rig_calibration.cpp
  LIBS board_calib_core)
# Live and offline rig entries on the same simulated frames (core/pipeline/rig_pipeline.h).
board_calib_core_gtest(test_rig_pipeline
  SOURCES test/core/test_rig_pipeline.cpp
  LIBS board_calib_core)
