// Ray casting of a small scene (board, room, person-like occluder) for cameras and LiDARs.
// Cameras: one ray per pixel centre through a cached per-camera ray map, then supersampling
// only where the surface label changes within the 3x3 neighbourhood, so edges are
// anti-aliased (sub-pixel true) at a fraction of the cost of supersampling everything.
// LiDARs: each beam is a small bundle of sub-rays across its divergence footprint, which
// yields mixed returns where the footprint straddles the board's edge.
#include <board_calib/core/sim/simulator.h>

#include <apriltag/apriltag.h>
#include <apriltag/tag36h11.h>

#include <opencv2/core/utility.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <memory>
#include <mutex>
#include <sstream>

namespace board_calib {
namespace sim {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kDegToRad = kPi / 180.0;
constexpr double kRayEpsilon = 1e-9;  // m, ignore hits at the ray origin

// Person-like occluder: a box standing on the floor behind the board's centre.
constexpr double kPersonHalfWidth = 0.22;   // m, shoulder half width
constexpr double kPersonHalfDepth = 0.14;   // m
constexpr double kPersonBehindBoard = 0.25; // m, body centre behind the board centre (horizontal), at least
constexpr double kPersonMaxBehind = 2.0;    // m
constexpr double kPersonStep = 0.05;        // m
constexpr double kPersonClearance = 0.15;   // m, body behind the board's plane: a held board is at arm's length

// Room texture.
constexpr double kFloorTile = 0.6;          // m, tile size on the floor
constexpr double kGroutWidth = 0.01;        // m
constexpr double kWallPanelWidth = 1.2;     // m
constexpr double kWallPanelHeight = 0.8;    // m
constexpr double kSeamFraction = 0.02;      // of a panel, dark seams between panels
constexpr double kPosterThreshold = 0.85;   // panels above this hash are coloured posters
// Outdoor texture: paving slabs, facades with storeys of windows, sky.
constexpr double kPavingSlab = 0.5;         // m
constexpr double kPavingGroutGrey = 0.7;    // grout albedo relative to the pavement's
constexpr double kPavingVariation = 0.2;    // relative albedo spread between slabs
constexpr double kFacadeHeight = 15.0;      // m above the ground; above it the sky
constexpr double kFacadeBay = 3.0;          // m, window pitch along a facade and between storeys
constexpr double kWindowLo = 0.6, kWindowHi = 2.4;  // m, window extent inside a bay (both axes)
constexpr double kWindowGrey = 0.12;
// Board face grain (cardboard, wood): streaks along board x.
constexpr double kGrainAlong = 0.04;        // m
constexpr double kGrainAcross = 0.004;      // m

// Surface appearance (linear grey levels 0..1).
constexpr double kBoardWhite = 0.86;
constexpr double kBoardBlack = 0.08;
constexpr double kBoardBack = 0.45;
constexpr double kBlackReflectivity = 0.25;  // LiDAR intensity of printed black relative to white
constexpr double kBoardFacingMin = 0.85;   // brightness of the board at grazing view
constexpr double kBoardAmbient = 0.85;     // the board is lit mostly evenly (light, slightly shaded)
constexpr double kAmbient = 0.55;
constexpr double kDiffuse = 0.45;

// Labels: surface class per camera sample; a change between neighbours marks an edge pixel.
enum Label : int {
  kLabelNone = 0,
  kLabelFloor = 1,
  kLabelCeiling = 2,
  kLabelWall = 3,   // + wall index 0..3
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
  uint64_t h = static_cast<uint64_t>(x) * 0x9E3779B97F4A7C15ULL ^ static_cast<uint64_t>(y) * 0xC2B2AE3D27D4EB4FULL ^
               static_cast<uint64_t>(z) * 0x165667B19E3779F9ULL;
  h ^= h >> 29;
  h *= 0xBF58476D1CE4E5B9ULL;
  h ^= h >> 32;
  return static_cast<double>(h & 0xFFFFFF) / static_cast<double>(0xFFFFFF);
}

// The scene in the world frame, prepared once per render / scan.
class Scene {
 public:
  Scene(const SceneSpec& spec, const Eigen::Isometry3d& world_T_board)
      : spec_(spec), world_T_board_(world_T_board), board_T_world_(world_T_board.inverse()) {
    for (const auto& panel : spec.panels) panels_.push_back(panel.world_T_panel.inverse());
    board_normal_ = world_T_board.linear().col(2);
    board_origin_ = world_T_board.translation();
    if (spec.occluder) {
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
      for (const auto& corner : spec.target.outerCorners()) lowest = std::min(lowest, (world_T_board * corner).z());
      Eigen::Vector3d person_centre;
      for (double behind = kPersonBehindBoard; behind < kPersonMaxBehind; behind += kPersonStep) {
        person_centre = Eigen::Vector3d(centre.x() + behind * back.x(), centre.y() + behind * back.y(),
                                        spec.floor_z_m + person_half_height_);
        bool clear = true;
        for (int k = 0; k < 8 && clear; ++k) {
          const Eigen::Vector3d local((k & 1 ? 1 : -1) * kPersonHalfDepth, (k & 2 ? 1 : -1) * kPersonHalfWidth, 0.0);
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
  }

  Hit cast(const Eigen::Vector3d& origin, const Eigen::Vector3d& dir) const {
    Hit best;
    castBoard(origin, dir, &best);
    if (spec_.occluder && person_half_height_ > 0) castPerson(origin, dir, &best);
    for (size_t k = 0; k < panels_.size(); ++k) castPanel(k, origin, dir, &best);
    if (spec_.outdoor || spec_.room) castRoom(origin, dir, &best);
    if (best.valid()) best.point = origin + best.t * dir;
    return best;
  }

  // Colour (BGR, 0..1) of a hit as a camera sees it; `dir` is the viewing ray. The room is
  // piecewise flat (panels, tiles): realistic straight clutter for line detectors, and
  // noise-free images compress well in bags.
  Eigen::Vector3d shade(const Hit& hit, const Eigen::Vector3d& dir) const {
    // Light from above and slightly from the side: soft, so edges stay photometric.
    const Eigen::Vector3d light = Eigen::Vector3d(0.3, 0.2, 1.0).normalized();
    const double lambert = std::abs(hit.normal.dot(light));
    const bool board = hit.board();
    const double shading = board ? kBoardAmbient + (1 - kBoardAmbient) * lambert : kAmbient + kDiffuse * lambert;
    const Eigen::Vector3d& p = hit.point;
    double grey = 0.5;
    Eigen::Vector3d tint(1.0, 1.0, 1.0);  // b, g, r
    switch (hit.label) {
      case kLabelBoardWhite:
      case kLabelBoardBlack: {
        // Slightly darker at grazing views (matte print): a smooth gradient over the board.
        const double facing = std::abs(hit.normal.dot(dir));
        grey = (hit.label == kLabelBoardWhite ? spec_.board_grey : kBoardBlack) * (kBoardFacingMin + (1 - kBoardFacingMin) * facing);
        if (hit.label == kLabelBoardWhite) {
          tint = spec_.board_tint;
          if (spec_.board_texture > 0) {
            const Eigen::Vector3d q = board_T_world_ * p;
            const double h = hash01(static_cast<int64_t>(std::floor(q.x() / kGrainAlong)),
                                    static_cast<int64_t>(std::floor(q.y() / kGrainAcross)), 5);
            grey *= 1.0 + spec_.board_texture * (2 * h - 1);
          }
        }
        break;
      }
      case kLabelBoardBack: grey = kBoardBack; break;
      case kLabelPerson: {
        grey = 0.3;
        tint = {1.3, 0.95, 0.75};  // blue clothes
        break;
      }
      case kLabelFloor: {
        if (spec_.outdoor) {  // paving slabs around the configured pavement brightness
          const double gx = p.x() / kPavingSlab, gy = p.y() / kPavingSlab;
          const double fx = gx - std::floor(gx), fy = gy - std::floor(gy);
          const double grout = kGroutWidth / kPavingSlab;
          const double h = hash01(static_cast<int64_t>(std::floor(gx)), static_cast<int64_t>(std::floor(gy)), 2);
          grey = spec_.ground_grey * ((fx < grout || fy < grout) ? kPavingGroutGrey : 1.0 + kPavingVariation * (h - 0.5));
          break;
        }
        const double gx = p.x() / kFloorTile, gy = p.y() / kFloorTile;
        const double fx = gx - std::floor(gx), fy = gy - std::floor(gy);
        const double grout = kGroutWidth / kFloorTile;
        if (fx < grout || fy < grout) {
          grey = 0.22;
        } else {
          grey = 0.38 + 0.2 * hash01(static_cast<int64_t>(std::floor(gx)), static_cast<int64_t>(std::floor(gy)), 1);
        }
        tint = {0.85, 0.95, 1.1};
        break;
      }
      case kLabelCeiling: grey = 0.8; break;
      default: {
        if (hit.label >= kLabelPanel) {
          const Panel& panel = spec_.panels[static_cast<size_t>(hit.label - kLabelPanel)];
          grey = panel.grey;
          tint = panel.tint;
          break;
        }
        if (spec_.outdoor) {  // facades: storeys of dark windows, per-building wall brightness
          const double s = std::abs(hit.normal.x()) > 0.5 ? p.y() : p.x();
          const double gu = s / kFacadeBay, gv = (p.z() - spec_.floor_z_m) / kFacadeBay;
          const double fu = (gu - std::floor(gu)) * kFacadeBay, fv = (gv - std::floor(gv)) * kFacadeBay;
          const bool window = fu > kWindowLo && fu < kWindowHi && fv > kWindowLo && fv < kWindowHi && gv >= 1;
          grey = window ? kWindowGrey : 0.45 + 0.3 * hash01(static_cast<int64_t>(std::floor(gu / 4)), 0, 7 + hit.label);
          if (window) tint = {1.2, 1.0, 0.9};
          break;
        }
        // walls: panels of random brightness with dark seams, some posters
        const double s = std::abs(hit.normal.x()) > 0.5 ? p.y() : p.x();
        const double gu = s / kWallPanelWidth, gv = (p.z() - spec_.floor_z_m) / kWallPanelHeight;
        const double fu = gu - std::floor(gu), fv = gv - std::floor(gv);
        const int64_t iu = static_cast<int64_t>(std::floor(gu)), iv = static_cast<int64_t>(std::floor(gv));
        if (fu < kSeamFraction || fv < kSeamFraction) {
          grey = 0.25;
        } else {
          const double h = hash01(iu, iv, 3 + hit.label);
          grey = 0.4 + 0.35 * h;
          if (h > kPosterThreshold) tint = {0.7 + 0.6 * hash01(iu, iv, 17), 0.8, 0.7 + 0.6 * hash01(iu, iv, 23)};
        }
        tint = tint.cwiseProduct(Eigen::Vector3d(0.9 + 0.05 * (hit.label - kLabelWall), 1.0, 1.05));
      }
    }
    return grey * shading * tint;
  }

  // Colour where a camera ray hits nothing: the sky outdoors, black otherwise.
  Eigen::Vector3d sky() const { return spec_.outdoor ? Eigen::Vector3d(0.95, 0.85, 0.75) : Eigen::Vector3d::Zero(); }

  // LiDAR reflectivity in intensity units.
  double reflectivity(const Hit& hit) const {
    switch (hit.label) {
      case kLabelBoardWhite: return spec_.board_intensity;
      case kLabelBoardBlack: return spec_.board_intensity * kBlackReflectivity;
      case kLabelBoardBack: return spec_.board_intensity * 0.5;
      default:
        if (hit.label >= kLabelPanel) return spec_.panels[static_cast<size_t>(hit.label - kLabelPanel)].intensity;
        return spec_.background_intensity;
    }
  }

 private:
  void castBoard(const Eigen::Vector3d& origin, const Eigen::Vector3d& dir, Hit* best) const {
    const double denom = board_normal_.dot(dir);
    if (std::abs(denom) < 1e-12) return;
    const double t = board_normal_.dot(board_origin_ - origin) / denom;
    if (t <= kRayEpsilon || t >= best->t) return;
    const Eigen::Vector3d p_board = board_T_world_ * (origin + t * dir);
    const Target& target = spec_.target;
    if (p_board.x() < 0 || p_board.y() < 0 || p_board.x() >= target.width || p_board.y() >= target.height) return;
    best->t = t;
    best->normal = board_normal_;
    if (denom > 0) {  // ray travels along +z: seen from -z, the printed face
      bool black = boardBlackAt(target, p_board.x(), p_board.y());
      for (const auto& mark : spec_.board_marks)
        black = black || (p_board.x() >= mark.min.x() && p_board.x() < mark.max.x() && p_board.y() >= mark.min.y() &&
                          p_board.y() < mark.max.y());
      best->label = black ? kLabelBoardBlack : kLabelBoardWhite;
    } else {
      best->label = kLabelBoardBack;
    }
  }

  void castPerson(const Eigen::Vector3d& origin, const Eigen::Vector3d& dir, Hit* best) const {
    const Eigen::Vector3d o = person_T_world_ * origin;
    const Eigen::Vector3d d = person_T_world_.linear() * dir;
    const Eigen::Vector3d half(kPersonHalfDepth, kPersonHalfWidth, person_half_height_);
    double t_near = -std::numeric_limits<double>::infinity(), t_far = std::numeric_limits<double>::infinity();
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

  void castPanel(size_t k, const Eigen::Vector3d& origin, const Eigen::Vector3d& dir, Hit* best) const {
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

  void castRoom(const Eigen::Vector3d& origin, const Eigen::Vector3d& dir, Hit* best) const {
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
    if (spec_.outdoor && face < 4 && origin.z() + t_exit * dir.z() > spec_.floor_z_m + kFacadeHeight) return;  // sky
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

// ---------------------------------------------------------------------------------------------
// Camera ray maps: normalised undistorted coordinates of every pixel centre, cached per camera.
// ---------------------------------------------------------------------------------------------
struct RayMap {
  int width = 0, height = 0;
  std::vector<float> xy;  // 2 per pixel, row-major

  Eigen::Vector2d at(int u, int v) const {
    const size_t i = 2 * (static_cast<size_t>(v) * width + u);
    return {xy[i], xy[i + 1]};
  }
  // Bilinear (extrapolating at the border) between pixel centres; the inverse distortion is
  // smooth, so at sub-pixel offsets the interpolation error is far below 1e-3 px.
  Eigen::Vector2d interpolate(double u, double v) const {
    const int u0 = std::clamp(static_cast<int>(std::floor(u)), 0, std::max(0, width - 2));
    const int v0 = std::clamp(static_cast<int>(std::floor(v)), 0, std::max(0, height - 2));
    const int u1 = std::min(u0 + 1, width - 1), v1 = std::min(v0 + 1, height - 1);
    const double a = u - u0, b = v - v0;
    return (at(u0, v0) * (1 - a) + at(u1, v0) * a) * (1 - b) + (at(u0, v1) * (1 - a) + at(u1, v1) * a) * b;
  }
};

std::string intrinsicsKey(const CameraIntrinsics& in) {
  std::ostringstream key;
  key.precision(17);
  key << in.width << ' ' << in.height << ' ' << in.fx << ' ' << in.fy << ' ' << in.cx << ' ' << in.cy << ' '
      << static_cast<int>(in.model);
  for (double c : in.coeffs) key << ' ' << c;
  return key.str();
}

std::shared_ptr<const RayMap> buildRayMap(const CameraModel& camera) {
  auto map = std::make_shared<RayMap>();
  const int w = camera.width(), h = camera.height();
  map->width = w;
  map->height = h;
  map->xy.resize(2 * static_cast<size_t>(w) * h);
  const auto& in = camera.intrinsics();
  constexpr int kMaxIterations = 30;
  constexpr double kStep = 1e-7;
  constexpr double kTolerance2 = 1e-26;
  cv::parallel_for_(cv::Range(0, h), [&](const cv::Range& range) {
  for (int v = range.start; v < range.end; ++v) {
    Eigen::Vector2d x = camera.undistortNormalized(Eigen::Vector2d(0, v));  // robust start of each row
    for (int u = 0; u < w; ++u) {
      const Eigen::Vector2d target((u - in.cx) / in.fx, (v - in.cy) / in.fy);
      // Newton from the left neighbour's solution: two or three steps per pixel.
      for (int it = 0; it < kMaxIterations; ++it) {
        Eigen::Vector2d f;
        camera.distortNormalized(x.x(), x.y(), &f.x(), &f.y());
        const Eigen::Vector2d r = f - target;
        if (r.squaredNorm() < kTolerance2) break;
        Eigen::Matrix2d J;
        for (int k = 0; k < 2; ++k) {
          Eigen::Vector2d xp = x;
          xp[k] += kStep;
          Eigen::Vector2d fp;
          camera.distortNormalized(xp.x(), xp.y(), &fp.x(), &fp.y());
          J.col(k) = (fp - f) / kStep;
        }
        x -= J.partialPivLu().solve(r);
      }
      const size_t i = 2 * (static_cast<size_t>(v) * w + u);
      map->xy[i] = static_cast<float>(x.x());
      map->xy[i + 1] = static_cast<float>(x.y());
    }
  }
  });
  return map;
}

std::shared_ptr<const RayMap> rayMapFor(const CameraModel& camera) {
  static std::mutex mutex;
  static std::map<std::string, std::shared_ptr<const RayMap>> cache;
  constexpr size_t kMaxCached = 8;  // a rig rarely has more cameras; bounds memory
  const std::string key = intrinsicsKey(camera.intrinsics());
  {
    std::lock_guard<std::mutex> lock(mutex);
    auto it = cache.find(key);
    if (it != cache.end()) return it->second;
  }
  auto map = buildRayMap(camera);
  std::lock_guard<std::mutex> lock(mutex);
  if (cache.size() >= kMaxCached) cache.clear();
  cache[key] = map;
  return map;
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// Options
// ---------------------------------------------------------------------------------------------
std::string LidarSpec::validate() const {
  if (elevations_deg.empty()) return "LiDAR '" + name + "': elevations_deg is empty";
  for (double e : elevations_deg)
    if (!std::isfinite(e) || e <= -90 || e >= 90) return "LiDAR '" + name + "': elevation out of (-90, 90) deg";
  if (!azimuth_offsets_deg.empty() && azimuth_offsets_deg.size() != elevations_deg.size())
    return "LiDAR '" + name + "': azimuth_offsets_deg must be empty or have one entry per ring";
  if (!(horizontal_resolution_deg > 0.01) || horizontal_resolution_deg > 10)
    return "LiDAR '" + name + "': horizontal_resolution_deg must be in (0.01, 10]";
  if (!(range_noise_m >= 0)) return "LiDAR '" + name + "': range_noise_m must be >= 0";
  if (!(min_range_m >= 0) || !(max_range_m > min_range_m))
    return "LiDAR '" + name + "': need 0 <= min_range_m < max_range_m";
  if (!(dropout_probability >= 0) || dropout_probability > 1)
    return "LiDAR '" + name + "': dropout_probability must be in [0, 1]";
  if (!(beam_divergence_deg >= 0) || beam_divergence_deg > 5)
    return "LiDAR '" + name + "': beam_divergence_deg must be in [0, 5]";
  if (!(mixed_return_max_gap_m >= 0)) return "LiDAR '" + name + "': mixed_return_max_gap_m must be >= 0";
  if (!(intensity_noise >= 0)) return "LiDAR '" + name + "': intensity_noise must be >= 0";
  if (!(rate_hz > 0)) return "LiDAR '" + name + "': rate_hz must be > 0";
  return {};
}

int LidarSpec::columns() const { return std::max(1, static_cast<int>(std::lround(360.0 / horizontal_resolution_deg))); }

double LidarSpec::azimuthRad(int ring, int col) const {
  double az_deg = 180.0 - col * (360.0 / columns());
  if (!azimuth_offsets_deg.empty() && ring >= 0 && ring < static_cast<int>(azimuth_offsets_deg.size()))
    az_deg += azimuth_offsets_deg[static_cast<size_t>(ring)];
  az_deg = std::remainder(az_deg, 360.0);
  return az_deg * kDegToRad;
}

std::string SceneSpec::validate() const {
  const std::string target_reason = target.validate();
  if (!target_reason.empty()) return "target: " + target_reason;
  if (room) {
    if (!(room_half_size_m > 0)) return "room_half_size_m must be > 0";
    if (!(ceiling_z_m > floor_z_m)) return "ceiling_z_m must be above floor_z_m";
  }
  if (outdoor) {
    if (!(street_half_width_m > 0)) return "street_half_width_m must be > 0";
    if (!(facade_distance_m > 0)) return "facade_distance_m must be > 0";
    if (!(ground_grey >= 0 && ground_grey <= 1)) return "ground_grey must be in [0, 1]";
  }
  if (!std::isfinite(board_intensity) || !std::isfinite(background_intensity) || board_intensity < 0 ||
      background_intensity < 0)
    return "intensities must be finite and >= 0";
  if (!(board_grey >= 0 && board_grey <= 1)) return "board_grey must be in [0, 1]";
  if (!board_tint.allFinite() || (board_tint.array() < 0).any()) return "board_tint must be finite and >= 0";
  if (!(board_texture >= 0 && board_texture <= 0.5)) return "board_texture must be in [0, 0.5]";
  for (const auto& mark : board_marks)
    if (!mark.min.allFinite() || !mark.max.allFinite() || !(mark.min.array() < mark.max.array()).all())
      return "board mark: min must be < max";
  if (panels.size() > 1000) return "at most 1000 panels";
  for (size_t k = 0; k < panels.size(); ++k) {
    const std::string why = panels[k].validate();
    if (!why.empty()) return "panel " + std::to_string(k) + ": " + why;
  }
  return {};
}

std::string Panel::validate() const {
  if (!(width_m > 0) || !(height_m > 0)) return "width_m and height_m must be > 0";
  if (!(grey >= 0 && grey <= 1)) return "grey must be in [0, 1]";
  if (!tint.allFinite() || (tint.array() < 0).any()) return "tint must be finite and >= 0";
  if (!std::isfinite(intensity) || intensity < 0) return "intensity must be finite and >= 0";
  if (!world_T_panel.matrix().allFinite()) return "pose must be finite";
  return {};
}

std::string RenderOptions::validate() const {
  if (supersampling < 1 || supersampling > 16) return "supersampling must be in [1, 16]";
  if (!(noise_sigma >= 0)) return "noise_sigma must be >= 0";
  if (!(vignetting >= 0) || vignetting > 1) return "vignetting must be in [0, 1]";
  if (!(blur_sigma_px >= 0)) return "blur_sigma_px must be >= 0";
  return {};
}

Expected<LidarSpec> lidarPreset(const std::string& name) {
  LidarSpec spec;
  spec.name = name;
  if (name == "VLP-16") {
    // Velodyne's ROS driver numbers rings bottom-up (ring 0 = -15 deg), 2 deg apart.
    for (int i = 0; i < 16; ++i) spec.elevations_deg.push_back(-15.0 + 2.0 * i);
    spec.horizontal_resolution_deg = 0.2;  // 600 rpm
    spec.range_noise_m = 0.015;
    spec.max_range_m = 100.0;
    spec.beam_divergence_deg = 0.17;
  } else if (name == "VLP-32C") {
    // Datasheet elevations, ascending (ring 0 = lowest beam, as the ROS driver numbers them).
    spec.elevations_deg = {-25.0,  -15.639, -11.31, -8.843, -7.254, -6.148, -5.333, -4.667,
                           -4.0,   -3.667,  -3.333, -3.0,   -2.667, -2.333, -2.0,   -1.667,
                           -1.333, -1.0,    -0.667, -0.333, 0.0,    0.333,  0.667,  1.0,
                           1.333,  1.667,   2.333,  3.333,  4.667,  7.0,    10.333, 15.0};
    spec.horizontal_resolution_deg = 0.2;
    spec.range_noise_m = 0.01;
    spec.max_range_m = 200.0;
    spec.beam_divergence_deg = 0.17;
  } else if (name == "OS1-64") {
    // Ouster numbers rings top-down (ring 0 = +16.6 deg), uniform over 33.2 deg; beams are
    // staggered in azimuth by a 4-periodic pattern.
    constexpr int kRings = 64;
    constexpr double kTop = 16.6, kFov = 33.2;
    const double stagger[4] = {3.164, 1.055, -1.055, -3.164};
    for (int i = 0; i < kRings; ++i) {
      spec.elevations_deg.push_back(kTop - kFov * i / (kRings - 1));
      spec.azimuth_offsets_deg.push_back(stagger[i % 4]);
    }
    spec.horizontal_resolution_deg = 360.0 / 1024;
    spec.range_noise_m = 0.02;
    spec.min_range_m = 0.8;
    spec.max_range_m = 120.0;
    spec.beam_divergence_deg = 0.13;
  } else {
    return Expected<LidarSpec>::failure("unknown LiDAR preset '" + name + "' (known: VLP-16, VLP-32C, OS1-64)");
  }
  return spec;
}

// ---------------------------------------------------------------------------------------------
// LiDAR
// ---------------------------------------------------------------------------------------------
LidarCloud simulateLidarScan(const LidarSpec& spec, const Eigen::Isometry3d& world_T_lidar, const SceneSpec& scene,
                             const Eigen::Isometry3d& world_T_board, std::mt19937& rng) {
  return simulateLidarScan(spec, world_T_lidar, scene, world_T_board, rng, nullptr);
}

LidarCloud simulateLidarScan(const LidarSpec& spec, const Eigen::Isometry3d& world_T_lidar, const SceneSpec& scene,
                             const Eigen::Isometry3d& world_T_board, std::mt19937& rng,
                             std::vector<ReturnOrigin>* origins) {
  LidarCloud cloud;
  cloud.has_intensity = true;
  cloud.has_ring = spec.with_ring;
  if (origins) origins->clear();
  if (!spec.validate().empty() || !scene.validate().empty()) return cloud;  // empty cloud: nothing sensible to cast

  const Scene world(scene, world_T_board);
  const int rings = static_cast<int>(spec.elevations_deg.size());
  const int cols = spec.columns();
  const Eigen::Matrix3d R = world_T_lidar.linear();
  const Eigen::Vector3d origin = world_T_lidar.translation();
  const float nan = std::numeric_limits<float>::quiet_NaN();

  // Sub-rays across the beam footprint: centre plus a ring of six at half the divergence.
  constexpr int kFootprintRays = 7;
  const double footprint_radius = 0.5 * spec.beam_divergence_deg * kDegToRad;
  double sub_da[kFootprintRays] = {0}, sub_de[kFootprintRays] = {0};
  for (int k = 1; k < kFootprintRays; ++k) {
    const double phi = 2 * kPi * (k - 1) / (kFootprintRays - 1);
    sub_da[k] = footprint_radius * std::cos(phi);
    sub_de[k] = footprint_radius * std::sin(phi);
  }

  std::normal_distribution<double> range_noise(0.0, 1.0);
  std::uniform_real_distribution<double> uniform(0.0, 1.0);

  if (spec.organized) {
    cloud.width = cols;
    cloud.height = rings;
    cloud.points.resize(static_cast<size_t>(rings) * cols);
  }
  auto direction = [](double az, double el) {
    const double ce = std::cos(el);
    return Eigen::Vector3d(ce * std::cos(az), ce * std::sin(az), std::sin(el));
  };

  for (int ring = 0; ring < rings; ++ring) {
    const double el = spec.elevations_deg[static_cast<size_t>(ring)] * kDegToRad;
    for (int col = 0; col < cols; ++col) {
      const double az = spec.azimuthRad(ring, col);
      LidarPoint point;
      point.x = point.y = point.z = nan;
      point.ring = spec.with_ring ? ring : -1;
      ReturnOrigin what = ReturnOrigin::kNone;

      // Cast the footprint.
      Hit hits[kFootprintRays];
      int n_board = 0, n_valid = 0;
      for (int k = 0; k < kFootprintRays; ++k) {
        const Eigen::Vector3d d_lidar = direction(az + sub_da[k] / std::max(std::cos(el), 1e-6), el + sub_de[k]);
        hits[k] = world.cast(origin, R * d_lidar);
        if (hits[k].valid()) {
          ++n_valid;
          if (hits[k].board()) ++n_board;
        }
      }
      const bool dropped = spec.dropout_probability > 0 && uniform(rng) < spec.dropout_probability;
      if (n_valid > 0 && !dropped) {
        // Energy per sub-ray ~ reflectivity / r^2. Cluster into board / not board.
        double e_board = 0, r_board = 0, i_board = 0, e_other = 0, r_other = 0, i_other = 0;
        for (int k = 0; k < kFootprintRays; ++k) {
          if (!hits[k].valid()) continue;
          const double refl = std::max(1.0, world.reflectivity(hits[k]));
          const double energy = refl / std::max(hits[k].t * hits[k].t, 1e-6);
          if (hits[k].board()) {
            e_board += energy;
            r_board += energy * hits[k].t;
            i_board += refl;
          } else {
            e_other += energy;
            r_other += energy * hits[k].t;
            i_other += refl;
          }
        }
        double range = 0, intensity = 0;
        if (n_board == n_valid) {
          range = r_board / e_board;
          intensity = i_board / n_board;
          what = ReturnOrigin::kBoard;
        } else if (n_board == 0) {
          range = r_other / e_other;
          intensity = i_other / (n_valid - n_board);
          what = ReturnOrigin::kBackground;
        } else {
          const double rb = r_board / e_board, ro = r_other / e_other;
          if (std::abs(rb - ro) <= spec.mixed_return_max_gap_m) {
            range = (r_board + r_other) / (e_board + e_other);  // the receiver blends both echoes
          } else {
            range = e_board >= e_other ? rb : ro;  // separate echoes: the strongest one wins
          }
          intensity = (i_board + i_other) / n_valid;
          what = ReturnOrigin::kMixed;
        }
        range += spec.range_noise_m * range_noise(rng);
        intensity += spec.intensity_noise * range_noise(rng);
        if (range >= spec.min_range_m && range <= spec.max_range_m) {
          const Eigen::Vector3d p = range * direction(az, el);
          point.x = static_cast<float>(p.x());
          point.y = static_cast<float>(p.y());
          point.z = static_cast<float>(p.z());
          point.intensity = static_cast<float>(std::clamp(intensity, 0.0, 255.0));
        } else {
          what = ReturnOrigin::kNone;
        }
      }
      if (spec.organized) {
        cloud.points[static_cast<size_t>(ring) * cols + col] = point;
        if (origins) origins->push_back(what);
      } else if (what != ReturnOrigin::kNone) {
        cloud.points.push_back(point);
        if (origins) origins->push_back(what);
      }
    }
  }
  if (!spec.organized) {
    cloud.width = static_cast<int>(cloud.points.size());
    cloud.height = 1;
  }
  return cloud;
}

// ---------------------------------------------------------------------------------------------
// Camera
// ---------------------------------------------------------------------------------------------
cv::Mat renderCameraImage(const CameraModel& camera, const Eigen::Isometry3d& world_T_camera, const SceneSpec& scene,
                          const Eigen::Isometry3d& world_T_board, const RenderOptions& options, std::mt19937& rng) {
  const cv::Mat radiance = renderCameraRadiance(camera, world_T_camera, scene, world_T_board, options);
  if (radiance.empty()) return cv::Mat();
  return finishCameraImage(radiance, camera, options, rng);
}

cv::Mat renderCameraRadiance(const CameraModel& camera, const Eigen::Isometry3d& world_T_camera, const SceneSpec& scene,
                             const Eigen::Isometry3d& world_T_board, const RenderOptions& options) {
  const int w = camera.width(), h = camera.height();
  if (w <= 0 || h <= 0 || !options.validate().empty() || !scene.validate().empty()) return cv::Mat();
  const std::shared_ptr<const RayMap> rays = rayMapFor(camera);
  const Scene world(scene, world_T_board);
  const Eigen::Matrix3d R = world_T_camera.linear();
  const Eigen::Vector3d origin = world_T_camera.translation();

  cv::Mat colour(h, w, CV_32FC3);
  cv::Mat labels(h, w, CV_32SC1);
  auto sample = [&](const Eigen::Vector2d& xy, int* label) {
    const Eigen::Vector3d dir = (R * Eigen::Vector3d(xy.x(), xy.y(), 1.0)).normalized();
    const Hit hit = world.cast(origin, dir);
    *label = hit.label;
    if (!hit.valid()) return world.sky();
    return world.shade(hit, dir);
  };

  // Rows are independent (no randomness here), so they render in parallel.
  cv::parallel_for_(cv::Range(0, h), [&](const cv::Range& range) {
    for (int v = range.start; v < range.end; ++v) {
      auto* row = colour.ptr<cv::Vec3f>(v);
      auto* lrow = labels.ptr<int>(v);
      for (int u = 0; u < w; ++u) {
        const Eigen::Vector3d c = sample(rays->at(u, v), &lrow[u]);
        row[u] = cv::Vec3f(static_cast<float>(c[0]), static_cast<float>(c[1]), static_cast<float>(c[2]));
      }
    }
  });

  // Supersample pixels whose 3x3 neighbourhood changes label: the pixel footprint may straddle
  // an edge there. Pixel (u, v) covers [u - 0.5, u + 0.5] x [v - 0.5, v + 0.5].
  const int n = options.supersampling;
  if (n > 1) {
    cv::Mat edge(h, w, CV_8UC1, cv::Scalar(0));
    for (int v = 0; v < h; ++v) {
      for (int u = 0; u < w; ++u) {
        const int l = labels.at<int>(v, u);
        bool differs = false;
        for (int dv = -1; dv <= 1 && !differs; ++dv)
          for (int du = -1; du <= 1 && !differs; ++du) {
            const int uu = u + du, vv = v + dv;
            if (uu < 0 || vv < 0 || uu >= w || vv >= h) continue;
            differs = labels.at<int>(vv, uu) != l;
          }
        if (differs) edge.at<uint8_t>(v, u) = 1;
      }
    }
    cv::parallel_for_(cv::Range(0, h), [&](const cv::Range& range) {
    for (int v = range.start; v < range.end; ++v) {
      for (int u = 0; u < w; ++u) {
        if (!edge.at<uint8_t>(v, u)) continue;
        Eigen::Vector3d sum = Eigen::Vector3d::Zero();
        for (int j = 0; j < n; ++j)
          for (int i = 0; i < n; ++i) {
            const double su = u - 0.5 + (i + 0.5) / n, sv = v - 0.5 + (j + 0.5) / n;
            int label = 0;
            sum += sample(rays->interpolate(su, sv), &label);
          }
        sum /= (n * n);
        colour.at<cv::Vec3f>(v, u) =
            cv::Vec3f(static_cast<float>(sum[0]), static_cast<float>(sum[1]), static_cast<float>(sum[2]));
      }
    }
    });
  }

  return colour;
}

cv::Mat finishCameraImage(const cv::Mat& radiance, const CameraModel& camera, const RenderOptions& options,
                          std::mt19937& rng) {
  if (radiance.empty() || radiance.type() != CV_32FC3 || !options.validate().empty()) return cv::Mat();
  const int w = radiance.cols, h = radiance.rows;
  cv::Mat colour = radiance;
  if (options.blur_sigma_px > 0) cv::GaussianBlur(radiance, colour, cv::Size(0, 0), options.blur_sigma_px);

  // Vignetting (radial, quadratic in the distance from the principal point), then 8 bit + noise.
  const auto& in = camera.intrinsics();
  const double r_max2 = std::max({in.cx * in.cx + in.cy * in.cy, (w - in.cx) * (w - in.cx) + in.cy * in.cy,
                                  in.cx * in.cx + (h - in.cy) * (h - in.cy),
                                  (w - in.cx) * (w - in.cx) + (h - in.cy) * (h - in.cy)});
  cv::Mat noise;
  if (options.noise_sigma > 0) {
    noise.create(h, w, CV_32FC3);
    cv::RNG cv_rng(static_cast<uint64_t>(rng()) << 32 | rng());
    cv_rng.fill(noise, cv::RNG::NORMAL, 0.0, options.noise_sigma);
  }
  cv::Mat image(h, w, CV_8UC3);
  for (int v = 0; v < h; ++v) {
    const auto* src = colour.ptr<cv::Vec3f>(v);
    const auto* nrow = noise.empty() ? nullptr : noise.ptr<cv::Vec3f>(v);
    auto* dst = image.ptr<cv::Vec3b>(v);
    for (int u = 0; u < w; ++u) {
      const double r2 = ((u - in.cx) * (u - in.cx) + (v - in.cy) * (v - in.cy)) / r_max2;
      const double gain = 255.0 * (1.0 - options.vignetting * r2);
      for (int c = 0; c < 3; ++c) {
        const double value = src[u][c] * gain + (nrow ? nrow[u][c] : 0.0f);
        dst[u][c] = cv::saturate_cast<uint8_t>(value);
      }
    }
  }
  return image;
}

}  // namespace sim
}  // namespace board_calib
