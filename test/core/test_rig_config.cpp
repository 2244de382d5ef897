// Rig YAML loader: the shipped rig file, and specific reasons naming the key for bad input.
#include <board_calib/core/rig/rig_config.h>
#include <board_calib/core/transform.h>

#include <gtest/gtest.h>

#include <fstream>

using namespace board_calib;

namespace {

const char* kRig = R"(
target: targets/board.yaml
reference: vlp
stamp_tolerance_s: 0.02
cameras:
  - {name: left, image_topic: /l/img, camera_info_topic: /l/info, noise: {pixel_sigma_px: 0.3}}
  - {name: right, image_topic: /r/img, camera_info_topic: /r/info, features_topic: /r/board}
lidars:
  - {name: vlp, cloud_topic: /vlp/points, noise: {normal_sigma_deg: 0.4, offset_sigma_m: 0.01, edge_sigma_m: 0.03}}
known_extrinsics:
  - {a: left, b: right, a_T_b: {translation: [0.12, 0, 0], rotation_xyzw: [0, 0, 0.0087265, 0.9999619]}}
)";

// Replaces the first occurrence of `from` in the valid rig.
std::string variant(const std::string& from, const std::string& to) {
  std::string s = kRig;
  const size_t at = s.find(from);
  EXPECT_NE(at, std::string::npos) << from;
  return s.replace(at, from.size(), to);
}

std::string errorOf(const std::string& yaml) {
  auto r = parseRigConfig(yaml);
  EXPECT_FALSE(r.ok());
  return r ? std::string() : r.error();
}

}  // namespace

TEST(RigConfig, ParsesEveryField) {
  auto rig = parseRigConfig(kRig, "/rigs");
  ASSERT_TRUE(rig) << rig.error();
  EXPECT_EQ(rig->target_path, "/rigs/targets/board.yaml");
  EXPECT_EQ(rig->reference, "vlp");
  EXPECT_DOUBLE_EQ(rig->stamp_tolerance_s, 0.02);
  ASSERT_EQ(rig->cameras.size(), 2u);
  ASSERT_EQ(rig->lidars.size(), 1u);
  EXPECT_EQ(rig->cameras[1].camera_info_topic, "/r/info");
  EXPECT_DOUBLE_EQ(rig->cameras[0].pixel_sigma_px, 0.3);
  EXPECT_DOUBLE_EQ(rig->cameras[1].pixel_sigma_px, 0.0);  // graph default
  EXPECT_DOUBLE_EQ(rig->lidars[0].edge_sigma_m, 0.03);
  // Feature topics for the calibrator nodelet: NAME/<kind>_board unless given.
  EXPECT_EQ(rig->cameras[0].features_topic, "left/camera_board");
  EXPECT_EQ(rig->cameras[1].features_topic, "/r/board");
  EXPECT_EQ(rig->lidars[0].features_topic, "vlp/lidar_board");
  // MsgProblem order: cameras, then LiDARs.
  EXPECT_EQ(rig->sensorIndex("left"), 0);
  EXPECT_EQ(rig->sensorIndex("vlp"), 2);
  EXPECT_EQ(rig->sensorIndex("nope"), -1);
  EXPECT_EQ(rig->sensorNames(), (std::vector<std::string>{"left", "right", "vlp"}));
  const auto specs = rig->sensorSpecs();
  ASSERT_EQ(specs.size(), 3u);
  EXPECT_EQ(specs[2].kind, multi_sensor::SensorKind::kLidar);
  EXPECT_DOUBLE_EQ(specs[2].normal_sigma_deg, 0.4);
  ASSERT_EQ(rig->known_extrinsics.size(), 1u);
  // 1 deg about z, 12 cm along x (the quaternion above).
  const auto& k = rig->known_extrinsics[0];
  EXPECT_NEAR(rotationErrorDeg(k.a_T_b, Eigen::Isometry3d::Identity()), 1.0, 1e-3);
  EXPECT_NEAR(k.a_T_b.translation().x(), 0.12, 1e-12);
}

TEST(RigConfig, AbsoluteTargetIsKept) {
  auto rig =
      parseRigConfig(variant("target: targets/board.yaml", "target: /abs/board.yaml"), "/rigs");
  ASSERT_TRUE(rig) << rig.error();
  EXPECT_EQ(rig->target_path, "/abs/board.yaml");
}

TEST(RigConfig, ErrorsNameTheKey) {
  EXPECT_NE(errorOf(variant("target: targets/board.yaml\n", "")).find("'target'"),
            std::string::npos);
  EXPECT_NE(errorOf(variant("reference: vlp", "reference: os1")).find("rig.reference"),
            std::string::npos);
  EXPECT_NE(
      errorOf(variant("image_topic: /l/img, ", "")).find("cameras[0]: missing key 'image_topic'"),
      std::string::npos);
  EXPECT_NE(errorOf(variant("cloud_topic: /vlp/points", "cloud_topic: [1, 2]"))
                .find("lidars[0].cloud_topic"),
            std::string::npos);
  EXPECT_NE(errorOf(variant("pixel_sigma_px: 0.3", "pixel_sigma_px: -1"))
                .find("cameras[0].noise.pixel_sigma_px"),
            std::string::npos);
  EXPECT_NE(
      errorOf(variant("pixel_sigma_px: 0.3", "pixel_sigma: 0.3")).find("unknown key 'pixel_sigma'"),
      std::string::npos);
  // Unknown keys at every level name the key and where it is (a typo never falls back silently).
  EXPECT_NE(errorOf(variant("image_topic: /l/img", "imagetopic: /l/img"))
                .find("cameras[0]: unknown key 'imagetopic'"),
            std::string::npos);
  EXPECT_NE(errorOf(variant("cloud_topic: /vlp/points", "cloud_topic: /vlp/points, topic: /x"))
                .find("lidars[0]: unknown key 'topic'"),
            std::string::npos);
  EXPECT_NE(errorOf(variant("reference: vlp", "reference: vlp\nlidar: []"))
                .find("rig: unknown key 'lidar'"),
            std::string::npos);
  EXPECT_NE(
      errorOf(variant("stamp_tolerance_s: 0.02", "stamp_tolerance_s: 0")).find("stamp_tolerance_s"),
      std::string::npos);
  // Absurd values (trust sweep 7: a tolerance of 1e9 s, a pixel sigma of 1e9, a stereo pair
  // 1000 km apart were accepted).
  EXPECT_NE(errorOf(variant("stamp_tolerance_s: 0.02", "stamp_tolerance_s: 1e9"))
                .find("rig.stamp_tolerance_s: must be in (0, 1] s"),
            std::string::npos);
  EXPECT_NE(errorOf(variant("pixel_sigma_px: 0.3", "pixel_sigma_px: 1e9"))
                .find("cameras[0].noise.pixel_sigma_px: must be <= 100 px"),
            std::string::npos);
  EXPECT_NE(errorOf(variant("translation: [0.12, 0, 0]", "translation: [1e6, 0, 0]"))
                .find("known_extrinsics[0].a_T_b.translation: 1000000.0 m"),
            std::string::npos);
  EXPECT_NE(errorOf(variant("stamp_tolerance_s: 0.02", "stamp_tolerance_s: soon"))
                .find("rig.stamp_tolerance_s"),
            std::string::npos);
  EXPECT_NE(errorOf(variant("{name: right", "{name: left")).find("duplicate sensor name 'left'"),
            std::string::npos);
  EXPECT_NE(errorOf(variant("/r/info", "/l/info")).find("'/l/info' used twice"), std::string::npos);
  EXPECT_NE(errorOf(variant("features_topic: /r/board", "features_topic: left/camera_board"))
                .find("'left/camera_board' used twice"),
            std::string::npos);
  EXPECT_NE(errorOf(variant("b: right", "b: rear")).find("known_extrinsics[0].b"),
            std::string::npos);
  EXPECT_NE(errorOf(variant("translation: [0.12, 0, 0]", "translation: [0.12, 0]"))
                .find("known_extrinsics[0].a_T_b.translation"),
            std::string::npos);
  EXPECT_NE(errorOf(variant("0.9999619", "0.5")).find("not a unit quaternion"), std::string::npos);
  EXPECT_NE(errorOf("cameras: [").find("invalid YAML"), std::string::npos);
  EXPECT_NE(errorOf("- 1\n- 2\n").find("top level"), std::string::npos);
  // One sensor is not a rig.
  EXPECT_NE(errorOf("target: t.yaml\nreference: vlp\nlidars: [{name: vlp, cloud_topic: /p}]\n")
                .find("two sensors"),
            std::string::npos);
}

TEST(RigConfig, LoadsTheShippedRigAndItsTarget) {
  const std::string path =
      std::string(BOARD_CALIB_SOURCE_DIR) + "/config/rigs/multi_rig_apriltag.yaml";
  auto rig = loadRigConfig(path);
  ASSERT_TRUE(rig) << rig.error();
  EXPECT_EQ(rig->cameras.size(), 2u);
  EXPECT_EQ(rig->lidars.size(), 2u);
  std::ifstream target(rig->target_path);
  EXPECT_TRUE(target.good()) << rig->target_path;
  auto missing = loadRigConfig("/nonexistent/rig.yaml");
  ASSERT_FALSE(missing);
  EXPECT_NE(missing.error().find("cannot read rig file"), std::string::npos);
}
