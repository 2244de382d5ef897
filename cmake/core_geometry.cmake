# Geometry basics: target description, camera model, transforms, result file.
board_calib_core_module(geometry
  src/core/target.cpp
  src/core/camera_model.cpp
  src/core/transform.cpp
  src/core/result_io.cpp
  src/core/file_io.cpp
  src/core/common/board_geometry.cpp
  src/core/common/edge_association.cpp)
target_link_libraries(bc_geometry PUBLIC yaml-cpp)
