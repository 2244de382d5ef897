# Camera board detector: plain board (edges), checkerboard, AprilTag grid.
board_calib_core_module(image_detection
  src/core/image_detection/image_board_detector.cpp
  src/core/image_detection/common.cpp
  src/core/image_detection/plain_detector.cpp
  src/core/image_detection/plain_regions.cpp
  src/core/image_detection/plain_edges.cpp
  src/core/image_detection/plain_candidate.cpp
  src/core/image_detection/line_hypotheses.cpp
  src/core/image_detection/checkerboard_detector.cpp)
target_include_directories(bc_image_detection SYSTEM PUBLIC ${OpenCV_INCLUDE_DIRS})
target_link_libraries(bc_image_detection PUBLIC bc_geometry opencv_core opencv_imgproc opencv_calib3d opencv_features2d
  apriltag::apriltag)
