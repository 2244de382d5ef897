# Projection core: maths against CameraModel, culling, z-buffer, drawing, projected-edges check.
board_calib_core_gtest(test_projection
  SOURCES test/core/test_projection.cpp
  MODULES bc_projection bc_geometry
  LIBS ${OpenCV_LIBRARIES})
