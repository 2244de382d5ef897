// Live and offline rigs are the same code: the same simulated frames fed through the offline
// entry (raw images and clouds into core/pipeline/rig_pipeline.h, as calibrate_bag --config
// does) and through the live entry (the detectors as the detector nodelets run them, their
// features into the same pipeline, as the calibrator's rig mode receives them) give the same
// board poses and the same judged result, at the simulator's truth.
#include <board_calib/core/pipeline/rig_calibration.h>
#include <board_calib/core/pipeline/rig_pipeline.h>
#include <board_calib/core/pipeline/rig_report.h>
#include <board_calib/core/projection/view_overlay.h>
#include <board_calib/core/sim/scenario.h>
#include <board_calib/core/transform.h>

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>

namespace board_calib {
namespace {

std::string readFile(const std::string& path) {
  std::ifstream in(path);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

// The offline report draws, per camera, the kept images of captured poses with every LiDAR at
// the solved extrinsic, and the LiDAR's board lands on the camera's board.
void expectOverlaysOnTheBoard(const RigPipeline& pipeline, const RigCalibration& run,
                              const RigConfig& rig) {
  const std::vector<RigCameraFrames> frames = pipeline.overlayFrames();
  ASSERT_EQ(frames.size(), rig.cameras.size());
  const std::string dir =
      (std::filesystem::temp_directory_path() / ("rig_overlays_" + std::to_string(::getpid())))
          .string();
  RigReportInputs inputs;
  inputs.source = "test";
  inputs.camera_frames = frames;
  ASSERT_TRUE(writeRigReport(dir, rig, run.problem, run.solution, run.result, inputs));
  const std::string report = readFile(dir + "/report.md");
  int overlays = 0;
  double worst_inside = 1.0;
  for (const auto& camera : frames) {
    // 6 poses, 4 kept images per camera (the default): every camera has its overlays.
    EXPECT_EQ(camera.images.size(), 4u) << rig.cameras[static_cast<size_t>(camera.sensor)].name;
    const std::string& frame = run.solution.sensors[static_cast<size_t>(camera.sensor)].frame;
    for (const auto& pose : run.problem.poses) {
      const auto seen = pose.cameras.find(camera.sensor);
      if (seen == pose.cameras.end() || !camera.images.count(seen->second.stamp)) continue;
      const std::string file = "overlays/" + frame + "_pose_" + std::to_string(pose.id) + ".jpg";
      EXPECT_TRUE(std::filesystem::exists(dir + "/" + file)) << file;
      EXPECT_NE(report.find(file), std::string::npos) << "linked from the report: " << file;
      ++overlays;
      for (const auto& [sensor, lidar] : pose.lidars) {
        const std::string& lidar_frame = run.solution.sensors[static_cast<size_t>(sensor)].frame;
        for (const auto& pair : run.result.pairs) {
          if (pair.camera_frame != frame || pair.lidar_frame != lidar_frame) continue;
          const auto inside = boardPointsInsideImageBoard(lidar, seen->second, pair.camera_T_lidar);
          ASSERT_TRUE(inside.has_value());
          // The board points are the LiDAR's board inliers; at the solved pose (within 0.2 deg /
          // 1 cm) only points within the beam footprint and range noise (~1-2 cm) of an edge can
          // project outside the image lines: a rim of a 0.6-1 m board, a few % of its points.
          EXPECT_GE(*inside, 0.9) << frame << " <- " << lidar_frame << " pose " << pose.id;
          worst_inside = std::min(worst_inside, *inside);
          // The figure can fail: 10 cm to the side puts a band of the board off the image board.
          Eigen::Isometry3d shifted = pair.camera_T_lidar;
          shifted.translation().x() += 0.10;
          EXPECT_LT(*boardPointsInsideImageBoard(lidar, seen->second, shifted), *inside - 0.05);
          EXPECT_NE(readFile(dir + "/" + pair.camera_frame + "__" + lidar_frame + "/report.md")
                        .find("../" + file),
                    std::string::npos)
              << "linked from the pair page";
        }
      }
    }
  }
  EXPECT_GE(overlays, static_cast<int>(4 * rig.cameras.size()));
  std::printf("%d overlays; board points inside the image board: %.1f %% at the worst\n", overlays,
              100.0 * worst_inside);
  std::filesystem::remove_all(dir);
}

// Every simulated frame into both entries: raw frames into `offline` (as calibrate_bag --config
// feeds them), the detector nodelets' features into `live` (as the calibrator's rig mode gets
// them).
void playBoth(const sim::Scenario& scenario, const Target& target,
              const RigPipelineOptions& options, RigPipeline* offline, RigPipeline* live) {
  auto timeline = sim::makeTimeline(scenario);
  ASSERT_TRUE(timeline.ok()) << timeline.error();
  auto generator = sim::FrameGenerator::create(scenario);
  ASSERT_TRUE(generator.ok()) << generator.error();
  // The detector nodelets' work: one image detector per camera, the cloud detector per LiDAR.
  std::vector<ImageBoardDetector> detectors;
  std::vector<CameraModel> models;
  for (const auto& camera : scenario.cameras) {
    auto d = ImageBoardDetector::create(target, options.image);
    auto m = CameraModel::create(camera.intrinsics);
    ASSERT_TRUE(d.ok() && m.ok());
    detectors.push_back(std::move(*d));
    models.push_back(std::move(*m));
  }
  const int cameras = static_cast<int>(scenario.cameras.size());
  for (size_t i = 0; i < timeline->frames.size(); ++i) {
    const sim::Frame& f = timeline->frames[i];
    if (f.is_camera) {
      const auto& camera = scenario.cameras[static_cast<size_t>(f.sensor)];
      const cv::Mat image = generator->image(f, i);
      offline->addImage(f.sensor, image, camera.intrinsics, camera.frame_id, f.stamp);
      ImageDetection d = detectors[static_cast<size_t>(f.sensor)].detect(
          image, models[static_cast<size_t>(f.sensor)]);
      d.features.stamp = f.stamp;
      d.features.frame_id = camera.frame_id;
      live->addCameraFeatures(f.sensor, d.features);
    } else {
      LidarCloud cloud = generator->cloud(f, i);
      cloud.stamp = f.stamp;
      cloud.frame_id = scenario.lidars[static_cast<size_t>(f.sensor)].frame_id;
      offline->addCloud(f.sensor, cloud);
      LidarBoardDetection d = detectLidarBoard(cloud, target, options.lidar);
      d.features.stamp = cloud.stamp;
      d.features.frame_id = cloud.frame_id;
      live->addLidarFeatures(cameras + f.sensor, d.features);
    }
  }
}

TEST(RigPipeline, LiveAndOfflineEntriesGiveTheSameResult) {
  auto scenario =
      sim::loadScenario(std::string(BOARD_CALIB_SOURCE_DIR) + "/test/data/msg_rig_scenario.yaml");
  ASSERT_TRUE(scenario.ok()) << scenario.error();
  scenario->motion.poses = 6;  // enough to cross-validate (5), small enough for the test budget
  auto rig =
      loadRigConfig(std::string(BOARD_CALIB_SOURCE_DIR) + "/config/rigs/multi_rig_apriltag.yaml");
  ASSERT_TRUE(rig.ok()) << rig.error();
  const Target& target = scenario->scene.target;
  const RigPipelineOptions options = rigPipelineOptionsFor(*rig);
  auto offline = RigPipeline::create(*rig, target, options);
  auto live = RigPipeline::create(*rig, target, options);
  ASSERT_TRUE(offline.ok() && live.ok());
  playBoth(*scenario, target, options, &*offline, &*live);
  offline->finish();
  live->finish();
  auto offline_problem = offline->problem();
  auto live_problem = live->problem();
  ASSERT_TRUE(offline_problem.ok() && live_problem.ok());
  // Every hold captured once (the capture target), by both entries alike.
  EXPECT_EQ(offline_problem->poses.size(), static_cast<size_t>(scenario->motion.poses))
      << offline->session().captureStats().summary();
  ASSERT_EQ(offline_problem->poses.size(), live_problem->poses.size());

  const RigCalibration a = calibrateRig(*offline_problem, *rig, target);
  const RigCalibration b = calibrateRig(*live_problem, *rig, target);
  ASSERT_TRUE(a.solution.success) << a.reason;
  ASSERT_TRUE(b.solution.success) << b.reason;
  EXPECT_EQ(a.verdict, b.verdict);
  EXPECT_EQ(a.reason, b.reason);
  EXPECT_NE(a.verdict, Verdict::kFailed) << rigVerdictSummary(a);
  const ResultFile truth = sim::groundTruth(*scenario);
  ASSERT_EQ(a.pairs.size(), b.pairs.size());
  size_t checked = 0;
  for (size_t i = 0; i < a.pairs.size(); ++i) {
    // Same frames, same code: the same numbers (up to the solver's floating-point noise).
    EXPECT_LT(
        rotationErrorDeg(a.pairs[i].solution.camera_T_lidar, b.pairs[i].solution.camera_T_lidar),
        1e-9);
    EXPECT_LT(
        translationErrorM(a.pairs[i].solution.camera_T_lidar, b.pairs[i].solution.camera_T_lidar),
        1e-9);
    for (const auto& p : truth.pairs)
      if (p.camera_frame == a.pairs[i].camera_frame && p.lidar_frame == a.pairs[i].lidar_frame) {
        ++checked;
        // 6 poses: the rig e2e bound (0.2 deg / 1 cm) holds with room on this rig.
        EXPECT_LT(rotationErrorDeg(a.pairs[i].solution.camera_T_lidar, p.camera_T_lidar), 0.2)
            << p.camera_frame;
        EXPECT_LT(translationErrorM(a.pairs[i].solution.camera_T_lidar, p.camera_T_lidar), 0.01)
            << p.camera_frame;
      }
  }
  EXPECT_EQ(checked, a.pairs.size()) << "every pair compared with the truth";
  expectOverlaysOnTheBoard(*offline, a, *rig);
}

}  // namespace
}  // namespace board_calib
