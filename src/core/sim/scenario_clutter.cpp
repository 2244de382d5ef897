// SPDX-License-Identifier: BSD-3-Clause
// Seeded clutter of a scenario: printed marks on the board, and posters, screens, cabinets,
// doors and free-standing panels around it.
#include "scenario_internal.h"

#include <board_calib/core/transform.h>

#include <algorithm>
#include <cmath>

namespace board_calib {
namespace sim {
namespace internal {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kPosterSizeMin = 0.8, kPosterSizeMax = 1.3;  // of the board's sides: board-sized
constexpr double kPosterStandoffMin = 0.02,
                 kPosterStandoffMax = 0.3;             // m off the wall (poster .. screen, cabinet)
constexpr double kDoorWidth = 0.9, kDoorHeight = 2.0;  // m
constexpr double kDoorFraction = 0.2;                  // of the wall panels
constexpr double kFreeStandingFraction = 0.4;
constexpr double kDiamondFraction = 0.3;  // of the free-standing panels: rolled like a held board
constexpr double kClutterClearance =
    1.5;  // m beyond the farthest board pose / off the motion's cone (plus 15 deg)
constexpr double kClutterConeMarginDeg = 15.0;
constexpr double kFacadeClutterReach =
    30.0;  // m along a facade from the rig (the LiDAR's useful range)
constexpr int kClutterAttempts = 200;
constexpr double kMarkInset = 0.06;  // m, marks stay this far inside the board's edges
constexpr double kMarkMinW = 0.02, kMarkMaxW = 0.12, kMarkMinH = 0.01, kMarkMaxH = 0.05;  // m

double uniformIn(std::mt19937& rng, double lo, double hi) {
  return lo + (hi - lo) * std::uniform_real_distribution<double>(0.0, 1.0)(rng);
}

// Contrast with the surroundings (walls 0.4..0.75): dark or bright, a few tinted; LiDAR
// intensity anywhere from dull to as bright as the board.
void randomLook(std::mt19937& rng, const SceneSpec& scene, Panel* panel) {
  const bool dark = uniformIn(rng, 0, 1) < 0.5;
  panel->grey = dark ? uniformIn(rng, 0.05, 0.25) : uniformIn(rng, 0.8, 0.95);
  if (uniformIn(rng, 0, 1) < 0.3)
    panel->tint = Eigen::Vector3d(uniformIn(rng, 0.6, 1.2), uniformIn(rng, 0.6, 1.2),
                                  uniformIn(rng, 0.6, 1.2));
  panel->intensity =
      static_cast<float>(uniformIn(rng, 0.1, 1.0) * std::max(1.0f, scene.board_intensity));
}

}  // namespace

Eigen::Matrix3d facingRig() {
  Eigen::Matrix3d R;
  R.col(0) = -Eigen::Vector3d::UnitY();
  R.col(1) = -Eigen::Vector3d::UnitZ();
  R.col(2) = Eigen::Vector3d::UnitX();
  return R;
}

void addRandomMarks(int n, std::mt19937& rng, SceneSpec* scene) {
  const Target& t = scene->target;
  for (int i = 0; i < n; ++i) {
    const double w = std::min(uniformIn(rng, kMarkMinW, kMarkMaxW), t.width - 2 * kMarkInset);
    const double h = std::min(uniformIn(rng, kMarkMinH, kMarkMaxH), t.height - 2 * kMarkInset);
    if (w <= 0 || h <= 0) return;  // board too small for marks
    const double x = uniformIn(rng, kMarkInset, t.width - kMarkInset - w);
    const double y = uniformIn(rng, kMarkInset, t.height - kMarkInset - h);
    scene->board_marks.push_back({Eigen::Vector2d(x, y), Eigen::Vector2d(x + w, y + h)});
  }
}

void addRandomPanels(const Scenario& s, int n, std::mt19937& rng, SceneSpec* scene) {
  if (n <= 0 || !(scene->room || scene->outdoor)) return;
  const Target& t = scene->target;
  const double big = std::max(t.width, t.height), small = std::min(t.width, t.height);
  const double half_x = scene->outdoor ? std::min(scene->facade_distance_m, kFacadeClutterReach)
                                       : scene->room_half_size_m;
  const double half_y = scene->outdoor ? scene->street_half_width_m : scene->room_half_size_m;
  const double top = scene->outdoor ? scene->floor_z_m + 6.0 : scene->ceiling_z_m;
  const Eigen::Vector3d rig = s.world_T_rig.translation();
  const Eigen::Vector3d rig_x = s.world_T_rig.linear().col(0);
  for (int i = 0; i < n; ++i) {
    Panel panel;
    randomLook(rng, *scene, &panel);
    const bool free_standing = uniformIn(rng, 0, 1) < kFreeStandingFraction;
    const bool door = !free_standing && uniformIn(rng, 0, 1) < kDoorFraction;
    panel.width_m = door ? kDoorWidth : big * uniformIn(rng, kPosterSizeMin, kPosterSizeMax);
    panel.height_m = door ? kDoorHeight : small * uniformIn(rng, kPosterSizeMin, kPosterSizeMax);
    if (!door && uniformIn(rng, 0, 1) < 0.5) std::swap(panel.width_m, panel.height_m);
    if (!free_standing) {
      // Walls: 0 x-, 1 x+, 2 y-, 3 y+ (outdoors only the side facades along the street).
      // Half of them on the wall the rig faces, so the cameras see clutter around the board too.
      int ahead = std::abs(rig_x.x()) >= std::abs(rig_x.y()) ? (rig_x.x() > 0 ? 1 : 0)
                                                             : (rig_x.y() > 0 ? 3 : 2);
      if (scene->outdoor && ahead < 2) ahead = 2 + static_cast<int>(uniformIn(rng, 0, 2) >= 1);
      const int any = scene->outdoor ? 2 + static_cast<int>(uniformIn(rng, 0, 2) >= 1)
                                     : std::min(3, static_cast<int>(uniformIn(rng, 0, 4)));
      const int wall = uniformIn(rng, 0, 1) < 0.5 ? ahead : any;
      const double standoff =
          door ? -0.05 : uniformIn(rng, kPosterStandoffMin, kPosterStandoffMax);  // doors recessed
      const double along_half = (wall < 2 ? half_y : half_x) - 0.5 * panel.width_m - 0.2;
      if (along_half <= 0) continue;
      const double along = uniformIn(rng, -along_half, along_half);
      const double z_lo = scene->floor_z_m + 0.5 * panel.height_m + (door ? 0.0 : 0.5);
      const double z_hi = std::max(z_lo, top - 0.5 * panel.height_m - 0.1);
      const double z =
          door ? scene->floor_z_m + 0.5 * panel.height_m + 0.005 : uniformIn(rng, z_lo, z_hi);
      Eigen::Vector3d inward = Eigen::Vector3d::Zero();
      inward[wall / 2] = (wall % 2) ? -1.0 : 1.0;
      Eigen::Vector3d centre = Eigen::Vector3d::Zero();
      centre[wall / 2] =
          -inward[wall / 2] * (wall < 2 ? half_x : half_y) + inward[wall / 2] * standoff;
      centre[1 - wall / 2] = along;
      centre.z() = z;
      Eigen::Matrix3d R;
      R.col(2) = -inward;  // normal away from the room's inside, like the board's away from the rig
      R.col(1) = -Eigen::Vector3d::UnitZ();
      R.col(0) = R.col(1).cross(R.col(2));
      panel.world_T_panel = makeTransform(R, centre);
    } else {
      bool placed = false;
      for (int attempt = 0; attempt < kClutterAttempts && !placed; ++attempt) {
        const Eigen::Vector3d c(uniformIn(rng, -half_x + 1.0, half_x - 1.0),
                                uniformIn(rng, -half_y + 1.0, half_y - 1.0), 0.0);
        Eigen::Vector3d d = c - rig;
        d.z() = 0;
        const double r = d.norm();
        const double az = std::acos(std::clamp(d.normalized().dot(rig_x), -1.0, 1.0)) / kRadPerDeg;
        const bool in_cone = az < s.motion.max_azimuth_deg + kClutterConeMarginDeg &&
                             r < s.motion.max_distance_m + kClutterClearance;
        if (r < kClutterClearance || in_cone) continue;
        const double lift = uniformIn(rng, 0.0, 0.8);
        const double yaw = uniformIn(rng, -kPi, kPi);
        const double roll =
            uniformIn(rng, 0, 1) < kDiamondFraction ? uniformIn(rng, 30, 60) * kRadPerDeg : 0.0;
        const Eigen::Matrix3d R = fromRollPitchYaw(Eigen::Vector3d(roll, 0.0, yaw)) * facingRig();
        const double half_height = 0.5 * (std::abs(std::cos(roll)) * panel.height_m +
                                          std::abs(std::sin(roll)) * panel.width_m);
        panel.world_T_panel =
            makeTransform(R, Eigen::Vector3d(c.x(), c.y(), scene->floor_z_m + lift + half_height));
        placed = true;
      }
      if (!placed) continue;
    }
    scene->panels.push_back(panel);
  }
}

}  // namespace internal
}  // namespace sim
}  // namespace board_calib
