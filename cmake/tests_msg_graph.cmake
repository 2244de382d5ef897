# MSG graph on a simulated rig at known ground truth (stereo + two LiDARs, 40 poses), and the
# grouping of per-sensor streams into board poses.
board_calib_core_gtest(test_msg_graph
  SOURCES test/core/test_msg_graph.cpp test/core/test_msg_session.cpp
  MODULES bc_msg_graph bc_solvers bc_geometry)
