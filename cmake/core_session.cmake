# Calibration session: association, gating, coverage advice, save/load.
board_calib_core_module(session
  src/core/capture/stillness.cpp
  src/core/session/session.cpp
  src/core/session/session_io.cpp
  src/core/session/feature_yaml.cpp)
target_link_libraries(bc_session PUBLIC bc_geometry yaml-cpp)
