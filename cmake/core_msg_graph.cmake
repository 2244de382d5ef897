# MSG-Cal multi-sensor graph: pairwise init, spanning tree, global Ceres solve of every sensor
# pose, loop / stereo consistency, result file; grouping of per-sensor streams into board poses;
# and the synthetic multi-sensor rig generator.
board_calib_core_module(msg_graph
  src/core/msg_graph/msg_graph.cpp
  src/core/msg_graph/pairwise_links.cpp
  src/core/msg_graph/graph_problem.cpp
  src/core/msg_graph/graph_results.cpp
  src/core/msg_graph/msg_session.cpp
  src/core/msg_graph/msg_synthetic.cpp)
target_link_libraries(bc_msg_graph PUBLIC bc_solvers bc_geometry Ceres::ceres)
