# Projection core: maths against CameraModel, culling, z-buffer, drawing, projected-edges check;
# the one edge association shared by the overlay and the solvers.
board_calib_core_gtest(test_projection
  SOURCES test/core/test_projection.cpp test/core/test_edge_association.cpp
  MODULES bc_projection bc_solvers bc_geometry
  LIBS ${OpenCV_LIBRARIES})

# Overlay on simulated data: projected LiDAR edge points land on the rendered board edges.
board_calib_core_gtest(test_projection_sim
  SOURCES test/core/test_projection_sim.cpp
  MODULES bc_projection bc_sim bc_geometry
  LIBS ${OpenCV_LIBRARIES} opencv_imgcodecs)  # imgcodecs: the overlay is saved for a look

# The projected-edges check against the independent MLRE tool on real reference features.
board_calib_core_gtest(test_projection_real
  SOURCES test/core/test_projection_real.cpp
  MODULES bc_projection bc_geometry
  LIBS ${OpenCV_LIBRARIES} yaml-cpp)
