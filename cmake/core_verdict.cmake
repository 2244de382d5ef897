# Consistency of the views before solving, and the verdict (good / doubtful / failed) after.
board_calib_core_module(verdict
  src/core/verdict/consistency.cpp
  src/core/verdict/verdict.cpp)
target_link_libraries(bc_verdict PUBLIC bc_solvers bc_geometry)
