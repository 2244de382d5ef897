#include <board_calib/core/pipeline/scene_prepass.h>

#include <opencv2/core.hpp>

#include <cmath>
#include <limits>

namespace board_calib {

std::string ScenePrepassOptions::validate() const {
  if (frames_per_static < 0) return "frames_per_static must be >= 0";
  return {};
}

Expected<ScenePrepass> ScenePrepass::create(const Target& target,
                                            const ImageBoardDetectorOptions& detector,
                                            const StaticMemoryOptions& memory,
                                            const ScenePrepassOptions& options) {
  if (const std::string why = options.validate(); !why.empty())
    return Expected<ScenePrepass>::failure("scene pre-pass: " + why);
  auto tracker = ImageBoardTracker::create(target, detector, memory);
  if (!tracker) return Expected<ScenePrepass>::failure(tracker.error());
  const double period_s = options.frames_per_static > 0
                              ? memory.static_after_s / options.frames_per_static
                              : std::numeric_limits<double>::infinity();
  return Expected<ScenePrepass>(ScenePrepass(std::move(*tracker), period_s, options.rectangles));
}

bool ScenePrepass::wants(double stamp) const {
  // A stamp going back (a second recording) starts over, as the tracker does.
  return std::isfinite(period_s_) && (stamp < last_stamp_ || stamp - last_stamp_ >= period_s_);
}

bool ScenePrepass::add(const cv::Mat& image, const CameraIntrinsics& intrinsics, double stamp) {
  if (!wants(stamp)) return false;
  if (!intrinsics_ || *intrinsics_ != intrinsics) {
    auto model = CameraModel::create(intrinsics);
    if (!model) return false;
    intrinsics_ = intrinsics;
    camera_ = *model;
  }
  if (image.cols != camera_->width() || image.rows != camera_->height()) return false;
  last_stamp_ = stamp;
  // OpenCV asserts on degenerate input: such an image teaches nothing.
  try {
    tracker_.learnScene(image, *camera_, stamp, rectangles_);
  } catch (const cv::Exception&) {
    return false;
  }
  return true;
}

}  // namespace board_calib
