// ImageBoardTracker: the session memory of one camera's static scene. Places are compared with
// one tolerance, the line stage's merge band (a held board's bow, or the segment ends' noise at
// the line detector's scale): two sightings of a window whose sides and corners agree that well
// are one window. Measured on the simulated street: a static window's refined corners move
// 0.0-0.2 px between frames (once 1.1 px), the band is 3.5-4.2 px at 1440-1920 px.
#include <board_calib/core/image_detection/image_board_tracker.h>

#include "detection_internal.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>

#include <opencv2/imgproc.hpp>

namespace board_calib {
namespace {

constexpr size_t kMinBackgroundFrames = 5;  // a median of fewer is the board wherever it held
// At most this many frames (4 per static_after_s over forget_after_s is 20 by default): a short
// static_after_s must not fill memory with frames.
constexpr size_t kMaxBackgroundFrames = 24;

}  // namespace

Expected<ImageBoardTracker> ImageBoardTracker::create(const Target& target,
                                                      const ImageBoardDetectorOptions& detector,
                                                      const StaticMemoryOptions& memory) {
  if (const std::string why = memory.validate(); !why.empty())
    return Expected<ImageBoardTracker>::failure("static memory: " + why);
  auto d = ImageBoardDetector::create(target, detector);
  if (!d) return Expected<ImageBoardTracker>::failure(d.error());
  return Expected<ImageBoardTracker>(ImageBoardTracker(std::move(*d), memory));
}

std::string ImageBoardTracker::setDetectorOptions(const ImageBoardDetectorOptions& options) {
  auto d = ImageBoardDetector::create(detector_.target(), options);
  if (!d) return d.error();
  detector_ = std::move(*d);
  return {};
}

void ImageBoardTracker::reset() {
  places_.clear();
  lines_.clear();
  frames_ = 0;
  last_stamp_ = -1e300;
  background_frames_.clear();
  background_stamps_.clear();
  background_last_s_ = -1e300;
  background_ = cv::Mat();
}

// One frame every quarter of static_after_s, over forget_after_s at most: the board and its holder
// stay at one place for a hold, seldom half of that. The median is used once the frames span
// static_after_s (a board held still from the start is not yet background then).
void ImageBoardTracker::learnBackground(const cv::Mat& image, double stamp) {
  // Only a plain board is searched where the frame departs from the background.
  if (detector_.target().type != TargetType::kPlain) return;
  if (image.type() != CV_8UC3 || image.empty() || !std::isfinite(stamp) ||
      stamp - background_last_s_ < memory_.static_after_s / 4)
    return;
  background_last_s_ = stamp;
  const double scale =
      static_cast<double>(detector_.options().segmentation_width_px) / std::max(1, image.cols);
  cv::Mat small;
  cv::resize(image, small, cv::Size(), std::min(1.0, scale), std::min(1.0, scale), cv::INTER_AREA);
  if (image.size() != background_source_) {  // another camera or resolution: start over
    background_frames_.clear();
    background_stamps_.clear();
    background_source_ = image.size();
  }
  background_frames_.push_back(std::move(small));
  background_stamps_.push_back(stamp);
  while (!background_stamps_.empty() &&
         (stamp - background_stamps_.front() > memory_.forget_after_s ||
          background_frames_.size() > kMaxBackgroundFrames)) {
    background_frames_.pop_front();
    background_stamps_.pop_front();
  }
  const bool spans = stamp - background_stamps_.front() >= memory_.static_after_s;
  background_ = spans && background_frames_.size() >= kMinBackgroundFrames
                    ? image_detection::medianImage(background_frames_)
                    : cv::Mat();
}

int ImageBoardTracker::numStaticPlaces() const {
  const auto learnt = std::count_if(places_.begin(), places_.end(), [&](const Place& p) {
    return p.sightings.isStatic(memory_, frames_);
  });
  return static_cast<int>(learnt + static_cast<long>(known_.rectangles.size()));
}

int ImageBoardTracker::numStaticLines() const {
  const auto learnt = std::count_if(lines_.begin(), lines_.end(), [&](const LinePlace& l) {
    return l.sightings.isStatic(memory_, frames_);
  });
  return static_cast<int>(learnt + static_cast<long>(known_.lines_px.size()));
}

StaticScene ImageBoardTracker::staticScene() const {
  StaticScene out;
  for (const Place& p : places_)
    if (p.sightings.isStatic(memory_, frames_))
      out.rectangles.push_back(
          {p.corners_px, p.tolerance_px, p.sightings.last_s - p.sightings.first_s});
  for (const LinePlace& l : lines_)
    if (l.sightings.isStatic(memory_, frames_)) out.lines_px.push_back(l.ends_px);
  out.rectangles.insert(out.rectangles.end(), known_.rectangles.begin(), known_.rectangles.end());
  // A pre-pass saw the whole recording: its background is the better one.
  out.background = !known_.background.empty() ? known_.background : background_;
  out.lines_px.insert(out.lines_px.end(), known_.lines_px.begin(), known_.lines_px.end());
  return out;
}

int ImageBoardTracker::match(const std::array<Eigen::Vector2d, kNumEdges>& corners) const {
  int best = -1;
  double best_off = std::numeric_limits<double>::infinity();
  for (size_t k = 0; k < places_.size(); ++k) {
    const double off = image_detection::worstCornerOffset(corners, places_[k].corners_px);
    if (off <= places_[k].tolerance_px && off < best_off) {
      best_off = off;
      best = static_cast<int>(k);
    }
  }
  return best;
}

void ImageBoardTracker::remember(const ImageDetection& detection, double stamp) {
  const double tolerance =
      image_detection::sameLineTolerancePx(detector_.options(), detection.features.image_width);
  for (const auto& corners : detection.details.boards_px) {
    const int k = match(corners);
    if (k < 0)
      places_.push_back({corners, tolerance, PlaceSightings::start(stamp, frames_)});
    else
      places_[static_cast<size_t>(k)].sightings.see(stamp, frames_);  // once per frame
  }
}

void ImageBoardTracker::rememberLines(const std::vector<std::array<Eigen::Vector2d, 2>>& lines,
                                      double stamp, int image_width) {
  const double tolerance = image_detection::sameLineTolerancePx(detector_.options(), image_width);
  const size_t known = lines_.size();  // this frame's new lines do not match each other
  for (const auto& ends : lines) {
    bool seen = false;
    for (size_t k = 0; k < known; ++k)
      if (image_detection::sameLine(ends, lines_[k].ends_px, tolerance)) {
        lines_[k].sightings.see(stamp, frames_);
        seen = true;
      }
    if (!seen) lines_.push_back({ends, PlaceSightings::start(stamp, frames_)});
  }
}

void ImageBoardTracker::startFrame(double stamp) {
  if (stamp < last_stamp_) reset();  // a replay started over
  last_stamp_ = stamp;
  ++frames_;
}

void ImageBoardTracker::forget(double stamp) {
  const auto forgotten = [&](const auto& p) { return p.sightings.forgotten(memory_, stamp); };
  places_.erase(std::remove_if(places_.begin(), places_.end(), forgotten), places_.end());
  lines_.erase(std::remove_if(lines_.begin(), lines_.end(), forgotten), lines_.end());
}

void ImageBoardTracker::learnScene(const cv::Mat& image, const CameraModel& camera, double stamp,
                                   bool rectangles) {
  startFrame(stamp);
  bool lines_seen = false;
  if (rectangles) {
    const ImageDetection det = detector_.detect(image, camera);
    remember(det, stamp);
    // The line stage is skipped when a region gave a clean board: then it runs alone below.
    lines_seen = det.details.line_segments > 0;
    if (lines_seen) rememberLines(det.details.lines_px, stamp, image.cols);
  }
  if (!lines_seen)
    rememberLines(
        image_detection::sceneLines(image_detection::toGray(image), camera, detector_.options()),
        stamp, image.cols);
  forget(stamp);
  learnBackground(image, stamp);
}

ImageDetection ImageBoardTracker::detect(const cv::Mat& image, const CameraModel& camera,
                                         double stamp) {
  startFrame(stamp);
  const auto t0 = std::chrono::steady_clock::now();
  learnBackground(image, stamp);
  const StaticScene scene = staticScene();
  const auto t1 = std::chrono::steady_clock::now();
  ImageDetection det = detector_.detect(image, camera, scene);
  const auto t2 = std::chrono::steady_clock::now();
  remember(det, stamp);
  rememberLines(det.details.lines_px, stamp, image.cols);
  forget(stamp);
  memory_ms_ =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t2 + t1 - t0)
          .count();
  if (det.features.found) {
    const int k = match(det.features.corners_px);
    // This frame made the board's place static: look past it now rather than from the next one.
    if (k >= 0 && places_[static_cast<size_t>(k)].sightings.isStatic(memory_, frames_)) {
      det = detector_.detect(image, camera, staticScene());
      remember(det, stamp);
    }
  }
  return det;
}

}  // namespace board_calib
