// SPDX-License-Identifier: BSD-3-Clause
// Shared by the scenario reader and its clutter generator. Internal to the sim module.
#pragma once

#include <board_calib/core/sim/scenario.h>

#include <Eigen/Geometry>

#include <random>

namespace board_calib {
namespace sim {
namespace internal {

/// Panel orientation: with rpy 0 it stands upright facing the rig (normal along world +x, x to
/// world -y, y down), like the board; roll turns it in its plane.
Eigen::Matrix3d facingRig();

/// n random printed marks on the board (scene.board_marks).
void addRandomMarks(int n, std::mt19937& rng, SceneSpec* scene);

/// Posters, screens, cabinets and doors on the walls (facades outdoors) and free-standing panels
/// away from where the board is held (beyond the farthest pose or outside the motion's cone), so
/// they never hide it; the pose sampler checks the lines of sight anyway.
void addRandomPanels(const Scenario& s, int n, std::mt19937& rng, SceneSpec* scene);

}  // namespace internal
}  // namespace sim
}  // namespace board_calib
