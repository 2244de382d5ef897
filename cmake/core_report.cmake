# Result files, summaries, tables and snippets from solver results.
board_calib_core_module(report src/core/report/report.cpp)
target_link_libraries(bc_report PUBLIC bc_solvers bc_geometry)
