// SPDX-License-Identifier: BSD-3-Clause
// The simulated world shared by the LiDAR scan and the camera render: a board, a room or street,
// optional panels and a person-like occluder behind the board, cast one ray at a time.
// Internal to the sim module.
#pragma once

#include <board_calib/core/sim/simulator.h>

#include <Eigen/Geometry>

#include <limits>
#include <vector>

namespace board_calib {
namespace sim {
namespace internal {

constexpr double kPi = 3.14159265358979323846;
constexpr double kDegToRad = kPi / 180.0;

// Labels: surface class per camera sample; a change between neighbours marks an edge pixel.
enum Label : int {
  kLabelNone = 0,
  kLabelFloor = 1,
  kLabelCeiling = 2,
  kLabelWall = 3,  // + wall index 0..3
  kLabelPerson = 8,
  kLabelBoardWhite = 9,
  kLabelBoardBlack = 10,
  kLabelBoardBack = 11,
  kLabelPanel = 32,  // + panel index
};

struct Hit {
  double t = std::numeric_limits<double>::infinity();
  int label = kLabelNone;
  Eigen::Vector3d normal = Eigen::Vector3d::Zero();  // world, unit
  Eigen::Vector3d point = Eigen::Vector3d::Zero();   // world
  bool valid() const { return label != kLabelNone; }
  bool board() const { return label >= kLabelBoardWhite && label <= kLabelBoardBack; }
};

// The scene in the world frame, prepared once per render / scan.
class Scene {
 public:
  Scene(const SceneSpec& spec, const Eigen::Isometry3d& world_T_board);

  Hit cast(const Eigen::Vector3d& origin, const Eigen::Vector3d& dir) const;

  // Colour (BGR, 0..1) of a hit as a camera sees it; `dir` is the viewing ray. The room is
  // piecewise flat (panels, tiles): realistic straight clutter for line detectors, and
  // noise-free images compress well in bags.
  Eigen::Vector3d shade(const Hit& hit, const Eigen::Vector3d& dir) const;

  // Colour where a camera ray hits nothing: the sky outdoors, black otherwise.
  Eigen::Vector3d sky() const {
    return spec_.outdoor ? Eigen::Vector3d(0.95, 0.85, 0.75) : Eigen::Vector3d::Zero();
  }

  // LiDAR reflectivity in intensity units.
  double reflectivity(const Hit& hit) const;

 private:
  void placePerson();
  // Grey level and BGR tint of one surface class at world point p.
  double boardGrey(const Hit& hit, const Eigen::Vector3d& dir, Eigen::Vector3d* tint) const;
  double floorGrey(const Eigen::Vector3d& p, Eigen::Vector3d* tint) const;
  double wallGrey(const Hit& hit, Eigen::Vector3d* tint) const;

  void castBoard(const Eigen::Vector3d& origin, const Eigen::Vector3d& dir, Hit* best) const;
  void castPerson(const Eigen::Vector3d& origin, const Eigen::Vector3d& dir, Hit* best) const;
  void castPanel(size_t k, const Eigen::Vector3d& origin, const Eigen::Vector3d& dir,
                 Hit* best) const;
  void castRoom(const Eigen::Vector3d& origin, const Eigen::Vector3d& dir, Hit* best) const;

  const SceneSpec& spec_;
  Eigen::Isometry3d world_T_board_;
  Eigen::Isometry3d board_T_world_;
  Eigen::Vector3d board_normal_;
  Eigen::Vector3d board_origin_;
  std::vector<Eigen::Isometry3d> panels_;  // panel_T_world per panel
  Eigen::Isometry3d person_T_world_ = Eigen::Isometry3d::Identity();
  Eigen::Matrix3d person_rotation_ = Eigen::Matrix3d::Identity();
  double person_half_height_ = 0.0;
};

}  // namespace internal
}  // namespace sim
}  // namespace board_calib
