#include <board_calib/core/lidar_detection/lidar_board_detector.h>

#include <cmath>
#include <limits>
#include <unordered_map>
#include <unordered_set>

namespace board_calib {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kDegPerRad = 180.0 / kPi;
constexpr float kNoReturn = std::numeric_limits<float>::infinity();
constexpr int64_t kVoxelOffset = 1 << 20;

enum class Layout { kNone, kRangeImage, kRingAzimuth, kVoxels };

double rangeOf(const LidarPoint& p) {
  if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z)) return -1.0;
  return std::sqrt(double(p.x) * p.x + double(p.y) * p.y + double(p.z) * p.z);
}

int64_t packVoxel(int64_t ix, int64_t iy, int64_t iz) {
  return ((ix + kVoxelOffset) << 42) | ((iy + kVoxelOffset) << 21) | (iz + kVoxelOffset);
}

}  // namespace

std::string BackgroundModelOptions::validate() const {
  if (!(range_margin_m > 0.0)) return "range_margin_m must be > 0";
  if (!(azimuth_bin_deg > 0.0 && azimuth_bin_deg <= 10.0))
    return "azimuth_bin_deg must be in (0, 10]";
  if (!(voxel_size_m > 0.0)) return "voxel_size_m must be > 0";
  if (!(min_range_m >= 0.0)) return "min_range_m must be >= 0";
  return {};
}

struct BackgroundModel::Impl {
  BackgroundModelOptions options;
  Layout layout = Layout::kNone;
  int frames = 0;
  int width = 0, height = 0;
  // Closest background range per cell: kRangeImage (row * width + col) or kRingAzimuth.
  std::vector<float> min_range;
  std::unordered_map<int64_t, float> ring_azimuth;  // key: ring * bins + bin
  std::unordered_set<int64_t> voxels;

  int azimuthBins() const { return static_cast<int>(std::ceil(360.0 / options.azimuth_bin_deg)); }
  int64_t ringAzimuthKey(const LidarPoint& p) const {
    double az = std::atan2(p.y, p.x) * kDegPerRad;
    if (az < 0) az += 360.0;
    const int bin = std::min(azimuthBins() - 1, static_cast<int>(az / options.azimuth_bin_deg));
    return static_cast<int64_t>(p.ring) * azimuthBins() + bin;
  }
  int64_t voxelKey(const LidarPoint& p, int dx = 0, int dy = 0, int dz = 0) const {
    const double s = options.voxel_size_m;
    return packVoxel(static_cast<int64_t>(std::floor(p.x / s)) + dx,
                     static_cast<int64_t>(std::floor(p.y / s)) + dy,
                     static_cast<int64_t>(std::floor(p.z / s)) + dz);
  }
  bool isReturn(const LidarPoint& p) const {
    const double r = rangeOf(p);
    return r >= options.min_range_m && r > 0.0;
  }
};

BackgroundModel::BackgroundModel(BackgroundModelOptions options) : impl_(std::make_unique<Impl>()) {
  impl_->options = options;
}
BackgroundModel::~BackgroundModel() = default;
BackgroundModel::BackgroundModel(BackgroundModel&&) noexcept = default;
BackgroundModel& BackgroundModel::operator=(BackgroundModel&&) noexcept = default;

int BackgroundModel::numFrames() const { return impl_->frames; }

void BackgroundModel::clear() {
  const auto options = impl_->options;
  impl_ = std::make_unique<Impl>();
  impl_->options = options;
}

Status BackgroundModel::addFrame(const LidarCloud& cloud) {
  auto& m = *impl_;
  const std::string bad = m.options.validate();
  if (!bad.empty()) return Status::failure("invalid background options: " + bad);
  if (cloud.points.empty()) return Status::failure("background frame is empty");
  if (cloud.organized() && static_cast<size_t>(cloud.width) * cloud.height != cloud.points.size())
    return Status::failure("background frame: width x height does not match the number of points");
  Layout layout = Layout::kVoxels;
  if (cloud.organized())
    layout = Layout::kRangeImage;
  else if (cloud.has_ring)
    layout = Layout::kRingAzimuth;
  if (m.layout != Layout::kNone && layout != m.layout)
    return Status::failure(
        "background frame layout differs from the captured ones (clear the model first)");
  if (layout == Layout::kRangeImage && m.layout == Layout::kRangeImage &&
      (cloud.width != m.width || cloud.height != m.height))
    return Status::failure("background frame is " + std::to_string(cloud.width) + "x" +
                           std::to_string(cloud.height) + ", the model " + std::to_string(m.width) +
                           "x" + std::to_string(m.height));
  if (m.layout == Layout::kNone && layout == Layout::kRangeImage) {
    m.width = cloud.width;
    m.height = cloud.height;
    m.min_range.assign(cloud.points.size(), kNoReturn);
  }
  m.layout = layout;
  for (size_t i = 0; i < cloud.points.size(); ++i) {
    const auto& p = cloud.points[i];
    if (!m.isReturn(p)) continue;
    const float r = static_cast<float>(rangeOf(p));
    switch (layout) {
      case Layout::kRangeImage: m.min_range[i] = std::min(m.min_range[i], r); break;
      case Layout::kRingAzimuth: {
        if (p.ring < 0) break;
        auto it = m.ring_azimuth.emplace(m.ringAzimuthKey(p), r).first;
        it->second = std::min(it->second, r);
        break;
      }
      case Layout::kVoxels: m.voxels.insert(m.voxelKey(p)); break;
      case Layout::kNone: break;
    }
  }
  ++m.frames;
  return Status::success();
}

std::vector<uint8_t> BackgroundModel::foregroundMask(const LidarCloud& cloud) const {
  const auto& m = *impl_;
  std::vector<uint8_t> mask(cloud.points.size(), 1);
  if (m.frames == 0) return mask;
  const float margin = static_cast<float>(m.options.range_margin_m);
  const bool same_image = m.layout == Layout::kRangeImage && cloud.organized() &&
                          cloud.width == m.width && cloud.height == m.height &&
                          cloud.points.size() == m.min_range.size();
  for (size_t i = 0; i < cloud.points.size(); ++i) {
    const auto& p = cloud.points[i];
    if (!m.isReturn(p)) {
      mask[i] = 0;
      continue;
    }
    const float r = static_cast<float>(rangeOf(p));
    if (same_image) {
      mask[i] = r < m.min_range[i] - margin;
    } else if (m.layout == Layout::kRingAzimuth && p.ring >= 0) {
      const auto it = m.ring_azimuth.find(m.ringAzimuthKey(p));
      mask[i] = it == m.ring_azimuth.end() || r < it->second - margin;
    } else if (m.layout == Layout::kVoxels || m.layout == Layout::kRingAzimuth ||
               m.layout == Layout::kRangeImage) {
      // Without a matching layout fall back on occupancy of the neighbourhood: only possible
      // with voxels, so a mismatched range image / ring model keeps everything.
      if (m.layout != Layout::kVoxels) continue;
      bool occupied = false;
      for (int dx = -1; dx <= 1 && !occupied; ++dx)
        for (int dy = -1; dy <= 1 && !occupied; ++dy)
          for (int dz = -1; dz <= 1 && !occupied; ++dz)
            occupied = m.voxels.count(m.voxelKey(p, dx, dy, dz)) > 0;
      mask[i] = !occupied;
    }
  }
  return mask;
}

}  // namespace board_calib
