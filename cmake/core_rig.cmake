# Rig description for MSG-Cal (cameras, LiDARs, topics, noise, known extrinsics): YAML loader,
# and the live multi-sensor session (capture of board poses from N camera / M LiDAR streams).
board_calib_core_module(rig
  src/core/rig/rig_config.cpp
  src/core/rig/rig_session.cpp
  src/core/rig/rig_session_io.cpp
  src/core/rig/rig_report.cpp)
target_link_libraries(bc_rig PUBLIC bc_msg_graph bc_session yaml-cpp)
