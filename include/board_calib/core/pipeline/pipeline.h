// Offline calibration pipeline: raw images and clouds in, board features out, paired into a
// PairSession. The same detectors and session the nodelets use, without ROS, so the
// offline tool and the tests exercise exactly the live code path.
#pragma once

#include <board_calib/core/image_detection/image_board_detector.h>
#include <board_calib/core/image_detection/image_board_tracker.h>
#include <board_calib/core/lidar_detection/lidar_board_detector.h>
#include <board_calib/core/pipeline/scene_prepass.h>
#include <board_calib/core/pipeline/second_chance.h>
#include <board_calib/core/session/session.h>

#include <map>
#include <memory>
#include <optional>

namespace board_calib {

struct PipelineOptions {
  LidarBoardDetectorOptions lidar;
  StaticMemoryOptions lidar_memory;  ///< enabled: clouds go through a LidarBoardTracker (static
                                     ///< planes are background)
  ImageBoardDetectorOptions image;
  StaticMemoryOptions image_memory;  ///< enabled: images go through an ImageBoardTracker (static
                                     ///< scene rectangles and lines are not the board)
  /// Offline only: the images' static scene learnt before the first frame by a ScenePrepass over
  /// the whole recording (scene_prepass.h), excluded from the first frame on. Empty: live.
  StaticScene image_known_scene;
  ScenePrepassOptions image_prepass;  ///< how the offline callers run that pre-pass
  SessionOptions session;
  bool keep_view_frames = true;  ///< keep the raw image and cloud of every accepted view (reports)
  int frame_history = 64;        ///< raw frames kept per stream at most until their view is decided
  /// Second pass (issue 14, 3b): a frame whose board is not found alone is searched again where
  /// this prior (a first calibration and the first pass's boards) puts it. Unset: first pass.
  std::optional<SecondChancePrior> prior;
  SecondChanceOptions second_chance;
  std::string validate() const;
};

/// What happened to one input frame.
struct FrameOutcome {
  bool board_found = false;
  std::string detection;  ///< detector reason when not found, or doubts
  SessionEvent event;     ///< what the session did with the resulting pair
  double detect_ms = 0.0;
};

struct PipelineStats {
  int images = 0, clouds = 0;
  int images_with_board = 0, clouds_with_board = 0;
  int bad_camera_info = 0;
  std::map<std::string, int> image_failures;  ///< reason -> count
  std::map<std::string, int> cloud_failures;  ///< reason -> count
  double image_ms = 0.0, cloud_ms = 0.0;      ///< total detection time
  SecondChanceStats second_chance;            ///< second pass only
};

class CalibrationPipeline {
 public:
  static Expected<CalibrationPipeline> create(const Target& target, const PipelineOptions& options);
  CalibrationPipeline(CalibrationPipeline&&) noexcept;
  CalibrationPipeline& operator=(CalibrationPipeline&&) noexcept;
  ~CalibrationPipeline();

  /// A raw image with the intrinsics valid at its time. Bad intrinsics are reported, not thrown.
  FrameOutcome addImage(const cv::Mat& image, const CameraIntrinsics& intrinsics,
                        const std::string& frame_id, double stamp);
  FrameOutcome addCloud(const LidarCloud& cloud);
  /// No more frames: judges the images still waiting for their still window.
  SessionEvent finish();

  PairSession& session();
  const PairSession& session() const;
  const PipelineStats& stats() const;
  const Target& target() const;
  const PipelineOptions& options() const;
  /// Frames of accepted views (when keep_view_frames): view id -> raw image / cloud.
  const std::map<int, cv::Mat>& viewImages() const;
  const std::map<int, LidarCloud>& viewClouds() const;
  /// Camera model of the last image (for reports); nullptr before the first valid image.
  const CameraModel* cameraModel() const;
  /// Every board found so far (alone or by the second chance): a second pass's prior.
  const BoardSightings& sightings() const;

 private:
  CalibrationPipeline() = default;
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace board_calib
