#include <board_calib/core/result_io.h>
#include <board_calib/core/transform.h>

#include <gtest/gtest.h>

#include <cstdio>
#include <random>

using namespace board_calib;

TEST(Transform, QuaternionAndMatrixRoundTrip) {
  std::mt19937 rng(3);
  for (int i = 0; i < 50; ++i) {
    const Eigen::Isometry3d T = perturb(Eigen::Isometry3d::Identity(), 1.5, 2.0, rng);
    const Eigen::Isometry3d a = makeTransform(T.translation(), quaternionXyzw(T));
    EXPECT_LT(rotationErrorDeg(a, T), 1e-9);
    EXPECT_LT(translationErrorM(a, T), 1e-12);
    const auto m = rowMajor(T);
    const auto b = fromRowMajor(std::vector<double>(m.begin(), m.end()));
    ASSERT_TRUE(b.ok());
    EXPECT_LT(rotationErrorDeg(*b, T), 1e-9);
    EXPECT_LT(expSO3(logSO3(T.rotation())).isApprox(T.rotation(), 1e-9) ? 0 : 1, 1);
    EXPECT_TRUE(fromRollPitchYaw(rollPitchYaw(T.rotation())).isApprox(T.rotation(), 1e-9));
  }
  EXPECT_FALSE(fromRowMajor({1, 2, 3}).ok());
  EXPECT_FALSE(fromRowMajor({2, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0}).ok());
}

// The one Kabsch of the core (solvers, consistency check, consensus prior): the rotation that
// generated the pairs, a weight that silences an outlier, never a reflection, and a refusal when
// one direction cannot fix a rotation.
TEST(Transform, RotationAligningFindsTheRotationOrSaysWhyNot) {
  std::mt19937 rng(11);
  std::normal_distribution<double> unit(0.0, 1.0);
  for (int trial = 0; trial < 20; ++trial) {
    const Eigen::Matrix3d R = perturb(Eigen::Isometry3d::Identity(), 1.5, 0.0, rng).rotation();
    std::vector<Eigen::Vector3d> from, to;
    for (int i = 0; i < 6; ++i) {
      from.emplace_back(unit(rng), unit(rng), unit(rng));
      to.push_back(R * from.back());
    }
    auto found = rotationAligning(from, to, {}, 1e-6);
    ASSERT_TRUE(found.ok());
    EXPECT_TRUE(found->isApprox(R, 1e-9));
    // A far outlier at weight 0 changes nothing.
    from.push_back(Eigen::Vector3d(1, 0, 0));
    to.push_back(Eigen::Vector3d(-5, 3, 1));
    std::vector<double> weights(from.size(), 1.0);
    weights.back() = 0.0;
    found = rotationAligning(from, to, weights, 1e-6);
    ASSERT_TRUE(found.ok());
    EXPECT_TRUE(found->isApprox(R, 1e-9));
  }
  // Mirrored pairs: the best proper rotation, determinant +1.
  const std::vector<Eigen::Vector3d> from = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  const std::vector<Eigen::Vector3d> mirrored = {{1, 0, 0}, {0, 1, 0}, {0, 0, -1}};
  const auto proper = rotationAligning(from, mirrored, {}, 1e-6);
  ASSERT_TRUE(proper.ok());
  EXPECT_NEAR(proper->determinant(), 1.0, 1e-12);
  // One direction (parallel pairs) or nothing does not fix a rotation; sizes must match.
  const std::vector<Eigen::Vector3d> parallel = {{0, 0, 1}, {0, 0, 2}};
  EXPECT_FALSE(rotationAligning(parallel, parallel, {}, 1e-6).ok());
  EXPECT_FALSE(rotationAligning({}, {}, {}, 1e-6).ok());
  EXPECT_FALSE(rotationAligning(from, parallel, {}, 1e-6).ok());
  EXPECT_FALSE(rotationAligning(from, from, {1.0}, 1e-6).ok());
}

TEST(Plane, TransformKeepsPointsOnPlane) {
  std::mt19937 rng(5);
  const Eigen::Isometry3d T = perturb(Eigen::Isometry3d::Identity(), 1.0, 1.0, rng);
  Plane p;
  p.normal = Eigen::Vector3d(1, 2, 3).normalized();
  p.offset = 2.5;
  const Eigen::Vector3d on = p.normal * p.offset + p.normal.unitOrthogonal() * 0.7;
  EXPECT_NEAR(p.transformed(T).signedDistance(T * on), 0.0, 1e-12);
}

TEST(ResultFile, WriteReadRoundTrip) {
  std::mt19937 rng(11);
  ResultFile r;
  r.method = "pbpc";
  r.camera_frame = "camera";
  r.lidar_frame = "os1_lidar";
  r.camera_T_lidar = perturb(Eigen::Isometry3d::Identity(), 1.0, 0.5, rng);
  r.views_used = 16;
  r.mlre_px = 1.62;
  r.stddev = PoseStddev{{0.001, 0.002, 0.003}, {0.01, 0.02, 0.03}};
  r.quality["plane_rms_mm"] = 12.5;
  r.notes.push_back("board looks 3% larger in the LiDAR than declared");
  r.reference_frame = "os1_lidar";
  r.sensors.push_back({"os1_lidar", "lidar", Eigen::Isometry3d::Identity()});
  r.sensors.push_back({"camera", "camera", r.camera_T_lidar.inverse()});
  r.pairs.push_back({"camera", "os1_lidar", r.camera_T_lidar, 1.7, std::nullopt});
  r.pairs.push_back({"camera2", "os1_lidar", r.camera_T_lidar, std::nullopt,
                     PoseStddev{{0.004, 0.005, 0.006}, {0.1, 0.2, 0.3}}});

  const std::string path = ::testing::TempDir() + "/board_calib_result.yaml";
  ASSERT_TRUE(writeResultFile(path, r).ok);
  const auto back = loadResultFile(path);
  std::remove(path.c_str());
  ASSERT_TRUE(back.ok()) << back.error();
  EXPECT_EQ(back->method, "pbpc");
  EXPECT_EQ(back->camera_frame, "camera");
  EXPECT_EQ(back->lidar_frame, "os1_lidar");
  EXPECT_LT(rotationErrorDeg(back->camera_T_lidar, r.camera_T_lidar), 1e-6);
  EXPECT_LT(translationErrorM(back->camera_T_lidar, r.camera_T_lidar), 1e-8);
  EXPECT_EQ(back->views_used, 16);
  ASSERT_TRUE(back->mlre_px.has_value());
  EXPECT_NEAR(*back->mlre_px, 1.62, 1e-9);
  ASSERT_TRUE(back->stddev.has_value());
  EXPECT_NEAR(back->stddev->rotation_deg.z(), 0.03, 1e-9);
  EXPECT_NEAR(back->quality.at("plane_rms_mm"), 12.5, 1e-9);
  ASSERT_EQ(back->notes.size(), 1u);
  ASSERT_EQ(back->sensors.size(), 2u);
  ASSERT_EQ(back->pairs.size(), 2u);
  EXPECT_LT(rotationErrorDeg(back->pairs[0].camera_T_lidar, r.camera_T_lidar), 1e-6);
  // Per-pair stddev is optional: absent stays absent, present round-trips.
  EXPECT_FALSE(back->pairs[0].stddev.has_value());
  EXPECT_FALSE(back->pairs[1].mlre_px.has_value());
  ASSERT_TRUE(back->pairs[1].stddev.has_value());
  EXPECT_NEAR(back->pairs[1].stddev->translation_m.y(), 0.005, 1e-9);
  EXPECT_NEAR(back->pairs[1].stddev->rotation_deg.z(), 0.3, 1e-9);
}

TEST(ResultFile, ContractKeysPresentAndInverseConsistent) {
  ResultFile r;
  r.method = "ppc";
  r.camera_frame = "c";
  r.lidar_frame = "l";
  r.camera_T_lidar =
      makeTransform(Eigen::Vector3d(0.1, -0.2, 0.3), Eigen::Vector4d(0.5, -0.5, 0.5, 0.5));
  const std::string yaml = resultToYaml(r);
  for (const char* key :
       {"method:", "camera_frame:", "lidar_frame:", "camera_T_lidar:", "lidar_T_camera:",
        "translation:", "rotation_xyzw:", "matrix:", "views_used:"})
    EXPECT_NE(yaml.find(key), std::string::npos) << key;
  // Matrix-only input (e.g. hand-edited) is accepted as well.
  const auto m = rowMajor(r.camera_T_lidar);
  std::string text = "method: x\ncamera_frame: c\nlidar_frame: l\ncamera_T_lidar: {matrix: [";
  for (int i = 0; i < 16; ++i) text += std::to_string(m[i]) + (i < 15 ? ", " : "]}\n");
  const auto parsed = parseResult(text);
  ASSERT_TRUE(parsed.ok()) << parsed.error();
  EXPECT_LT(rotationErrorDeg(parsed->camera_T_lidar, r.camera_T_lidar), 1e-3);
}

TEST(ResultFile, BadInputGivesReasons) {
  EXPECT_FALSE(loadResultFile("/nonexistent.yaml").ok());
  EXPECT_FALSE(parseResult("method: x\n").ok());
  const auto bad = parseResult(
      "method: x\ncamera_frame: c\nlidar_frame: l\ncamera_T_lidar: {translation: [1, 2]}\n");
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.error().find("camera_T_lidar"), std::string::npos);
}
