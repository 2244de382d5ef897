// Rig front end: raw images and clouds of every camera and LiDAR of a rig (offline), or their
// board features (live, from the detector nodelets), into captured board poses. The same
// detectors as the nodelets, and the same multi_sensor::RigSession as the calibrator's rig mode, so
// `calibrate_bag --config` and the live calibrator capture the same poses from the same frames;
// core/pipeline/rig_calibration.h then judges and writes the result.
#pragma once

#include <board_calib/core/image_detection/image_board_detector.h>
#include <board_calib/core/lidar_detection/lidar_board_detector.h>
#include <board_calib/core/pipeline/rig_report.h>
#include <board_calib/core/rig/rig_config.h>
#include <board_calib/core/rig/rig_session.h>

#include <map>
#include <memory>
#include <string>
#include <vector>

namespace board_calib {

enum class RigCapture {
  kStill,  ///< one pose per hold (the live rule, multi_sensor::RigSession)
  kAll,    ///< offline only: a pose of every stamp group (a hold of N frames gives N poses)
};
/// "still", "all".
const char* rigCaptureName(RigCapture capture);
Expected<RigCapture> parseRigCapture(const std::string& name);

struct RigPipelineOptions {
  ImageBoardDetectorOptions image;
  LidarBoardDetectorOptions lidar;
  multi_sensor::RigSessionOptions
      session;  ///< stamp_tolerance_s comes from the rig file (rigPipelineOptionsFor)
  RigCapture capture = RigCapture::kStill;
  /// Raw images kept per camera for the report's overlays (offline entry only), spread over the
  /// session: the first, the newest and the ones between with the widest gaps. 0: none.
  int overlay_frames = 4;
  int frame_history = 16;  ///< images with the board kept per camera at most while their moment
                           ///< is judged (still rule; bounded also by session.history_s)
  std::string validate() const;
};

/// Defaults with the rig file's stamp tolerance.
RigPipelineOptions rigPipelineOptionsFor(const RigConfig& rig);

/// What one sensor saw (for logs and the report).
struct RigSensorStats {
  std::string name;
  std::string frame_id;  ///< from the first frame (the name until then)
  int frames = 0, found = 0;
  std::map<std::string, int> failures;  ///< reason -> count
};

class RigPipeline {
 public:
  static Expected<RigPipeline> create(const RigConfig& rig, const Target& target,
                                      const RigPipelineOptions& options);
  RigPipeline(RigPipeline&&) noexcept;
  RigPipeline& operator=(RigPipeline&&) noexcept;
  ~RigPipeline();

  /// Offline: a raw image of the rig's camera `camera` (index among the cameras) with the
  /// intrinsics valid at its time; bad intrinsics are counted as a failure, not thrown.
  SessionEvent addImage(int camera, const cv::Mat& image, const CameraIntrinsics& intrinsics,
                        const std::string& frame_id, double stamp);
  /// Offline: a raw cloud of the rig's LiDAR `lidar` (index among the LiDARs).
  SessionEvent addCloud(int lidar, const LidarCloud& cloud);
  /// Live: board features of sensor `sensor` (MsgProblem order: cameras, then LiDARs).
  SessionEvent addCameraFeatures(int sensor, const CameraBoardFeatures& features);
  SessionEvent addLidarFeatures(int sensor, const LidarBoardFeatures& features);
  /// No more frames: judges the moments still waiting for their still window.
  SessionEvent finish();

  /// The problem to solve: the rig's sensors (frames as seen) and the captured poses.
  Expected<multi_sensor::MsgProblem> problem() const;
  const multi_sensor::RigSession& session() const;
  multi_sensor::RigSession& session();
  const std::vector<RigSensorStats>& stats() const;  ///< MsgProblem order
  /// Per camera, the raw images kept for the overlays (overlay_frames; still rule: images of
  /// captured poses with a LiDAR; all rule: images with the board). Empty for the live entry.
  std::vector<RigCameraFrames> overlayFrames() const;
  const RigConfig& rig() const;
  const Target& target() const;

 private:
  RigPipeline() = default;
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace board_calib
