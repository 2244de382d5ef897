# Solver tests on synthetic features at known ground truth.
board_calib_core_gtest(test_solvers
  SOURCES test/core/test_solvers.cpp
  MODULES bc_solvers bc_geometry)
