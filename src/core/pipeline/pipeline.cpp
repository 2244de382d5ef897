#include <board_calib/core/pipeline/pipeline.h>

#include <chrono>
#include <deque>
#include <optional>

namespace board_calib {
namespace {

constexpr double kFrameMarginS = 0.5;  // s, raw frames kept beyond the still window

double elapsedMs(std::chrono::steady_clock::time_point since) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - since)
      .count();
}

}  // namespace

std::string PipelineOptions::validate() const {
  if (auto why = lidar.validate(); !why.empty()) return "lidar detector: " + why;
  if (auto why = lidar_memory.validate(); !why.empty()) return "lidar session memory: " + why;
  if (auto why = image.validate(); !why.empty()) return "image detector: " + why;
  if (auto why = image_memory.validate(); !why.empty()) return "image session memory: " + why;
  if (auto why = image_prepass.validate(); !why.empty()) return "scene pre-pass: " + why;
  if (auto why = session.validate(); !why.empty()) return "session: " + why;
  if (frame_history < 1) return "frame_history must be >= 1";
  if (auto why = second_chance.validate(); !why.empty()) return "second chance: " + why;
  return {};
}

struct CalibrationPipeline::Impl {
  Impl(const Target& t, const PipelineOptions& o, ImageBoardDetector d,
       std::optional<ImageBoardTracker> image_memory)
      : target(t),
        options(o),
        image_detector(std::move(d)),
        image_tracker(std::move(image_memory)),
        session(t, o.session) {
    if (o.lidar_memory.enabled) tracker.emplace(t, o.lidar, o.lidar_memory);
  }

  Target target;
  PipelineOptions options;
  ImageBoardDetector image_detector;  // alone, and near a projected board (second chance)
  std::optional<ImageBoardTracker> image_tracker;  // session memory of the static scene (issue 14)
  std::optional<LidarBoardTracker> tracker;        // session memory of board-like places (issue 14)
  PairSession session;
  std::optional<CameraIntrinsics> intrinsics;
  std::optional<CameraModel> camera;
  PipelineStats stats;
  std::deque<std::pair<double, cv::Mat>> recent_images;
  std::deque<std::pair<double, LidarCloud>> recent_clouds;
  std::map<int, cv::Mat> view_images;
  std::map<int, LidarCloud> view_clouds;
  BoardSightings sightings;

  // Second chance for an image the whole-image search missed; true when the board was found.
  bool retryImage(const cv::Mat& image, ImageDetection* det) {
    if (!options.prior) return false;
    SecondChanceStats& sc = stats.second_chance;
    ++sc.images_tried;
    std::string why;
    const auto expected = expectedImageBoard(*options.prior, det->features.stamp,
                                             secondChanceWindowS(options.session), *camera,
                                             options.second_chance, &why);
    ImageDetection near;
    if (expected) {
      near = image_detector.detectNear(image, *camera, *expected);
      if (!near.features.found) why = "near the projected LiDAR board: " + near.features.reason;
    }
    if (!expected || !near.features.found) {
      sc.images_not_recovered[why]++;
      return false;
    }
    near.features.frame_id = det->features.frame_id;
    near.features.stamp = det->features.stamp;
    *det = std::move(near);
    ++sc.images_recovered;
    return true;
  }

  // Second chance for a cloud whose board was not found alone; true when it was found.
  bool retryCloud(const LidarCloud& cloud, LidarBoardDetection* det) {
    if (!options.prior) return false;
    SecondChanceStats& sc = stats.second_chance;
    ++sc.clouds_tried;
    std::string why;
    const auto expected =
        expectedLidarBoard(*options.prior, cloud.stamp, secondChanceWindowS(options.session),
                           target, options.second_chance, &why);
    LidarBoardDetection near;
    if (expected) {
      near = detectLidarBoardNear(cloud, target, options.lidar, *expected);
      if (!near.features.found)
        why = std::string("near the back-projected image board: ") +
              lidarDetectionCodeName(near.code);
    }
    if (!expected || !near.features.found) {
      sc.clouds_not_recovered[why]++;
      return false;
    }
    *det = std::move(near);
    ++sc.clouds_recovered;
    return true;
  }

  // Raw frames wait until the session has judged them: the still window plus the sync tolerance.
  // Images still waiting for their judgement keep their frames (a snapshot recording judges its
  // first images only once later frames show the rates).
  template <typename Frames>
  void trimFrames(Frames& frames) {
    const double keep_s =
        options.session.still_window_s + options.session.sync_tolerance_s + kFrameMarginS;
    double cutoff = frames.back().first - keep_s;
    if (const auto pending = session.oldestPendingStamp())
      cutoff = std::min(cutoff, *pending - keep_s);
    while (frames.size() > 1 && (static_cast<int>(frames.size()) > options.frame_history ||
                                 frames.front().first < cutoff))
      frames.pop_front();
  }

  std::map<int, std::pair<double, double>>
      view_frame_stamps;  // view id -> (image, cloud) stamps kept

  // Every view whose frames are not kept yet (or were replaced by a better frame of its hold).
  void keepAccepted(const SessionEvent& event) {
    if (event.kind != SessionEvent::Kind::kAccepted || !options.keep_view_frames) return;
    for (const auto& sv : session.views()) {
      const auto stamps = std::make_pair(sv.view.camera.stamp, sv.view.lidar.stamp);
      auto known = view_frame_stamps.find(sv.view.id);
      if (known != view_frame_stamps.end() && known->second == stamps) continue;
      for (const auto& [stamp, image] : recent_images)
        if (stamp == stamps.first) view_images[sv.view.id] = image;
      for (const auto& [stamp, cloud] : recent_clouds)
        if (stamp == stamps.second) view_clouds[sv.view.id] = cloud;
      view_frame_stamps[sv.view.id] = stamps;
    }
  }
};

Expected<CalibrationPipeline> CalibrationPipeline::create(const Target& target,
                                                          const PipelineOptions& options) {
  if (auto why = options.validate(); !why.empty())
    return Expected<CalibrationPipeline>::failure(why);
  if (auto why = target.validate(); !why.empty())
    return Expected<CalibrationPipeline>::failure("target: " + why);
  auto detector = ImageBoardDetector::create(target, options.image);
  if (!detector)
    return Expected<CalibrationPipeline>::failure("image detector: " + detector.error());
  std::optional<ImageBoardTracker> image_tracker;
  if (options.image_memory.enabled) {
    auto t = ImageBoardTracker::create(target, options.image, options.image_memory);
    if (!t) return Expected<CalibrationPipeline>::failure("image session memory: " + t.error());
    image_tracker.emplace(std::move(*t));
    image_tracker->setKnownScene(options.image_known_scene);
  }
  CalibrationPipeline p;
  p.impl_ = std::make_unique<Impl>(target, options, std::move(*detector), std::move(image_tracker));
  return p;
}

CalibrationPipeline::CalibrationPipeline(CalibrationPipeline&&) noexcept = default;
CalibrationPipeline& CalibrationPipeline::operator=(CalibrationPipeline&&) noexcept = default;
CalibrationPipeline::~CalibrationPipeline() = default;

FrameOutcome CalibrationPipeline::addImage(const cv::Mat& image, const CameraIntrinsics& intrinsics,
                                           const std::string& frame_id, double stamp) {
  Impl& d = *impl_;
  FrameOutcome out;
  ++d.stats.images;
  if (!d.intrinsics || *d.intrinsics != intrinsics) {
    auto model = CameraModel::create(intrinsics);
    if (!model) {
      ++d.stats.bad_camera_info;
      out.detection = "bad camera_info: " + model.error();
      d.stats.image_failures[out.detection]++;
      return out;
    }
    d.intrinsics = intrinsics;
    d.camera = *model;
  }
  const auto start = std::chrono::steady_clock::now();
  ImageDetection det = d.image_tracker ? d.image_tracker->detect(image, *d.camera, stamp)
                                       : d.image_detector.detect(image, *d.camera);
  det.features.frame_id = frame_id;
  det.features.stamp = stamp;
  if (!det.features.found) d.retryImage(image, &det);
  out.detect_ms = elapsedMs(start);
  d.stats.image_ms += out.detect_ms;
  out.board_found = det.features.found;
  out.detection = det.features.reason;
  if (det.features.found) {
    ++d.stats.images_with_board;
    d.sightings.images[stamp] =
        imageSighting(det.features, *d.camera, d.target, d.options.second_chance);
  } else {
    d.stats.image_failures[det.features.reason]++;
    d.sightings.images_missed.push_back(stamp);
  }
  // A first pass keeps every board-shaped quadrilateral for a consensus without a calibration.
  if (!d.options.prior && d.target.type == TargetType::kPlain) {
    auto candidates =
        boardCandidates(det, *d.camera, d.target, d.options.second_chance.corner_sigma_px);
    if (!candidates.empty()) d.sightings.image_candidates[stamp] = std::move(candidates);
  }
  if (d.options.keep_view_frames) {
    d.recent_images.emplace_back(stamp, image);
    d.trimFrames(d.recent_images);
  }
  out.event = d.session.addCamera(det.features);
  d.keepAccepted(out.event);
  return out;
}

FrameOutcome CalibrationPipeline::addCloud(const LidarCloud& cloud) {
  Impl& d = *impl_;
  FrameOutcome out;
  ++d.stats.clouds;
  const auto start = std::chrono::steady_clock::now();
  LidarBoardDetection det =
      d.tracker ? d.tracker->detect(cloud) : detectLidarBoard(cloud, d.target, d.options.lidar);
  if (!det.features.found) d.retryCloud(cloud, &det);
  out.detect_ms = elapsedMs(start);
  d.stats.cloud_ms += out.detect_ms;
  det.features.frame_id = cloud.frame_id;
  det.features.stamp = cloud.stamp;
  out.board_found = det.features.found;
  out.detection = det.features.reason;
  if (det.features.found) {
    ++d.stats.clouds_with_board;
    d.sightings.clouds[cloud.stamp] = lidarSighting(det.features);
  } else {
    d.stats.cloud_failures[std::string(lidarDetectionCodeName(det.code))]++;
    d.sightings.clouds_missed.push_back(cloud.stamp);
  }
  if (d.options.keep_view_frames) {
    d.recent_clouds.emplace_back(cloud.stamp, cloud);
    d.trimFrames(d.recent_clouds);
  }
  out.event = d.session.addLidar(det.features);
  d.keepAccepted(out.event);
  return out;
}

SessionEvent CalibrationPipeline::finish() {
  const SessionEvent event = impl_->session.finish();
  impl_->keepAccepted(event);
  return event;
}

PairSession& CalibrationPipeline::session() { return impl_->session; }
const PairSession& CalibrationPipeline::session() const { return impl_->session; }
const PipelineStats& CalibrationPipeline::stats() const { return impl_->stats; }
const Target& CalibrationPipeline::target() const { return impl_->target; }
const PipelineOptions& CalibrationPipeline::options() const { return impl_->options; }
const std::map<int, cv::Mat>& CalibrationPipeline::viewImages() const { return impl_->view_images; }
const std::map<int, LidarCloud>& CalibrationPipeline::viewClouds() const {
  return impl_->view_clouds;
}
const BoardSightings& CalibrationPipeline::sightings() const { return impl_->sightings; }
const CameraModel* CalibrationPipeline::cameraModel() const {
  return impl_->camera ? &*impl_->camera : nullptr;
}

}  // namespace board_calib
