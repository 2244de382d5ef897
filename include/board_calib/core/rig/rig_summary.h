// Text summary of an MSG-Cal rig solve, shared by `calibrate_bag --config` and the calibrator
// nodelet's rig mode. ROS-free.
#pragma once

#include <board_calib/core/msg_graph/msg_graph.h>
#include <board_calib/core/result_io.h>
#include <board_calib/core/rig/rig_config.h>

#include <string>

namespace board_calib {

/// Every sensor pose with its 1 sigma, every camera <- LiDAR pair with its MLRE, the loop
/// consistency, the graph residuals, the consistency with each known extrinsic of the rig
/// (a stereo pair: the paper's factory-stereo check) and the solver's notes. `solution` must
/// be successful and use the rig's sensor order.
std::string rigSolutionSummary(const RigConfig& rig, const multi_sensor::MsgSolution& solution,
                               const ResultFile& result);

/// "t [x, y, z] m, q_xyzw [qx, qy, qz, qw]".
std::string poseLine(const Eigen::Isometry3d& T);

}  // namespace board_calib
