# Report figures: PNGs written, outlier edges flagged and highlighted, Markdown links.
board_calib_core_gtest(test_report_plots
  SOURCES test/core/test_report_plots.cpp
  MODULES bc_report_plots bc_solvers bc_geometry
  LIBS ${OpenCV_LIBRARIES} opencv_imgcodecs)

# Consistency notes: board size side by side, compensated plane scale quoted compensated.
board_calib_core_gtest(test_report_notes
  SOURCES test/core/test_report_notes.cpp
  MODULES bc_report bc_solvers bc_geometry)
