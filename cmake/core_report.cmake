# Result files, summaries, tables and snippets from solver results.
board_calib_core_module(report src/core/report/report.cpp)
target_link_libraries(bc_report PUBLIC bc_solvers bc_geometry)

# Report figures (PNG charts drawn with OpenCV) and the Markdown section linking them.
board_calib_core_module(report_plots src/core/report/plots.cpp)
target_include_directories(bc_report_plots SYSTEM PUBLIC ${OpenCV_INCLUDE_DIRS})
target_link_libraries(bc_report_plots PUBLIC bc_solvers bc_geometry ${OpenCV_LIBRARIES} opencv_imgcodecs)
