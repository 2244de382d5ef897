// SPDX-License-Identifier: BSD-3-Clause
// Camera images: one ray per pixel centre through a cached per-camera ray map, then
// supersampling only where the surface label changes within the 3x3 neighbourhood, so edges
// are anti-aliased (sub-pixel true) at a fraction of the cost of supersampling everything.
#include <board_calib/core/sim/simulator.h>

#include "scene.h"

#include <opencv2/core/utility.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <map>
#include <memory>
#include <mutex>
#include <sstream>

namespace board_calib {
namespace sim {
namespace {

using internal::Hit;
using internal::Scene;

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
    return (at(u0, v0) * (1 - a) + at(u1, v0) * a) * (1 - b) +
           (at(u0, v1) * (1 - a) + at(u1, v1) * a) * b;
  }
};

std::string intrinsicsKey(const CameraIntrinsics& in) {
  std::ostringstream key;
  key.precision(17);
  key << in.width << ' ' << in.height << ' ' << in.fx << ' ' << in.fy << ' ' << in.cx << ' '
      << in.cy << ' ' << static_cast<int>(in.model);
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
      Eigen::Vector2d x =
          camera.undistortNormalized(Eigen::Vector2d(0, v));  // robust start of each row
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
// Camera
// ---------------------------------------------------------------------------------------------
cv::Mat renderCameraImage(const CameraModel& camera, const Eigen::Isometry3d& world_T_camera,
                          const SceneSpec& scene, const Eigen::Isometry3d& world_T_board,
                          const RenderOptions& options, std::mt19937& rng) {
  const cv::Mat radiance =
      renderCameraRadiance(camera, world_T_camera, scene, world_T_board, options);
  if (radiance.empty()) return cv::Mat();
  return finishCameraImage(radiance, camera, options, rng);
}

cv::Mat renderCameraRadiance(const CameraModel& camera, const Eigen::Isometry3d& world_T_camera,
                             const SceneSpec& scene, const Eigen::Isometry3d& world_T_board,
                             const RenderOptions& options) {
  const int w = camera.width(), h = camera.height();
  if (w <= 0 || h <= 0 || !options.validate().empty() || !scene.validate().empty())
    return cv::Mat();
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
        row[u] =
            cv::Vec3f(static_cast<float>(c[0]), static_cast<float>(c[1]), static_cast<float>(c[2]));
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
          colour.at<cv::Vec3f>(v, u) = cv::Vec3f(
              static_cast<float>(sum[0]), static_cast<float>(sum[1]), static_cast<float>(sum[2]));
        }
      }
    });
  }

  return colour;
}

cv::Mat finishCameraImage(const cv::Mat& radiance, const CameraModel& camera,
                          const RenderOptions& options, std::mt19937& rng) {
  if (radiance.empty() || radiance.type() != CV_32FC3 || !options.validate().empty())
    return cv::Mat();
  const int w = radiance.cols, h = radiance.rows;
  cv::Mat colour = radiance;
  if (options.blur_sigma_px > 0)
    cv::GaussianBlur(radiance, colour, cv::Size(0, 0), options.blur_sigma_px);

  // Vignetting (radial, quadratic in the distance from the principal point), then 8 bit + noise.
  const auto& in = camera.intrinsics();
  const double r_max2 =
      std::max({in.cx * in.cx + in.cy * in.cy, (w - in.cx) * (w - in.cx) + in.cy * in.cy,
                in.cx * in.cx + (h - in.cy) * (h - in.cy),
                (w - in.cx) * (w - in.cx) + (h - in.cy) * (h - in.cy)});
  // A mono sensor sees the scene's luminance, with its noise on that one channel.
  if (options.mono) cv::cvtColor(colour, colour, cv::COLOR_BGR2GRAY);
  const int channels = colour.channels();
  cv::Mat noise;
  if (options.noise_sigma > 0) {
    noise.create(h, w, CV_32FC(channels));
    cv::RNG cv_rng(static_cast<uint64_t>(rng()) << 32 | rng());
    cv_rng.fill(noise, cv::RNG::NORMAL, 0.0, options.noise_sigma);
  }
  cv::Mat image(h, w, CV_8UC(channels));
  for (int v = 0; v < h; ++v) {
    const float* src = colour.ptr<float>(v);
    const float* nrow = noise.empty() ? nullptr : noise.ptr<float>(v);
    uint8_t* dst = image.ptr<uint8_t>(v);
    for (int u = 0; u < w; ++u) {
      const double r2 = ((u - in.cx) * (u - in.cx) + (v - in.cy) * (v - in.cy)) / r_max2;
      const double gain = 255.0 * (1.0 - options.vignetting * r2);
      for (int c = 0; c < channels; ++c) {
        const int k = u * channels + c;
        const double value = src[k] * gain + (nrow ? nrow[k] : 0.0f);
        dst[k] = cv::saturate_cast<uint8_t>(value);
      }
    }
  }
  return image;
}

}  // namespace sim
}  // namespace board_calib
