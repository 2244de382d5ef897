# Solvers: PPC-Cal, PBPC-Cal, MSG-Cal pairwise (plane to plane), quality figures, robustness to
# random initialisation, and the synthetic-feature generator for tests.
board_calib_core_module(solvers
  src/core/solvers/common.cpp
  src/core/solvers/metrics.cpp
  src/core/solvers/calibrate.cpp
  src/core/solvers/prepared_views.cpp
  src/core/solvers/cluster_solve.cpp
  src/core/solvers/plane_to_plane.cpp
  src/core/solvers/robustness.cpp
  src/core/solvers/covariance.cpp
  src/core/solvers/synthetic_features.cpp)
target_link_libraries(bc_solvers PUBLIC bc_geometry Ceres::ceres)
