// The dynamic_reconfigure defaults of the nodelets must equal the core defaults: the
// core defaults are the measured ones (docs/BENCHMARKS.md), and a stale .cfg default silently
// makes the live nodelets worse than calibrate_bag.
#include "calibrator_options.h"
#include "cloud_detector_options.h"
#include "image_detector_options.h"

#include <gtest/gtest.h>

namespace board_calib {
namespace {

TEST(ConfigDefaults, CloudBoardDetectorCfgMatchesTheCore) {
  const LidarBoardDetectorOptions mapped =
      optionsFromConfig(CloudBoardDetectorConfig::__getDefault__());
  const LidarBoardDetectorOptions core;
#define BOARD_CALIB_EXPECT_SAME(cfg, member) \
  EXPECT_EQ(mapped.member, core.member) << "cfg/CloudBoardDetector.cfg default of '" #cfg "'";
  BOARD_CALIB_CLOUD_DETECTOR_FIELDS(BOARD_CALIB_EXPECT_SAME)
#undef BOARD_CALIB_EXPECT_SAME
}

TEST(ConfigDefaults, ImageBoardDetectorCfgMatchesTheCore) {
  const ImageBoardDetectorOptions mapped =
      optionsFromConfig(ImageBoardDetectorConfig::__getDefault__());
  const ImageBoardDetectorOptions core;
#define BOARD_CALIB_EXPECT_SAME(cfg, member) \
  EXPECT_EQ(mapped.member, core.member) << "cfg/ImageBoardDetector.cfg default of '" #cfg "'";
  BOARD_CALIB_IMAGE_DETECTOR_FIELDS(BOARD_CALIB_EXPECT_SAME)
#undef BOARD_CALIB_EXPECT_SAME
}

TEST(ConfigDefaults, CalibratorCfgMatchesTheSessions) {
  const CalibratorConfig defaults = CalibratorConfig::__getDefault__();
  const SessionOptions pair = sessionOptionsFromConfig(defaults);
  const SessionOptions pair_core;
#define BOARD_CALIB_EXPECT_SAME(cfg, member) \
  EXPECT_EQ(pair.member, pair_core.member) << "cfg/Calibrator.cfg default of '" #cfg "'";
  BOARD_CALIB_SESSION_FIELDS(BOARD_CALIB_EXPECT_SAME)
#undef BOARD_CALIB_EXPECT_SAME
  const multi_sensor::RigSessionOptions rig = rigSessionOptionsFromConfig(defaults);
  const multi_sensor::RigSessionOptions rig_core;
#define BOARD_CALIB_EXPECT_SAME(cfg, member) \
  EXPECT_EQ(rig.member, rig_core.member) << "cfg/Calibrator.cfg default of '" #cfg "' (rig mode)";
  BOARD_CALIB_RIG_SESSION_FIELDS(BOARD_CALIB_EXPECT_SAME)
#undef BOARD_CALIB_EXPECT_SAME
}

}  // namespace
}  // namespace board_calib
