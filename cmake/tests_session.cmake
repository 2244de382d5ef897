board_calib_core_gtest(test_core_session
  SOURCES test/core/test_session.cpp
  MODULES bc_session bc_geometry)
