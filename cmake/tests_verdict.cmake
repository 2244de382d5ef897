# Consistency, verdict and the pair calibration run (the whole core library: pipeline objects
# reference every detector).
board_calib_core_gtest(test_core_verdict
  SOURCES test/core/test_verdict.cpp
  LIBS board_calib_core)

# Capture and verdict on simulated recordings (moving frames, camera rates 1-30 Hz).
board_calib_core_gtest(test_capture_sim
  SOURCES test/core/test_capture_sim.cpp test/support/sim_session.cpp
  LIBS board_calib_core)
