# Rig description for MSG-Cal (cameras, LiDARs, topics, noise, known extrinsics): YAML loader.
board_calib_core_module(rig
  src/core/rig/rig_config.cpp)
target_link_libraries(bc_rig PUBLIC bc_msg_graph yaml-cpp)
