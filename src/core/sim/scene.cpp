// SPDX-License-Identifier: BSD-3-Clause
// The simulated world: ray casting against the board, the person-like occluder, panels and
// the room or street, and the surfaces' appearance for cameras and LiDARs.
#include "scene.h"

#include <apriltag/apriltag.h>
#include <apriltag/tag36h11.h>

#include <algorithm>
#include <cmath>

namespace board_calib {
namespace sim {
namespace internal {
namespace {

constexpr double kRayEpsilon = 1e-9;  // m, ignore hits at the ray origin

// Person-like occluder: a box standing on the floor behind the board's centre.
constexpr double kPersonHalfWidth = 0.22;  // m, shoulder half width
constexpr double kPersonHalfDepth = 0.14;  // m
constexpr double kPersonBehindBoard =
    0.25;  // m, body centre behind the board centre (horizontal), at least
constexpr double kPersonMaxBehind = 2.0;  // m
constexpr double kPersonStep = 0.05;      // m
constexpr double kPersonClearance =
    0.15;  // m, body behind the board's plane: a held board is at arm's length

// Room texture.
constexpr double kFloorTile = 0.6;         // m, tile size on the floor
constexpr double kGroutWidth = 0.01;       // m
constexpr double kWallPanelWidth = 1.2;    // m
constexpr double kWallPanelHeight = 0.8;   // m
constexpr double kSeamFraction = 0.02;     // of a panel, dark seams between panels
constexpr double kPosterThreshold = 0.85;  // panels above this hash are coloured posters
// Outdoor texture: paving slabs, facades with storeys of windows, sky.
constexpr double kPavingSlab = 0.5;       // m
constexpr double kPavingGroutGrey = 0.7;  // grout albedo relative to the pavement's
constexpr double kPavingVariation = 0.2;  // relative albedo spread between slabs
constexpr double kFacadeHeight = 15.0;    // m above the ground; above it the sky
constexpr double kFacadeBay = 3.0;        // m, window pitch along a facade and between storeys
constexpr double kWindowLo = 0.6, kWindowHi = 2.4;  // m, window extent inside a bay (both axes)
constexpr double kWindowGrey = 0.12;
// Board face grain (cardboard, wood): streaks along board x.
constexpr double kGrainAlong = 0.04;    // m
constexpr double kGrainAcross = 0.004;  // m

// Surface appearance (linear grey levels 0..1).
constexpr double kBoardWhite = 0.86;
constexpr double kBoardBlack = 0.08;
constexpr double kBoardBack = 0.45;
constexpr double kBlackReflectivity = 0.25;  // LiDAR intensity of printed black relative to white
constexpr double kBoardFacingMin = 0.85;     // brightness of the board at grazing view
constexpr double kBoardAmbient = 0.85;  // the board is lit mostly evenly (light, slightly shaded)
constexpr double kAmbient = 0.55;
constexpr double kDiffuse = 0.45;

// tag36h11 bitmaps (black/white cells incl. the white border ring), created once.
class TagBitmaps {
 public:
  static const TagBitmaps& instance() {
    static TagBitmaps bitmaps;
    return bitmaps;
  }
  int totalWidth() const { return total_width_; }
  int widthAtBorder() const { return width_at_border_; }
  int codes() const { return static_cast<int>(bitmaps_.size()); }
  // True for a black cell.
  bool black(int id, int cx, int cy) const {
    return bitmaps_[id][static_cast<size_t>(cy * total_width_ + cx)] == 0;
  }

 private:
  TagBitmaps() {
    apriltag_family_t* family = tag36h11_create();
    total_width_ = family->total_width;
    width_at_border_ = family->width_at_border;
    bitmaps_.resize(family->ncodes);
    for (uint32_t id = 0; id < family->ncodes; ++id) {
      image_u8_t* image = apriltag_to_image(family, static_cast<int>(id));
      auto& bits = bitmaps_[id];
      bits.resize(static_cast<size_t>(total_width_ * total_width_));
      for (int y = 0; y < total_width_; ++y)
        for (int x = 0; x < total_width_; ++x)
          bits[static_cast<size_t>(y * total_width_ + x)] = image->buf[y * image->stride + x];
      image_u8_destroy(image);
    }
    tag36h11_destroy(family);
  }
  int total_width_ = 0;
  int width_at_border_ = 0;
  std::vector<std::vector<uint8_t>> bitmaps_;
};

// Printed colour of the board face at board coordinates (x, y): true for black.
bool boardBlackAt(const Target& target, double x, double y) {
  switch (target.type) {
    case TargetType::kPlain: return false;
    case TargetType::kCheckerboard: {
      const auto& cb = target.checkerboard;
      // (cols + 1) x (rows + 1) squares; the first inner corner sits one square in.
      const double fx = (x - (cb.origin.x() - cb.square)) / cb.square;
      const double fy = (y - (cb.origin.y() - cb.square)) / cb.square;
      if (fx < 0 || fy < 0 || fx >= cb.cols + 1 || fy >= cb.rows + 1) return false;
      return ((static_cast<int>(fx) + static_cast<int>(fy)) % 2) == 0;
    }
    case TargetType::kAprilTagGrid: {
      const auto& g = target.apriltag_grid;
      const TagBitmaps& tags = TagBitmaps::instance();
      const double pitch = g.tag_size + g.spacing;
      const double cell = g.tag_size / tags.widthAtBorder();
      const int border_cells = (tags.totalWidth() - tags.widthAtBorder()) / 2;
      const double lx = x - g.origin.x(), ly = y - g.origin.y();
      if (lx < 0 || ly < 0) return false;
      const int c = static_cast<int>(lx / pitch), r = static_cast<int>(ly / pitch);
      if (c >= g.cols || r >= g.rows) return false;
      const double tx = lx - c * pitch, ty = ly - r * pitch;
      if (tx >= g.tag_size || ty >= g.tag_size) return false;
      const int id = g.first_id + r * g.cols + c;
      if (id < 0 || id >= tags.codes()) return false;
      const int cx = std::min(static_cast<int>(tx / cell), tags.widthAtBorder() - 1) + border_cells;
      const int cy = std::min(static_cast<int>(ty / cell), tags.widthAtBorder() - 1) + border_cells;
      return tags.black(id, cx, cy);
    }
  }
  return false;
}

// Pseudo-random value in [0, 1] per integer lattice cell (per-tile brightness).
double hash01(int64_t x, int64_t y, int64_t z) {
  uint64_t h = static_cast<uint64_t>(x) * 0x9E3779B97F4A7C15ULL ^
               static_cast<uint64_t>(y) * 0xC2B2AE3D27D4EB4FULL ^
               static_cast<uint64_t>(z) * 0x165667B19E3779F9ULL;
  h ^= h >> 29;
  h *= 0xBF58476D1CE4E5B9ULL;
  h ^= h >> 32;
  return static_cast<double>(h & 0xFFFFFF) / static_cast<double>(0xFFFFFF);
}

}  // namespace

Scene::Scene(const SceneSpec& spec, const Eigen::Isometry3d& world_T_board)
    : spec_(spec), world_T_board_(world_T_board), board_T_world_(world_T_board.inverse()) {
  for (const auto& panel : spec.panels) panels_.push_back(panel.world_T_panel.inverse());
  board_normal_ = world_T_board.linear().col(2);
  board_origin_ = world_T_board.translation();
  if (spec.occluder) placePerson();
}

// A box standing on the floor behind the board's centre, reaching up to it.
void Scene::placePerson() {
  const SceneSpec& spec = spec_;
  const Eigen::Isometry3d& world_T_board = world_T_board_;
  const Eigen::Vector3d centre = world_T_board * spec.target.center();
  Eigen::Vector3d back(board_normal_.x(), board_normal_.y(), 0.0);
  if (back.norm() < 1e-6) back = Eigen::Vector3d::UnitX();
  back.normalize();
  Eigen::Matrix3d rotation;
  rotation.col(0) = back;
  rotation.col(2) = Eigen::Vector3d::UnitZ();
  rotation.col(1) = rotation.col(2).cross(rotation.col(0));
  const double top = centre.z();
  person_half_height_ = std::max(0.0, (top - spec.floor_z_m) / 2);
  // Step back until the body, where it overlaps the board's height, is behind the board's
  // plane (a tilted board leans forward or back by up to ~0.3 m).
  double lowest = top;
  for (const auto& corner : spec.target.outerCorners())
    lowest = std::min(lowest, (world_T_board * corner).z());
  Eigen::Vector3d person_centre;
  for (double behind = kPersonBehindBoard; behind < kPersonMaxBehind; behind += kPersonStep) {
    person_centre = Eigen::Vector3d(centre.x() + behind * back.x(), centre.y() + behind * back.y(),
                                    spec.floor_z_m + person_half_height_);
    bool clear = true;
    for (int k = 0; k < 8 && clear; ++k) {
      const Eigen::Vector3d local((k & 1 ? 1 : -1) * kPersonHalfDepth,
                                  (k & 2 ? 1 : -1) * kPersonHalfWidth, 0.0);
      Eigen::Vector3d corner = person_centre + rotation * local;
      corner.z() = (k & 4) ? top : std::max(lowest, spec.floor_z_m);
      clear = board_normal_.dot(corner - board_origin_) > kPersonClearance;
    }
    if (clear) break;
  }
  person_T_world_ = Eigen::Isometry3d::Identity();
  person_T_world_.linear() = rotation.transpose();
  person_T_world_.translation() = -(rotation.transpose() * person_centre);
  person_rotation_ = rotation;
}

Hit Scene::cast(const Eigen::Vector3d& origin, const Eigen::Vector3d& dir) const {
  Hit best;
  castBoard(origin, dir, &best);
  if (spec_.occluder && person_half_height_ > 0) castPerson(origin, dir, &best);
  for (size_t k = 0; k < panels_.size(); ++k) castPanel(k, origin, dir, &best);
  if (spec_.outdoor || spec_.room) castRoom(origin, dir, &best);
  if (best.valid()) best.point = origin + best.t * dir;
  return best;
}

Eigen::Vector3d Scene::shade(const Hit& hit, const Eigen::Vector3d& dir) const {
  // Light from above and slightly from the side: soft, so edges stay photometric.
  const Eigen::Vector3d light = Eigen::Vector3d(0.3, 0.2, 1.0).normalized();
  const double lambert = std::abs(hit.normal.dot(light));
  const bool board = hit.board();
  const double shading =
      board ? kBoardAmbient + (1 - kBoardAmbient) * lambert : kAmbient + kDiffuse * lambert;
  double grey = 0.5;
  Eigen::Vector3d tint(1.0, 1.0, 1.0);  // b, g, r
  switch (hit.label) {
    case kLabelBoardWhite:
    case kLabelBoardBlack: grey = boardGrey(hit, dir, &tint); break;
    case kLabelBoardBack: grey = kBoardBack; break;
    case kLabelPerson: {
      grey = 0.3;
      tint = {1.3, 0.95, 0.75};  // blue clothes
      break;
    }
    case kLabelFloor: grey = floorGrey(hit.point, &tint); break;
    case kLabelCeiling: grey = 0.8; break;
    default: grey = wallGrey(hit, &tint);
  }
  return grey * shading * tint;
}

double Scene::boardGrey(const Hit& hit, const Eigen::Vector3d& dir, Eigen::Vector3d* tint) const {
  // Slightly darker at grazing views (matte print): a smooth gradient over the board.
  const double facing = std::abs(hit.normal.dot(dir));
  double grey = (hit.label == kLabelBoardWhite ? spec_.board_grey : kBoardBlack) *
                (kBoardFacingMin + (1 - kBoardFacingMin) * facing);
  if (hit.label == kLabelBoardWhite) {
    *tint = spec_.board_tint;
    if (spec_.board_texture > 0) {
      const Eigen::Vector3d q = board_T_world_ * hit.point;
      const double h = hash01(static_cast<int64_t>(std::floor(q.x() / kGrainAlong)),
                              static_cast<int64_t>(std::floor(q.y() / kGrainAcross)), 5);
      grey *= 1.0 + spec_.board_texture * (2 * h - 1);
    }
  }
  return grey;
}

double Scene::floorGrey(const Eigen::Vector3d& p, Eigen::Vector3d* tint) const {
  if (spec_.outdoor) {  // paving slabs around the configured pavement brightness
    const double gx = p.x() / kPavingSlab, gy = p.y() / kPavingSlab;
    const double fx = gx - std::floor(gx), fy = gy - std::floor(gy);
    const double grout = kGroutWidth / kPavingSlab;
    const double h =
        hash01(static_cast<int64_t>(std::floor(gx)), static_cast<int64_t>(std::floor(gy)), 2);
    return spec_.ground_grey *
           ((fx < grout || fy < grout) ? kPavingGroutGrey : 1.0 + kPavingVariation * (h - 0.5));
  }
  const double gx = p.x() / kFloorTile, gy = p.y() / kFloorTile;
  const double fx = gx - std::floor(gx), fy = gy - std::floor(gy);
  const double grout = kGroutWidth / kFloorTile;
  *tint = {0.85, 0.95, 1.1};
  if (fx < grout || fy < grout) return 0.22;
  return 0.38 + 0.2 * hash01(static_cast<int64_t>(std::floor(gx)),
                             static_cast<int64_t>(std::floor(gy)), 1);
}

// Panels, facades (outdoors) and room walls.
double Scene::wallGrey(const Hit& hit, Eigen::Vector3d* tint) const {
  const Eigen::Vector3d& p = hit.point;
  if (hit.label >= kLabelPanel) {
    const Panel& panel = spec_.panels[static_cast<size_t>(hit.label - kLabelPanel)];
    *tint = panel.tint;
    return panel.grey;
  }
  if (spec_.outdoor) {  // facades: storeys of dark windows, per-building wall brightness
    const double s = std::abs(hit.normal.x()) > 0.5 ? p.y() : p.x();
    const double gu = s / kFacadeBay, gv = (p.z() - spec_.floor_z_m) / kFacadeBay;
    const double fu = (gu - std::floor(gu)) * kFacadeBay, fv = (gv - std::floor(gv)) * kFacadeBay;
    const bool window =
        fu > kWindowLo && fu < kWindowHi && fv > kWindowLo && fv < kWindowHi && gv >= 1;
    if (window) *tint = {1.2, 1.0, 0.9};
    return window ? kWindowGrey
                  : 0.45 + 0.3 * hash01(static_cast<int64_t>(std::floor(gu / 4)), 0, 7 + hit.label);
  }
  // walls: panels of random brightness with dark seams, some posters
  const double s = std::abs(hit.normal.x()) > 0.5 ? p.y() : p.x();
  const double gu = s / kWallPanelWidth, gv = (p.z() - spec_.floor_z_m) / kWallPanelHeight;
  const double fu = gu - std::floor(gu), fv = gv - std::floor(gv);
  const int64_t iu = static_cast<int64_t>(std::floor(gu)),
                iv = static_cast<int64_t>(std::floor(gv));
  double grey = 0.25;
  if (!(fu < kSeamFraction || fv < kSeamFraction)) {
    const double h = hash01(iu, iv, 3 + hit.label);
    grey = 0.4 + 0.35 * h;
    if (h > kPosterThreshold)
      *tint = {0.7 + 0.6 * hash01(iu, iv, 17), 0.8, 0.7 + 0.6 * hash01(iu, iv, 23)};
  }
  *tint = tint->cwiseProduct(Eigen::Vector3d(0.9 + 0.05 * (hit.label - kLabelWall), 1.0, 1.05));
  return grey;
}

double Scene::reflectivity(const Hit& hit) const {
  switch (hit.label) {
    case kLabelBoardWhite: return spec_.board_intensity;
    case kLabelBoardBlack: return spec_.board_intensity * kBlackReflectivity;
    case kLabelBoardBack: return spec_.board_intensity * 0.5;
    default:
      if (hit.label >= kLabelPanel)
        return spec_.panels[static_cast<size_t>(hit.label - kLabelPanel)].intensity;
      return spec_.background_intensity;
  }
}

void Scene::castBoard(const Eigen::Vector3d& origin, const Eigen::Vector3d& dir, Hit* best) const {
  const double denom = board_normal_.dot(dir);
  if (std::abs(denom) < 1e-12) return;
  const double t = board_normal_.dot(board_origin_ - origin) / denom;
  if (t <= kRayEpsilon || t >= best->t) return;
  const Eigen::Vector3d p_board = board_T_world_ * (origin + t * dir);
  const Target& target = spec_.target;
  if (p_board.x() < 0 || p_board.y() < 0 || p_board.x() >= target.width ||
      p_board.y() >= target.height)
    return;
  best->t = t;
  best->normal = board_normal_;
  if (denom > 0) {  // ray travels along +z: seen from -z, the printed face
    bool black = boardBlackAt(target, p_board.x(), p_board.y());
    for (const auto& mark : spec_.board_marks)
      black = black || (p_board.x() >= mark.min.x() && p_board.x() < mark.max.x() &&
                        p_board.y() >= mark.min.y() && p_board.y() < mark.max.y());
    best->label = black ? kLabelBoardBlack : kLabelBoardWhite;
  } else {
    best->label = kLabelBoardBack;
  }
}

void Scene::castPerson(const Eigen::Vector3d& origin, const Eigen::Vector3d& dir, Hit* best) const {
  const Eigen::Vector3d o = person_T_world_ * origin;
  const Eigen::Vector3d d = person_T_world_.linear() * dir;
  const Eigen::Vector3d half(kPersonHalfDepth, kPersonHalfWidth, person_half_height_);
  double t_near = -std::numeric_limits<double>::infinity(),
         t_far = std::numeric_limits<double>::infinity();
  int axis_near = -1;
  for (int a = 0; a < 3; ++a) {
    if (std::abs(d[a]) < 1e-15) {
      if (o[a] < -half[a] || o[a] > half[a]) return;
      continue;
    }
    double t0 = (-half[a] - o[a]) / d[a], t1 = (half[a] - o[a]) / d[a];
    if (t0 > t1) std::swap(t0, t1);
    if (t0 > t_near) {
      t_near = t0;
      axis_near = a;
    }
    t_far = std::min(t_far, t1);
  }
  if (t_near > t_far || t_near <= kRayEpsilon || t_near >= best->t || axis_near < 0) return;
  best->t = t_near;
  best->label = kLabelPerson;
  Eigen::Vector3d n_local = Eigen::Vector3d::Zero();
  n_local[axis_near] = d[axis_near] > 0 ? -1.0 : 1.0;
  best->normal = person_rotation_ * n_local;
}

void Scene::castPanel(size_t k, const Eigen::Vector3d& origin, const Eigen::Vector3d& dir,
                      Hit* best) const {
  const Panel& panel = spec_.panels[k];
  const Eigen::Vector3d o = panels_[k] * origin;
  const Eigen::Vector3d d = panels_[k].linear() * dir;
  if (std::abs(d.z()) < 1e-12) return;
  const double t = -o.z() / d.z();
  if (t <= kRayEpsilon || t >= best->t) return;
  const Eigen::Vector3d q = o + t * d;
  if (std::abs(q.x()) > 0.5 * panel.width_m || std::abs(q.y()) > 0.5 * panel.height_m) return;
  best->t = t;
  best->label = kLabelPanel + static_cast<int>(k);
  best->normal = panel.world_T_panel.linear().col(2);
}

void Scene::castRoom(const Eigen::Vector3d& origin, const Eigen::Vector3d& dir, Hit* best) const {
  const double inf = std::numeric_limits<double>::infinity();
  const double half_x = spec_.outdoor ? spec_.facade_distance_m : spec_.room_half_size_m;
  const double half_y = spec_.outdoor ? spec_.street_half_width_m : spec_.room_half_size_m;
  // Inside an axis-aligned box: the exit distance along each axis (outdoors no ceiling).
  const double bounds_lo[3] = {-half_x, -half_y, spec_.floor_z_m};
  const double bounds_hi[3] = {half_x, half_y, spec_.outdoor ? inf : spec_.ceiling_z_m};
  double t_exit = std::numeric_limits<double>::infinity();
  int face = -1;
  for (int a = 0; a < 3; ++a) {
    if (std::abs(dir[a]) < 1e-15) continue;
    const double bound = dir[a] > 0 ? bounds_hi[a] : bounds_lo[a];
    const double t = (bound - origin[a]) / dir[a];
    if (t > kRayEpsilon && t < t_exit) {
      t_exit = t;
      face = a * 2 + (dir[a] > 0 ? 1 : 0);
    }
  }
  if (face < 0 || t_exit >= best->t) return;
  if (spec_.outdoor && face < 4 && origin.z() + t_exit * dir.z() > spec_.floor_z_m + kFacadeHeight)
    return;  // sky
  best->t = t_exit;
  const int axis = face / 2;
  best->normal = Eigen::Vector3d::Zero();
  best->normal[axis] = (face % 2) ? -1.0 : 1.0;
  if (axis == 2) {
    best->label = (face % 2) ? kLabelCeiling : kLabelFloor;
  } else {
    best->label = kLabelWall + face;
  }
}
}  // namespace internal
}  // namespace sim
}  // namespace board_calib
