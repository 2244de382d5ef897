// Private stages of the LiDAR board detector (not installed): valid points, candidates (planar
// voxel regions and scan-line segments), plane refinement, edges. Shared by
// lidar_board_detector.cpp (the single-cloud detector) and lidar_board_tracker.cpp.
#pragma once

#include <board_calib/core/lidar_detection/lidar_board_detector.h>

#include "geometry_2d.h"
#include "scan_segments.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <functional>
#include <limits>
#include <map>
#include <random>
#include <string>
#include <unordered_map>
#include <vector>

namespace board_calib {
namespace lidar_detail {

constexpr double kPi = 3.14159265358979323846;
constexpr double kRadPerDeg = kPi / 180.0;
// Voxel indices are packed into one 64-bit key, 21 bits per axis.
constexpr int64_t kVoxelIndexOffset = 1 << 20;
constexpr int64_t kVoxelIndexBits = 21;
// Covariance of a uniform segment of length a is a^2/12: sqrt(12 lambda) estimates a side.
constexpr double kUniformSideFromVariance = 12.0;
// A region whose covariance says it is this many times larger than the board is not scored.
constexpr double kPrefilterExtentFactor = 2.0;
// Weights of the candidate score (lower is better): size terms are |log(ratio)|.
constexpr double kFillWeight = 0.5;
constexpr double kRmsWeight = 0.2;
constexpr double kMinFillForLog = 1e-3;
// Support = points * exp(-kShapeErrorScale * shape error): 0.25 more shape error costs a factor e.
constexpr double kShapeErrorScale = 4.0;
// The plane's up direction becomes undefined when the board is (nearly) horizontal.
constexpr double kMaxNormalUpCosine = 0.97;
// Two candidates closer than this are parts of one board, not two boards.
constexpr double kSameBoardDistanceM = 0.5;
// Median absolute deviation to sigma (Gaussian), band width in sigmas, and its floor.
constexpr double kMadToSigma = 1.4826;
constexpr double kRobustBandSigmas = 2.5;
constexpr double kMinRobustBandM = 0.005;
constexpr double kAdaptiveBandSigmas = 3.0;  // plane inlier band in robust sigmas
constexpr double kMaxAdaptiveBandFactor =
    2.0;  // the band grows to at most this times the threshold
// The plane refit after the edges keeps points this far inside the edge lines (drops the
// mixed returns of the rim and anything touching the board from outside).
constexpr double kRimExclusionM = 0.02;
// Returns of another plane's voxel join the board only when at most this share of them (per
// return in the board's band) lies in the next band out: a separate layer behind a gap, not a
// surface crossing the board's plane. The board's own noise puts ~0.3 % there (3 to 6 sigma).
constexpr double kMaxLayerGapShare = 0.1;
// Points sampled for the convex hull of a large candidate.
constexpr size_t kMaxHullPoints = 4000;
// Re-assignment rounds between the two edges of one side.
constexpr int kEdgeAssignmentRounds = 3;

inline std::string fmt(const char* format, double a, double b = 0, double c = 0, double d = 0) {
  char buf[256];
  std::snprintf(buf, sizeof(buf), format, a, b, c, d);
  return buf;
}

inline int64_t voxelKey(int64_t ix, int64_t iy, int64_t iz) {
  return ((ix + kVoxelIndexOffset) << (2 * kVoxelIndexBits)) |
         ((iy + kVoxelIndexOffset) << kVoxelIndexBits) | (iz + kVoxelIndexOffset);
}

struct Voxel {
  int ix = 0, iy = 0, iz = 0;
  PlaneStats stats;
  int first = 0, count = 0;  // range in the voxel-sorted point index array
  int region = -1;
};

struct ValidPoint {
  Eigen::Vector3d p;
  int cloud_index = 0;
};

struct Region {
  std::vector<int> voxels;
  PlaneStats stats;
  // Sparse candidates (scan-line segments): their points and sampling.
  bool sparse = false;
  std::vector<int> points;
  int lines = 0;
  double column_step_rad = 0.0, line_step_rad = 0.0;
};

struct Candidate {
  LidarBoardCandidate info;
  int region = -1;
};

// Azimuth difference wrapped into (-pi, pi].
inline double wrapAngle(double a) {
  while (a > kPi) a -= 2 * kPi;
  while (a <= -kPi) a += 2 * kPi;
  return a;
}

inline LidarBoardDetection failure(LidarBoardDetection d, LidarDetectionCode code,
                                   const std::string& reason) {
  d.code = code;
  d.features.found = false;
  d.features.reason = reason;
  return d;
}

// Voxel key -> voxel number by open addressing (linear probing, a power-of-two table at most half
// full): region growing asks it 26 times per voxel and every point inserts, where a node-based
// map spent a quarter of the detector's time.
class VoxelIndex {
 public:
  void reserve(size_t n) { rehash(std::max<size_t>(16, 2 * n)); }
  /// The voxel number of `key`, inserting `value` when absent; `inserted` says which.
  int emplace(int64_t key, int value, bool* inserted) {
    if (2 * (size_ + 1) > keys_.size()) rehash(2 * keys_.size());
    size_t i = slot(key);
    while (used_[i] && keys_[i] != key) i = (i + 1) & mask_;
    *inserted = !used_[i];
    if (*inserted) {
      used_[i] = 1;
      keys_[i] = key;
      values_[i] = value;
      ++size_;
    }
    return values_[i];
  }
  /// The voxel number of `key`, -1 when absent.
  int find(int64_t key) const {
    if (keys_.empty()) return -1;
    for (size_t i = slot(key);; i = (i + 1) & mask_) {
      if (!used_[i]) return -1;
      if (keys_[i] == key) return values_[i];
    }
  }

 private:
  size_t slot(int64_t key) const {  // Fibonacci hashing: the high bits of key x 2^64 / phi
    return static_cast<size_t>((static_cast<uint64_t>(key) * 0x9E3779B97F4A7C15ull) >> shift_);
  }
  void rehash(size_t capacity) {
    size_t cap = 16;
    int bits = 4;
    while (cap < capacity) {
      cap <<= 1;
      ++bits;
    }
    std::vector<int64_t> keys = std::move(keys_);
    std::vector<int> values = std::move(values_);
    std::vector<unsigned char> used = std::move(used_);
    keys_.assign(cap, 0);
    values_.assign(cap, -1);
    used_.assign(cap, 0);
    mask_ = cap - 1;
    shift_ = 64 - bits;
    size_ = 0;
    bool inserted = false;
    for (size_t i = 0; i < keys.size(); ++i)
      if (used[i]) emplace(keys[i], values[i], &inserted);
  }
  std::vector<int64_t> keys_;
  std::vector<int> values_;
  std::vector<unsigned char> used_;
  size_t mask_ = 0, size_ = 0;
  int shift_ = 60;
};

struct VoxelGrid {
  std::vector<Voxel> voxels;
  VoxelIndex index;
  std::vector<int> sorted_points;  // point indices grouped by voxel

  int find(int ix, int iy, int iz) const { return index.find(voxelKey(ix, iy, iz)); }
};

// In-plane basis of a plane: u "right" as seen from the sensor, v "up" (sensor +z projected).
struct PlaneFrame {
  Eigen::Vector3d origin, n, u, v;
  Eigen::Vector2d project(const Eigen::Vector3d& p) const {
    const Eigen::Vector3d d = p - origin;
    return {d.dot(u), d.dot(v)};
  }
  Eigen::Vector3d lift(const Eigen::Vector2d& q) const { return origin + q.x() * u + q.y() * v; }
};

struct RefinedPlane {
  Plane plane;
  std::vector<int> inliers;  // indices into the valid points
  double rms = 0.0;
};

// Fewest returns of a sparse candidate: a few on each of the lines it needs.
constexpr int kSparsePointsPerLine = 4;
constexpr double kSparseLineGapVoxels =
    0.5;  // segments where lines are farther apart than this many voxels
constexpr double kSparseMinWidthRatio = 0.8;  // of the widest chord a board's middle line must show

// Stage 1: valid points (finite, in range, in the ROI, not background).
std::vector<ValidPoint> validPoints(const LidarCloud& cloud, const LidarBoardDetectorOptions& o,
                                    const BackgroundModel* background);
// Stage 2: voxels with plane statistics, planar region growing, candidates.
VoxelGrid buildVoxels(const std::vector<ValidPoint>& pts, double size);
std::vector<Region> growPlanarRegions(VoxelGrid& g, const LidarBoardDetectorOptions& o);
bool makePlaneFrame(const Eigen::Vector3d& normal, const Eigen::Vector3d& point, PlaneFrame* f);
// The board's in-plane frame at its points' centroid projected onto `plane`; false as
// makePlaneFrame (a nearly horizontal board). `centroid` receives that projected centroid.
bool boardFrameAtCentroid(const std::vector<ValidPoint>& pts, const std::vector<int>& board,
                          const Plane& plane, Eigen::Vector3d* centroid, PlaneFrame* frame);
Candidate scoreRegion(const Region& r, int region_id, const VoxelGrid& g,
                      const std::vector<ValidPoint>& pts, const Target& target,
                      const LidarBoardDetectorOptions& o);
int sparseMinPoints(const LidarBoardDetectorOptions& o);
/// Candidates from scan-line segments where the lines are too far apart for the voxels;
/// appended to `regions` and `candidates` unless a voxel candidate already covers them.
void addSparseCandidates(const LidarCloud& cloud, const std::vector<ValidPoint>& pts,
                         const VoxelGrid& grid, const Target& target,
                         const LidarBoardDetectorOptions& options, std::vector<Region>* regions,
                         std::vector<Candidate>* candidates);
// Stage 3: plane refinement (RANSAC seeded from the region, least squares on the inliers).
RefinedPlane refinePlane(const std::vector<int>& region_points, const std::vector<int>& gathered,
                         const std::vector<ValidPoint>& pts, const LidarBoardDetectorOptions& o,
                         std::mt19937& rng);
/// Points of a region and of its neighbouring voxels; of a neighbour that belongs to another
/// large plane, only the returns on the board's plane, and only when the rest lie clear of it.
void gatherRegionPoints(const std::vector<Region>& regions, int region_id, const VoxelGrid& grid,
                        const std::vector<ValidPoint>& pts,
                        const LidarBoardDetectorOptions& options, std::vector<int>* region_points,
                        std::vector<int>* gathered);
// Stage 4: scan lines and edges.
std::vector<int> scanLines(const LidarCloud& cloud, const std::vector<int>& board,
                           const std::vector<ValidPoint>& pts, const LidarBoardDetectorOptions& o,
                           std::string* source);
/// Per scan line: the board's extreme points in azimuth (left = larger azimuth seen from the
/// sensor, measured from the centroid's azimuth) and the line's point count, by line id.
struct LineExtremes {
  int count = 0;
  int left = -1, right = -1;  ///< indices into pts
  double left_az = -std::numeric_limits<double>::infinity(),
         right_az = std::numeric_limits<double>::infinity();
};
/// `Map` is std::map or std::unordered_map<int, LineExtremes>: the edge fits iterate the lines in
/// the map's order and their RANSAC depends on it, so each caller keeps the order its figures were
/// measured with.
template <typename Map>
Map lineExtremes(const std::vector<ValidPoint>& pts, const std::vector<int>& board,
                 const std::vector<int>& line, const Eigen::Vector3d& centroid) {
  const double center_azimuth = std::atan2(centroid.y(), centroid.x());
  Map per_line;
  for (size_t k = 0; k < board.size(); ++k) {
    const auto& p = pts[board[k]].p;
    const double az = wrapAngle(std::atan2(p.y(), p.x()) - center_azimuth);
    LineExtremes& e = per_line[line[k]];
    ++e.count;
    if (az > e.left_az) {
      e.left_az = az;
      e.left = board[k];
    }
    if (az < e.right_az) {
      e.right_az = az;
      e.right = board[k];
    }
  }
  return per_line;
}
/// Sparse boards: the declared rectangle fitted to the per-line extremes; false when it does not
/// fit.
bool extractEdgesByRectangle(const LidarCloud& cloud, const std::vector<ValidPoint>& pts,
                             const std::vector<int>& board, const Target& target,
                             const LidarBoardDetectorOptions& o, LidarBoardDetection* det);
void extractEdges(const LidarCloud& cloud, const std::vector<ValidPoint>& pts,
                  const std::vector<int>& board, const Target& target,
                  const LidarBoardDetectorOptions& o, std::mt19937& rng, LidarBoardDetection* det);

// History of a stateful detector: whether a board-like candidate sits at a static place, and
// whether two unknown places are ambiguous whatever their support.
struct History {
  std::function<bool(const LidarBoardCandidate&)> is_static;
  bool strict_ambiguity = false;
  /// Second chance: why a candidate lies outside the expected region (empty: inside); unset
  /// when the whole cloud is searched.
  std::function<std::string(const LidarBoardCandidate&)> outside_expected;
};

/// The detector's stages on one cloud; `history` may be null (single-cloud rules).
LidarBoardDetection detectImpl(const LidarCloud& cloud, const Target& target,
                               const LidarBoardDetectorOptions& options,
                               const BackgroundModel* background, const History* history);

}  // namespace lidar_detail
}  // namespace board_calib
