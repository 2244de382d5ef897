// Rig front end (see rig_pipeline.h).
#include <board_calib/core/msg_graph/pose_grouping.h>
#include <board_calib/core/pipeline/rig_pipeline.h>

#include <deque>
#include <iterator>
#include <limits>
#include <optional>
#include <set>

namespace board_calib {
namespace {

SessionEvent rejected(const std::string& why) { return {SessionEvent::Kind::kRejected, why, -1}; }

// Adds a frame and, above `cap`, drops the inner frame whose neighbours are closest in time, so
// the kept ones stay spread over the session (the first and the newest always stay).
void keepSpread(std::map<double, RigFrame>* kept, double stamp, RigFrame frame, int cap) {
  (*kept)[stamp] = std::move(frame);
  while (static_cast<int>(kept->size()) > cap) {
    if (cap < 2) {
      kept->erase(std::prev(kept->end()));
      continue;
    }
    auto drop = kept->end();
    double smallest_gap = std::numeric_limits<double>::infinity();
    for (auto it = std::next(kept->begin()); std::next(it) != kept->end(); ++it) {
      const double gap = std::next(it)->first - std::prev(it)->first;
      if (gap < smallest_gap) smallest_gap = gap, drop = it;
    }
    kept->erase(drop);
  }
}

}  // namespace

const char* rigCaptureName(RigCapture capture) {
  return capture == RigCapture::kAll ? "all" : "still";
}

Expected<RigCapture> parseRigCapture(const std::string& name) {
  if (name == "still") return RigCapture::kStill;
  if (name == "all") return RigCapture::kAll;
  return Expected<RigCapture>::failure("capture must be 'still' or 'all', not '" + name + "'");
}

std::string RigPipelineOptions::validate() const {
  if (auto why = image.validate(); !why.empty()) return "image detector: " + why;
  if (auto why = lidar.validate(); !why.empty()) return "lidar detector: " + why;
  if (auto why = session.validate(); !why.empty()) return "rig session: " + why;
  if (overlay_frames < 0) return "overlay_frames must be >= 0";
  if (frame_history < 1) return "frame_history must be >= 1";
  return {};
}

RigPipelineOptions rigPipelineOptionsFor(const RigConfig& rig) {
  RigPipelineOptions o;
  o.session = multi_sensor::rigSessionOptionsFor(rig);
  return o;
}

struct RigPipeline::Impl {
  struct Camera {
    ImageBoardDetector detector;
    std::optional<CameraIntrinsics> intrinsics;
    std::optional<CameraModel> model;
    std::deque<std::pair<double, RigFrame>> recent;  // images with the board, awaiting judgement
    std::map<double, RigFrame> kept;                 // for the overlays
  };
  Impl(const RigConfig& r, const Target& t, const RigPipelineOptions& o)
      : rig(r), target(t), options(o), session(r.sensorNames(), r.sensorSpecs(), o.session, t) {}

  RigConfig rig;
  Target target;
  RigPipelineOptions options;
  multi_sensor::RigSession session;
  std::vector<Camera> cameras;
  std::vector<RigSensorStats> stats;
  // Every found feature, for the offline "all" capture.
  std::map<int, std::vector<CameraBoardFeatures>> camera_features;
  std::map<int, std::vector<LidarBoardFeatures>> lidar_features;

  void count(int sensor, const std::string& frame_id, bool found, const std::string& reason) {
    RigSensorStats& s = stats[static_cast<size_t>(sensor)];
    if (s.frame_id == s.name && !frame_id.empty()) s.frame_id = frame_id;
    ++s.frames;
    if (found)
      ++s.found;
    else
      s.failures[reason.empty() ? "board not found" : reason]++;
  }

  // An image with the board: kept at once under the all rule, else until its moment is judged.
  void rememberImage(int camera, double stamp, const cv::Mat& image) {
    if (options.overlay_frames == 0) return;
    Camera& c = cameras[static_cast<size_t>(camera)];
    RigFrame frame{image, *c.intrinsics};
    if (options.capture == RigCapture::kAll) {
      keepSpread(&c.kept, stamp, std::move(frame), options.overlay_frames);
      return;
    }
    c.recent.emplace_back(stamp, std::move(frame));
    while (c.recent.size() > 1 && (static_cast<int>(c.recent.size()) > options.frame_history ||
                                   c.recent.front().first < stamp - options.session.history_s))
      c.recent.pop_front();
  }

  // Still rule: the kept images follow the captured poses that have a LiDAR (a replaced pose
  // gives up its image for the better moment's).
  void keepPoseFrames() {
    if (options.capture != RigCapture::kStill || options.overlay_frames == 0) return;
    const int first_lidar = static_cast<int>(cameras.size());
    for (int k = 0; k < first_lidar; ++k) {
      Camera& c = cameras[static_cast<size_t>(k)];
      std::set<double> stamps;
      for (const auto& pose : session.poses()) {
        const auto& o = pose.observation;
        const auto cam = o.cameras.find(k);
        if (cam != o.cameras.end() && !o.lidars.empty()) stamps.insert(cam->second.stamp);
      }
      for (auto it = c.kept.begin(); it != c.kept.end();)
        it = stamps.count(it->first) ? std::next(it) : c.kept.erase(it);
      for (const auto& [stamp, frame] : c.recent)
        if (stamps.count(stamp) && !c.kept.count(stamp))
          keepSpread(&c.kept, stamp, frame, options.overlay_frames);
    }
  }

  SessionEvent afterImageOrCloud(const SessionEvent& event) {
    if (event.kind == SessionEvent::Kind::kAccepted) keepPoseFrames();
    return event;
  }
};

Expected<RigPipeline> RigPipeline::create(const RigConfig& rig, const Target& target,
                                          const RigPipelineOptions& options) {
  if (auto why = rig.validate(); !why.empty()) return Expected<RigPipeline>::failure("rig: " + why);
  if (auto why = target.validate(); !why.empty())
    return Expected<RigPipeline>::failure("target: " + why);
  if (auto why = options.validate(); !why.empty()) return Expected<RigPipeline>::failure(why);
  RigPipeline p;
  p.impl_ = std::make_unique<Impl>(rig, target, options);
  for (size_t i = 0; i < rig.cameras.size(); ++i) {
    auto detector = ImageBoardDetector::create(target, options.image);
    if (!detector) return Expected<RigPipeline>::failure("image detector: " + detector.error());
    p.impl_->cameras.push_back({std::move(*detector), std::nullopt, std::nullopt, {}, {}});
  }
  for (const auto& name : rig.sensorNames()) p.impl_->stats.push_back({name, name, 0, 0, {}});
  return p;
}

RigPipeline::RigPipeline(RigPipeline&&) noexcept = default;
RigPipeline& RigPipeline::operator=(RigPipeline&&) noexcept = default;
RigPipeline::~RigPipeline() = default;

SessionEvent RigPipeline::addImage(int camera, const cv::Mat& image,
                                   const CameraIntrinsics& intrinsics, const std::string& frame_id,
                                   double stamp) {
  Impl& d = *impl_;
  if (camera < 0 || camera >= static_cast<int>(d.cameras.size()))
    return rejected("image for camera " + std::to_string(camera) + ", which the rig does not have");
  Impl::Camera& c = d.cameras[static_cast<size_t>(camera)];
  if (!c.intrinsics || *c.intrinsics != intrinsics) {
    auto model = CameraModel::create(intrinsics);
    if (!model) {
      d.count(camera, frame_id, false, "bad camera_info: " + model.error());
      return rejected("bad camera_info: " + model.error());
    }
    c.intrinsics = intrinsics;
    c.model.emplace(std::move(*model));
  }
  ImageDetection det = c.detector.detect(image, *c.model);
  det.features.stamp = stamp;
  if (det.features.frame_id.empty()) det.features.frame_id = frame_id;
  if (det.features.found) d.rememberImage(camera, stamp, image);
  return d.afterImageOrCloud(addCameraFeatures(camera, det.features));
}

SessionEvent RigPipeline::addCloud(int lidar, const LidarCloud& cloud) {
  Impl& d = *impl_;
  if (lidar < 0 || lidar >= static_cast<int>(d.rig.lidars.size()))
    return rejected("cloud for LiDAR " + std::to_string(lidar) + ", which the rig does not have");
  LidarBoardDetection det = detectLidarBoard(cloud, d.target, d.options.lidar);
  det.features.stamp = cloud.stamp;
  if (det.features.frame_id.empty()) det.features.frame_id = cloud.frame_id;
  if (!det.features.found && det.features.reason.empty())
    det.features.reason = lidarDetectionCodeName(det.code);
  return d.afterImageOrCloud(
      addLidarFeatures(static_cast<int>(d.rig.cameras.size()) + lidar, det.features));
}

SessionEvent RigPipeline::addCameraFeatures(int sensor, const CameraBoardFeatures& f) {
  Impl& d = *impl_;
  if (sensor < 0 || sensor >= static_cast<int>(d.stats.size()))
    return d.session.addCamera(sensor, f);
  d.count(sensor, f.frame_id, f.found, f.reason);
  if (d.options.capture == RigCapture::kAll) {
    if (f.found) d.camera_features[sensor].push_back(f);
    return {SessionEvent::Kind::kWaiting, "capture all: grouped by stamp at the end", -1};
  }
  return d.session.addCamera(sensor, f);
}

SessionEvent RigPipeline::addLidarFeatures(int sensor, const LidarBoardFeatures& f) {
  Impl& d = *impl_;
  if (sensor < 0 || sensor >= static_cast<int>(d.stats.size()))
    return d.session.addLidar(sensor, f);
  d.count(sensor, f.frame_id, f.found, f.reason);
  if (d.options.capture == RigCapture::kAll) {
    if (f.found) d.lidar_features[sensor].push_back(f);
    return {SessionEvent::Kind::kWaiting, "capture all: grouped by stamp at the end", -1};
  }
  return d.session.addLidar(sensor, f);
}

SessionEvent RigPipeline::finish() {
  const SessionEvent event = impl_->session.flush();
  impl_->keepPoseFrames();  // the flush may capture several poses and name one
  return event;
}

Expected<multi_sensor::MsgProblem> RigPipeline::problem() const {
  const Impl& d = *impl_;
  const int reference = d.rig.sensorIndex(d.rig.reference);
  if (d.options.capture == RigCapture::kStill) return d.session.problem(reference);
  multi_sensor::MsgProblem p;
  p.sensors = d.session.sensors();
  for (size_t k = 0; k < p.sensors.size(); ++k) p.sensors[k].frame = d.stats[k].frame_id;
  p.reference_sensor = reference;
  multi_sensor::GroupingOptions grouping;
  grouping.stamp_tolerance_s = d.options.session.stamp_tolerance_s;
  auto grouped =
      multi_sensor::groupByStamp(p.sensors, d.camera_features, d.lidar_features, grouping);
  if (!grouped) return Expected<multi_sensor::MsgProblem>::failure("grouping: " + grouped.error());
  p.poses = grouped->poses;
  return p;
}

const multi_sensor::RigSession& RigPipeline::session() const { return impl_->session; }
multi_sensor::RigSession& RigPipeline::session() { return impl_->session; }
const std::vector<RigSensorStats>& RigPipeline::stats() const { return impl_->stats; }
const RigConfig& RigPipeline::rig() const { return impl_->rig; }
std::vector<RigCameraFrames> RigPipeline::overlayFrames() const {
  std::vector<RigCameraFrames> out;
  for (size_t k = 0; k < impl_->cameras.size(); ++k)
    out.push_back({static_cast<int>(k), impl_->cameras[k].kept});
  return out;
}
const Target& RigPipeline::target() const { return impl_->target; }

}  // namespace board_calib
