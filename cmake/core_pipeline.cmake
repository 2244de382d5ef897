# Offline pipeline: detectors + session without ROS (calibrate_bag and end-to-end core tests).
board_calib_core_module(pipeline src/core/pipeline/pipeline.cpp src/core/pipeline/pair_calibration.cpp
  src/core/pipeline/pair_report.cpp src/core/pipeline/rig_pipeline.cpp src/core/pipeline/rig_calibration.cpp)
target_link_libraries(bc_pipeline PUBLIC bc_rig bc_msg_graph bc_session bc_image_detection bc_lidar_detection bc_verdict bc_report bc_report_plots bc_projection bc_geometry)
target_include_directories(bc_pipeline SYSTEM PUBLIC ${OpenCV_INCLUDE_DIRS})
