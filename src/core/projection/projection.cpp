#include <board_calib/core/projection/projection.h>

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>

namespace board_calib {

namespace {

constexpr int kColorTableSize = 256;
// Depth bins for the far-to-near drawing order (a counting sort; exact order within a bin
// does not matter visually).
constexpr int kDepthOrderBins = 1024;
// Percentiles of the automatic intensity scale.
constexpr double kAutoIntensityLow = 0.02;
constexpr double kAutoIntensityHigh = 0.98;

bool validPoint(const LidarPoint& p) {
  return std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z) &&
         (p.x != 0.f || p.y != 0.f || p.z != 0.f);
}

Status toBgr(cv::Mat* image) {
  if (image == nullptr || image->empty()) return Status::failure("image is empty");
  if (image->type() == CV_8UC3) return Status::success();
  if (image->type() == CV_8UC1) {
    cv::Mat bgr;
    cv::cvtColor(*image, bgr, cv::COLOR_GRAY2BGR);
    *image = bgr;
    return Status::success();
  }
  return Status::failure("image must be 8-bit mono or bgr (OpenCV type " +
                         std::to_string(image->type()) + ")");
}

// Offsets of a filled disc of the given radius.
std::vector<cv::Point> discOffsets(int radius) {
  std::vector<cv::Point> offsets;
  const int r2 = radius * radius + radius;  // slightly rounder than dx^2 + dy^2 <= r^2
  for (int dy = -radius; dy <= radius; ++dy)
    for (int dx = -radius; dx <= radius; ++dx)
      if (dx * dx + dy * dy <= r2) offsets.emplace_back(dx, dy);
  return offsets;
}

int tableIndex(double value, double lo, double hi) {
  if (!(hi > lo)) return 0;
  const double s = (value - lo) / (hi - lo);
  return std::clamp(static_cast<int>(s * (kColorTableSize - 1) + 0.5), 0, kColorTableSize - 1);
}

}  // namespace

const char* colorModeName(ColorMode mode) {
  switch (mode) {
    case ColorMode::kDepth: return "depth";
    case ColorMode::kIntensity: return "intensity";
    case ColorMode::kFlat: return "flat";
  }
  return "unknown";
}

Expected<ColorMode> parseColorMode(const std::string& name) {
  if (name == "depth") return ColorMode::kDepth;
  if (name == "intensity") return ColorMode::kIntensity;
  if (name == "flat") return ColorMode::kFlat;
  return Expected<ColorMode>::failure("unknown colour mode '" + name +
                                      "' (depth, intensity, flat)");
}

std::string ProjectionOptions::validate() const {
  std::ostringstream why;
  if (!(min_depth_m >= 0.0) || !std::isfinite(min_depth_m))
    why << "min_depth_m must be >= 0";
  else if (!(max_depth_m > min_depth_m) || !std::isfinite(max_depth_m))
    why << "max_depth_m must exceed min_depth_m";
  else if (zbuffer_cell_px < 0)
    why << "zbuffer_cell_px must be >= 0 (0 disables occlusion culling)";
  else if (!(occlusion_tolerance_m >= 0.0))
    why << "occlusion_tolerance_m must be >= 0";
  else if (!(margin_px >= 0.0))
    why << "margin_px must be >= 0";
  return why.str();
}

std::string OverlayOptions::validate() const {
  std::ostringstream why;
  if (!(depth_max_m > depth_min_m))
    why << "depth_max_m must exceed depth_min_m";
  else if (point_radius_px < 0 || point_radius_px > 50)
    why << "point_radius_px must be in [0, 50]";
  else if (!(alpha >= 0.0 && alpha <= 1.0))
    why << "alpha must be in [0, 1]";
  else if (!std::isfinite(intensity_min) || !std::isfinite(intensity_max))
    why << "intensity scale must be finite";
  return why.str();
}

const std::vector<cv::Vec3b>& colorTable() {
  static const std::vector<cv::Vec3b> table = [] {
    cv::Mat ramp(1, kColorTableSize, CV_8UC1), colored;
    for (int i = 0; i < kColorTableSize; ++i)
      ramp.at<std::uint8_t>(0, i) = static_cast<std::uint8_t>(i);
    cv::applyColorMap(ramp, colored, cv::COLORMAP_JET);
    std::vector<cv::Vec3b> out(kColorTableSize);
    for (int i = 0; i < kColorTableSize; ++i) out[i] = colored.at<cv::Vec3b>(0, i);
    return out;
  }();
  return table;
}

Expected<ProjectedCloud> projectCloud(const LidarCloud& cloud, const CameraModel& camera,
                                      const Eigen::Isometry3d& camera_T_lidar,
                                      const ProjectionOptions& options) {
  const std::string why = options.validate();
  if (!why.empty()) return Expected<ProjectedCloud>::failure("projection options: " + why);
  if (camera.width() <= 0 || camera.height() <= 0)
    return Expected<ProjectedCloud>::failure(
        "camera model has no image size (not created from intrinsics?)");
  if (!camera_T_lidar.matrix().allFinite())
    return Expected<ProjectedCloud>::failure("camera_T_lidar is not finite");

  ProjectedCloud out;
  out.points.reserve(cloud.points.size() / 4);
  const Eigen::Matrix3d R = camera_T_lidar.linear();
  const Eigen::Vector3d t = camera_T_lidar.translation();
  for (size_t i = 0; i < cloud.points.size(); ++i) {
    const LidarPoint& lp = cloud.points[i];
    if (!validPoint(lp)) {
      ++out.invalid;
      continue;
    }
    const Eigen::Vector3d pc = R * Eigen::Vector3d(lp.x, lp.y, lp.z) + t;
    if (!(pc.z() >= options.min_depth_m && pc.z() <= options.max_depth_m)) {
      ++out.out_of_range;
      continue;
    }
    if (!camera.isVisible(pc, options.margin_px)) {
      ++out.outside_image;
      continue;
    }
    Eigen::Vector2d px = Eigen::Vector2d::Zero();
    camera.project(pc, &px);
    ProjectedPoint pp;
    pp.u = static_cast<float>(px.x());
    pp.v = static_cast<float>(px.y());
    pp.depth = static_cast<float>(pc.z());
    pp.intensity = lp.intensity;
    pp.index = static_cast<int>(i);
    out.points.push_back(pp);
  }

  if (options.zbuffer_cell_px > 0 && !out.points.empty()) {
    // Cells cover the image plus the margin on every side.
    const int cell = options.zbuffer_cell_px;
    const int margin = static_cast<int>(std::ceil(options.margin_px));
    const int cols = (camera.width() + 2 * margin) / cell + 1;
    const int rows = (camera.height() + 2 * margin) / cell + 1;
    auto cellOf = [&](const ProjectedPoint& p) {
      const int cx = std::clamp(static_cast<int>(std::floor((p.u + margin) / cell)), 0, cols - 1);
      const int cy = std::clamp(static_cast<int>(std::floor((p.v + margin) / cell)), 0, rows - 1);
      return cy * cols + cx;
    };
    std::vector<float> nearest(static_cast<size_t>(cols) * rows, std::numeric_limits<float>::max());
    for (const auto& p : out.points) {
      float& n = nearest[cellOf(p)];
      n = std::min(n, p.depth);
    }
    const float tolerance = static_cast<float>(options.occlusion_tolerance_m);
    const size_t before = out.points.size();
    out.points.erase(std::remove_if(out.points.begin(), out.points.end(),
                                    [&](const ProjectedPoint& p) {
                                      return p.depth > nearest[cellOf(p)] + tolerance;
                                    }),
                     out.points.end());
    out.occluded = static_cast<int>(before - out.points.size());
  }
  return out;
}

Status drawProjectedCloud(const ProjectedCloud& projected, const OverlayOptions& options,
                          cv::Mat* image) {
  const std::string why = options.validate();
  if (!why.empty()) return Status::failure("overlay options: " + why);
  Status bgr = toBgr(image);
  if (!bgr) return bgr;
  if (projected.points.empty()) return Status::success();

  double lo = 0, hi = 1;
  if (options.color_mode == ColorMode::kDepth) {
    lo = options.depth_min_m;
    hi = options.depth_max_m;
  } else if (options.color_mode == ColorMode::kIntensity) {
    lo = options.intensity_min;
    hi = options.intensity_max;
    if (!(hi > lo)) {
      std::vector<float> values;
      values.reserve(projected.points.size());
      for (const auto& p : projected.points) values.push_back(p.intensity);
      const size_t k_lo = static_cast<size_t>(kAutoIntensityLow * (values.size() - 1));
      const size_t k_hi = static_cast<size_t>(kAutoIntensityHigh * (values.size() - 1));
      std::nth_element(values.begin(), values.begin() + k_lo, values.end());
      lo = values[k_lo];
      std::nth_element(values.begin(), values.begin() + k_hi, values.end());
      hi = values[k_hi];
      if (!(hi > lo)) hi = lo + 1.0;
    }
  }

  // Far to near by a counting sort over depth bins.
  float max_depth = 0.f;
  for (const auto& p : projected.points) max_depth = std::max(max_depth, p.depth);
  const float bin_scale = (kDepthOrderBins - 1) / std::max(max_depth, 1e-3f);
  std::vector<int> counts(kDepthOrderBins + 1, 0);
  std::vector<int> bins(projected.points.size());
  for (size_t i = 0; i < projected.points.size(); ++i) {
    bins[i] = kDepthOrderBins - 1 - static_cast<int>(projected.points[i].depth * bin_scale);
    ++counts[bins[i] + 1];
  }
  for (int b = 0; b < kDepthOrderBins; ++b) counts[b + 1] += counts[b];
  std::vector<int> order(projected.points.size());
  for (size_t i = 0; i < projected.points.size(); ++i)
    order[counts[bins[i]]++] = static_cast<int>(i);

  const auto& table = colorTable();
  const std::vector<cv::Point> disc = discOffsets(options.point_radius_px);
  const int w = image->cols, h = image->rows;
  const bool blend = options.alpha < 1.0;
  const float a = static_cast<float>(options.alpha);
  for (const int i : order) {
    const ProjectedPoint& p = projected.points[i];
    cv::Vec3b color = options.flat_color;
    if (options.color_mode == ColorMode::kDepth)
      color = table[kColorTableSize - 1 - tableIndex(p.depth, lo, hi)];
    else if (options.color_mode == ColorMode::kIntensity)
      color = table[tableIndex(p.intensity, lo, hi)];
    const int cu = static_cast<int>(std::lround(p.u)), cv_ = static_cast<int>(std::lround(p.v));
    for (const cv::Point& o : disc) {
      const int x = cu + o.x, y = cv_ + o.y;
      if (x < 0 || y < 0 || x >= w || y >= h) continue;
      cv::Vec3b& dst = image->ptr<cv::Vec3b>(y)[x];
      if (!blend) {
        dst = color;
      } else {
        for (int c = 0; c < 3; ++c)
          dst[c] = static_cast<std::uint8_t>(a * color[c] + (1.f - a) * dst[c] + 0.5f);
      }
    }
  }
  return Status::success();
}

int drawUndistortedSegment(const Eigen::Vector2d& from, const Eigen::Vector2d& to,
                           const CameraModel& camera, const LineStyle& style, cv::Mat* image) {
  if (image == nullptr || image->empty() || !from.allFinite() || !to.allFinite()) return 0;
  if (!(style.sample_step_px > 0.0)) return 0;
  const double length = (to - from).norm();
  // Bound the sample count: a line clipped to a sane region never needs more.
  constexpr int kMaxSamples = 100000;
  const int n =
      std::clamp(static_cast<int>(std::ceil(length / style.sample_step_px)), 1, kMaxSamples);
  const Eigen::Matrix3d K_inv = camera.K().inverse();
  const cv::Scalar color(style.color[0], style.color[1], style.color[2]);
  int segments = 0;
  bool have_prev = false;
  cv::Point2d prev;
  // Draw margin: segments may start a little outside the image so lines reach the border.
  const double margin = 2.0 * style.sample_step_px;
  for (int i = 0; i <= n; ++i) {
    const Eigen::Vector2d u = from + (to - from) * (static_cast<double>(i) / n);
    const Eigen::Vector3d ray = K_inv * Eigen::Vector3d(u.x(), u.y(), 1.0);
    if (!camera.isVisible(ray, margin)) {
      have_prev = false;
      continue;
    }
    const Eigen::Vector2d d = camera.distortPixel(u);
    const cv::Point2d cur(d.x(), d.y());
    if (have_prev) {
      cv::line(*image, prev, cur, color, style.thickness_px, cv::LINE_AA);
      ++segments;
    }
    prev = cur;
    have_prev = true;
  }
  return segments;
}

int drawUndistortedLine(const Eigen::Vector3d& line, const CameraModel& camera,
                        const LineStyle& style, cv::Mat* image) {
  const double a = line.x(), b = line.y(), c = line.z();
  const double norm = std::hypot(a, b);
  if (!(norm > 0) || !std::isfinite(c)) return 0;
  // Clip to a box around the image that contains its undistorted bounds for realistic lenses
  // (isVisible culls the rest sample by sample).
  const double w = camera.width(), h = camera.height();
  const double x0 = -0.5 * w, x1 = 1.5 * w, y0 = -0.5 * h, y1 = 1.5 * h;
  // Intersections with the box's four sides; keep those on the box.
  std::vector<Eigen::Vector2d> hits;
  if (std::abs(b) > 1e-12) {
    for (const double x : {x0, x1}) {
      const double y = -(a * x + c) / b;
      if (y >= y0 && y <= y1) hits.emplace_back(x, y);
    }
  }
  if (std::abs(a) > 1e-12) {
    for (const double y : {y0, y1}) {
      const double x = -(b * y + c) / a;
      if (x >= x0 && x <= x1) hits.emplace_back(x, y);
    }
  }
  if (hits.size() < 2) return 0;
  // The two hits farthest apart span the clipped line.
  size_t bi = 0, bj = 1;
  double best = -1;
  for (size_t i = 0; i < hits.size(); ++i)
    for (size_t j = i + 1; j < hits.size(); ++j)
      if ((hits[i] - hits[j]).squaredNorm() > best) {
        best = (hits[i] - hits[j]).squaredNorm();
        bi = i;
        bj = j;
      }
  return drawUndistortedSegment(hits[bi], hits[bj], camera, style, image);
}

Expected<ColoredCloud> colorCloud(const LidarCloud& cloud, const ProjectedCloud& projected,
                                  const cv::Mat& image) {
  if (image.empty()) return Expected<ColoredCloud>::failure("image is empty");
  if (image.type() != CV_8UC3 && image.type() != CV_8UC1)
    return Expected<ColoredCloud>::failure("image must be 8-bit mono or bgr (OpenCV type " +
                                           std::to_string(image.type()) + ")");
  ColoredCloud out;
  out.frame_id = cloud.frame_id;
  out.stamp = cloud.stamp;
  out.points.reserve(projected.points.size());
  const bool mono = image.type() == CV_8UC1;
  const int w = image.cols, h = image.rows;
  for (const ProjectedPoint& p : projected.points) {
    if (p.index < 0 || static_cast<size_t>(p.index) >= cloud.points.size())
      return Expected<ColoredCloud>::failure(
          "projection does not belong to this cloud (index out of range)");
    // Bilinear sample at the pixel centre convention of OpenCV (integer = pixel centre).
    const float u = std::clamp(p.u, 0.f, static_cast<float>(w - 1));
    const float v = std::clamp(p.v, 0.f, static_cast<float>(h - 1));
    const int x0 = std::min(static_cast<int>(u), w - 1), y0 = std::min(static_cast<int>(v), h - 1);
    const int x1 = std::min(x0 + 1, w - 1), y1 = std::min(y0 + 1, h - 1);
    const float fx = u - x0, fy = v - y0;
    const float w00 = (1 - fx) * (1 - fy), w01 = fx * (1 - fy), w10 = (1 - fx) * fy, w11 = fx * fy;
    float bgr[3];
    if (mono) {
      const float g = w00 * image.at<std::uint8_t>(y0, x0) + w01 * image.at<std::uint8_t>(y0, x1) +
                      w10 * image.at<std::uint8_t>(y1, x0) + w11 * image.at<std::uint8_t>(y1, x1);
      bgr[0] = bgr[1] = bgr[2] = g;
    } else {
      const cv::Vec3b &c00 = image.at<cv::Vec3b>(y0, x0), &c01 = image.at<cv::Vec3b>(y0, x1),
                      &c10 = image.at<cv::Vec3b>(y1, x0), &c11 = image.at<cv::Vec3b>(y1, x1);
      for (int c = 0; c < 3; ++c)
        bgr[c] = w00 * c00[c] + w01 * c01[c] + w10 * c10[c] + w11 * c11[c];
    }
    const LidarPoint& lp = cloud.points[p.index];
    ColoredPoint cp;
    cp.x = lp.x;
    cp.y = lp.y;
    cp.z = lp.z;
    cp.intensity = lp.intensity;
    cp.b = static_cast<std::uint8_t>(std::clamp(bgr[0] + 0.5f, 0.f, 255.f));
    cp.g = static_cast<std::uint8_t>(std::clamp(bgr[1] + 0.5f, 0.f, 255.f));
    cp.r = static_cast<std::uint8_t>(std::clamp(bgr[2] + 0.5f, 0.f, 255.f));
    out.points.push_back(cp);
  }
  return out;
}

std::array<Eigen::Vector3d, 4> frustumCorners(const CameraModel& camera, const double depth_m) {
  const double w = camera.width(), h = camera.height();
  // Pixel centres of the corner pixels' outer edges (OpenCV: pixel centre at integer).
  const std::array<Eigen::Vector2d, 4> px = {
      Eigen::Vector2d(-0.5, -0.5), Eigen::Vector2d(w - 0.5, -0.5),
      Eigen::Vector2d(w - 0.5, h - 0.5), Eigen::Vector2d(-0.5, h - 0.5)};
  std::array<Eigen::Vector3d, 4> out;
  for (int i = 0; i < 4; ++i) {
    const Eigen::Vector3d ray = camera.unprojectRay(px[i]);
    out[i] = ray * (depth_m / ray.z());
  }
  return out;
}

}  // namespace board_calib
