// calibrate_bag, pair mode: the bags streamed through the offline pipeline, once for the first
// pass and again for the second chance (re-read, not kept: a recording may not fit in memory).
#pragma once

#include <board_calib/core/pipeline/pipeline.h>

#include <string>
#include <vector>

namespace board_calib {

struct PairBagArgs {
  std::vector<std::string> bags;
  std::string image_topic, info_topic, cloud_topic;
  bool quiet = false;
};

/// Offline pre-pass of the static scene (issue 14): the bags' images, one every
/// static_after_s / frames_per_static, through a ScenePrepass; sets options->image_known_scene.
/// Nothing for a pattern board, without image memory or with frames_per_static 0. Returns the
/// one-line failure reason, empty on success.
std::string learnImageScene(const PairBagArgs& args, const Target& target,
                            PipelineOptions* options);

/// Streams the bags through `pipeline` and prints its detection figures (unless quiet). Sets
/// the frames of the first image and cloud when still empty. Returns the one-line failure
/// reason, empty on success.
std::string readPairBags(const PairBagArgs& args, CalibrationPipeline* pipeline,
                         std::string* camera_frame, std::string* lidar_frame);

}  // namespace board_calib
