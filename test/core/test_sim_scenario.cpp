// Scenario files, board motion, frame timeline and ground truth of the simulator.
#include <board_calib/core/sim/scenario.h>
#include <board_calib/core/transform.h>

#include <gtest/gtest.h>

#include <dirent.h>

#include <cmath>
#include <cstdlib>
#include <fstream>
#include <map>

namespace board_calib {
namespace sim {
namespace {

const std::string kScenarioDir = std::string(BOARD_CALIB_SOURCE_DIR) + "/config/scenarios";

std::vector<std::string> scenarioFiles() {
  std::vector<std::string> out;
  if (DIR* dir = opendir(kScenarioDir.c_str())) {
    while (dirent* entry = readdir(dir)) {
      const std::string name = entry->d_name;
      if (name.size() > 5 && name.substr(name.size() - 5) == ".yaml")
        out.push_back(kScenarioDir + "/" + name);
    }
    closedir(dir);
  }
  std::sort(out.begin(), out.end());
  return out;
}

// Angle (deg, 0..90) between a board edge and the LiDAR scan lines as the LiDAR sees it.
double edgeSlopeDeg(const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                    const Eigen::Vector3d& centre) {
  const Eigen::Vector3d view = centre.normalized();
  Eigen::Vector3d edge = b - a;
  edge -= edge.dot(view) * view;
  const Eigen::Vector3d scan = Eigen::Vector3d::UnitZ().cross(view).normalized();
  return std::acos(std::min(1.0, std::abs(edge.normalized().dot(scan)))) / kRadPerDeg;
}

TEST(SimScenario, ShippedScenariosLoadAndPlaceEveryPose) {
  const auto files = scenarioFiles();
  ASSERT_GE(files.size(), 5u);
  for (const auto& file : files) {
    SCOPED_TRACE(file);
    auto scenario = loadScenario(file);
    ASSERT_TRUE(scenario.ok()) << scenario.error();
    auto timeline = makeTimeline(*scenario);
    ASSERT_TRUE(timeline.ok()) << timeline.error();
    const auto& s = *scenario;
    ASSERT_EQ(timeline->world_T_board_poses.size(), static_cast<size_t>(s.motion.poses));
    const auto outer = s.scene.target.outerCorners();
    for (const auto& world_T_board : timeline->world_T_board_poses) {
      const Eigen::Vector3d centre_rig =
          s.world_T_rig.inverse() * world_T_board * s.scene.target.center();
      EXPECT_GE(centre_rig.norm(), s.motion.min_distance_m - 1e-9);
      EXPECT_LE(centre_rig.norm(), s.motion.max_distance_m + 1e-9);
      for (size_t c = 0; c < s.cameras.size(); ++c) {
        auto model = CameraModel::create(s.cameras[c].intrinsics);
        ASSERT_TRUE(model.ok());
        const Eigen::Isometry3d camera_T_board =
            worldTCamera(s, static_cast<int>(c)).inverse() * world_T_board;
        for (const auto& corner : outer) EXPECT_TRUE(model->isVisible(camera_T_board * corner));
        // The printed face (seen from board -z) faces the camera.
        EXPECT_LT((camera_T_board.inverse().translation()).z(), 0);
      }
      for (size_t l = 0; l < s.lidars.size(); ++l) {
        const Eigen::Isometry3d lidar_T_board =
            worldTLidar(s, static_cast<int>(l)).inverse() * world_T_board;
        const Eigen::Vector3d centre = lidar_T_board * s.scene.target.center();
        for (int e = 0; e < 4; ++e)
          EXPECT_GE(
              edgeSlopeDeg(lidar_T_board * outer[e], lidar_T_board * outer[(e + 1) % 4], centre),
              s.motion.min_edge_slope_deg - 1e-6)
              << "edge " << e << " near-parallel to the scan lines";
      }
    }
  }
}

TEST(SimScenario, TimelineHoldsMovesStampsAndThinning) {
  auto scenario = loadScenario(kScenarioDir + "/checker_vlp16_1280.yaml");  // 3 still, 1 moving
  ASSERT_TRUE(scenario.ok()) << scenario.error();
  const Scenario& s = *scenario;
  auto timeline = makeTimeline(s);
  ASSERT_TRUE(timeline.ok()) << timeline.error();
  const auto& frames = timeline->frames;
  for (size_t i = 1; i < frames.size(); ++i) EXPECT_LE(frames[i - 1].stamp, frames[i].stamp);
  // Per sensor and held pose: exactly still_frames_per_hold still frames at the held pose.
  std::map<std::pair<bool, int>, int> still_count;
  int moving_images = 0, moving_clouds = 0;
  for (const auto& f : frames) {
    if (f.still) {
      ++still_count[{f.is_camera, f.pose}];
      const auto& held = timeline->world_T_board_poses[static_cast<size_t>(f.pose)];
      EXPECT_LT(translationErrorM(f.world_T_board, held), 1e-12);
    } else {
      EXPECT_EQ(f.pose, -1);
      (f.is_camera ? moving_images : moving_clouds)++;
    }
    // Sensors run at their rates from their offsets.
    const double rate = f.is_camera ? s.cameras[0].rate_hz : s.lidars[0].spec.rate_hz;
    const double offset = f.is_camera ? s.cameras[0].stamp_offset_s : s.lidars[0].stamp_offset_s;
    const double k = (f.stamp - offset) * rate;
    EXPECT_NEAR(k, std::round(k), 1e-6);
  }
  for (int p = 0; p < s.motion.poses; ++p) {
    EXPECT_EQ((still_count[{true, p}]), s.motion.still_frames_per_hold) << "pose " << p;
    EXPECT_EQ((still_count[{false, p}]), s.motion.still_frames_per_hold) << "pose " << p;
  }
  ASSERT_GT(s.motion.frames_per_move, 0);
  EXPECT_EQ(moving_images, (s.motion.poses - 1) * s.motion.frames_per_move);
  EXPECT_EQ(moving_clouds, (s.motion.poses - 1) * s.motion.frames_per_move);
  // A still image and a still cloud of the same pose are a few ms apart.
  double best_gap = 1e9;
  for (const auto& a : frames)
    for (const auto& b : frames)
      if (a.is_camera && !b.is_camera && a.still && b.still && a.pose == b.pose)
        best_gap = std::min(best_gap, std::abs(a.stamp - b.stamp));
  EXPECT_NEAR(best_gap, std::abs(s.cameras[0].stamp_offset_s - s.lidars[0].stamp_offset_s), 1e-9);
  // Moves are smooth: consecutive held poses are different.
  EXPECT_GT(translationErrorM(timeline->world_T_board_poses[0], timeline->world_T_board_poses[1]),
            1e-3);
}

TEST(SimScenario, GroundTruthCoversEveryPair) {
  auto scenario = loadScenario(kScenarioDir + "/multi_rig_apriltag.yaml");
  ASSERT_TRUE(scenario.ok()) << scenario.error();
  const Scenario& s = *scenario;
  const ResultFile truth = groundTruth(s);
  ASSERT_EQ(truth.pairs.size(), s.cameras.size() * s.lidars.size());
  ASSERT_EQ(truth.sensors.size(), s.cameras.size() + s.lidars.size());
  EXPECT_EQ(truth.camera_frame, s.cameras[0].frame_id);
  EXPECT_EQ(truth.lidar_frame, s.lidars[0].frame_id);
  // Independent check from the file's numbers: left camera 12 cm from the right one, the
  // OS1 16 cm above the VLP and turned by 30 deg.
  std::map<std::string, Eigen::Isometry3d> ref_T;
  for (const auto& e : truth.sensors) ref_T[e.frame] = e.reference_T_sensor;
  EXPECT_NEAR((ref_T["left_optical"].translation() - ref_T["right_optical"].translation()).norm(),
              0.12, 1e-9);
  EXPECT_NEAR(rotationErrorDeg(ref_T["velodyne"], ref_T["os1_lidar"]), std::hypot(30.0, 1.1), 0.5);
  for (const auto& pair : truth.pairs) {
    const Eigen::Isometry3d expected = ref_T[pair.camera_frame].inverse() * ref_T[pair.lidar_frame];
    EXPECT_LT(translationErrorM(pair.camera_T_lidar, expected), 1e-9);
    EXPECT_LT(rotationErrorDeg(pair.camera_T_lidar, expected), 1e-6);
  }
  // Round trip through the result-file writer and reader.
  auto parsed = parseResult(resultToYaml(truth));
  ASSERT_TRUE(parsed.ok()) << parsed.error();
  EXPECT_EQ(parsed->pairs.size(), truth.pairs.size());
  EXPECT_LT(translationErrorM(parsed->camera_T_lidar, truth.camera_T_lidar), 1e-6);
}

TEST(SimScenario, FramesReuseStillRenderAndDifferOnlyByNoise) {
  auto scenario = loadScenario(kScenarioDir + "/unorganized_noring.yaml");
  ASSERT_TRUE(scenario.ok()) << scenario.error();
  scenario->cameras[0].intrinsics.width = 320;  // small: this checks logic, not rendering
  scenario->cameras[0].intrinsics.height = 200;
  scenario->cameras[0].intrinsics.fx = scenario->cameras[0].intrinsics.fy = 240;
  scenario->cameras[0].intrinsics.cx = 160;
  scenario->cameras[0].intrinsics.cy = 100;
  scenario->cameras[0].render.noise_sigma = 2.0;
  scenario->motion.poses = 2;
  auto timeline = makeTimeline(*scenario);
  ASSERT_TRUE(timeline.ok()) << timeline.error();
  auto generator = FrameGenerator::create(*scenario);
  ASSERT_TRUE(generator.ok());
  std::vector<std::pair<size_t, cv::Mat>> still_pose0;
  for (size_t i = 0; i < timeline->frames.size(); ++i) {
    const Frame& f = timeline->frames[i];
    if (f.is_camera && f.still && f.pose == 0) still_pose0.emplace_back(i, generator->image(f, i));
    if (!f.is_camera) {
      const LidarCloud cloud = generator->cloud(f, i);
      EXPECT_FALSE(cloud.has_ring);
      EXPECT_FALSE(cloud.organized());
      EXPECT_EQ(cloud.frame_id, scenario->lidars[0].frame_id);
      EXPECT_DOUBLE_EQ(cloud.stamp, f.stamp);
    }
  }
  ASSERT_EQ(still_pose0.size(), 2u);
  cv::Mat diff;
  cv::absdiff(still_pose0[0].second, still_pose0[1].second, diff);
  const double mean_abs = cv::mean(diff)[0];
  // Two independent N(0, 2) noises: E|a - b| = 2 * 2 / sqrt(pi) = 2.26 (less where clipped).
  EXPECT_GT(mean_abs, 1.5);
  EXPECT_LT(mean_abs, 2.8);
  // Regenerating a frame on its own gives the same pixels (noise seeded per frame).
  const cv::Mat again =
      generator->image(timeline->frames[still_pose0[1].first], still_pose0[1].first);
  EXPECT_EQ(cv::norm(again, still_pose0[1].second, cv::NORM_INF), 0.0);
}

// Lines of sight: ray-cast the first LiDAR to the board's centre, no panel in between.
void expectBoardInSight(const Scenario& scenario) {
  auto t = makeTimeline(scenario);
  ASSERT_TRUE(t.ok()) << t.error();
  for (const auto& pose : t->world_T_board_poses) {
    const Eigen::Vector3d centre = pose * scenario.scene.target.center();
    for (const auto& panel : scenario.scene.panels) {
      const Eigen::Isometry3d inv = panel.world_T_panel.inverse();
      const Eigen::Vector3d a0 = inv * worldTLidar(scenario, 0).translation(), b0 = inv * centre;
      if ((a0.z() > 0) == (b0.z() > 0)) continue;
      const Eigen::Vector3d q = a0 + (b0 - a0) * (a0.z() / (a0.z() - b0.z()));
      EXPECT_FALSE(std::abs(q.x()) <= 0.5 * panel.width_m &&
                   std::abs(q.y()) <= 0.5 * panel.height_m);
    }
  }
}

// A few still images of the scene as binary PPM (rgb) in `dir`, to look at.
void dumpStillImages(const Scenario& scenario, const char* dir) {
  auto t = makeTimeline(scenario);
  auto gen = FrameGenerator::create(scenario);
  ASSERT_TRUE(gen.ok());
  for (size_t i = 0; i < t->frames.size(); ++i)
    if (t->frames[i].is_camera && t->frames[i].still && t->frames[i].pose % 5 == 0) {
      const cv::Mat image = gen->image(t->frames[i], i);  // bgr8 -> binary PPM (rgb)
      std::ofstream out(std::string(dir) + "/" + scenario.name + "_" +
                        std::to_string(t->frames[i].pose) + ".ppm");
      out << "P6\n" << image.cols << " " << image.rows << "\n255\n";
      for (int v = 0; v < image.rows; ++v)
        for (int u = 0; u < image.cols; ++u) {
          const cv::Vec3b c = image.at<cv::Vec3b>(v, u);
          out.put(static_cast<char>(c[2]))
              .put(static_cast<char>(c[1]))
              .put(static_cast<char>(c[0]));
        }
    }
}

// Seeded clutter and marks: the count asked for, the same layout for the same seed, another
// for another clutter_seed, marks inside the board, no panel hiding any board pose from any
// sensor (the pose sampler checks the lines of sight) and far poses (5-14 m) outdoors.
// SIM_SCENARIO_DUMP=DIR writes a few still images of both scenes as PPM to look at.
TEST(SimScenario, SeededClutterAndOutdoorFarPoses) {
  auto clutter = loadScenario(kScenarioDir + "/plain_vlp32c_clutter.yaml");
  ASSERT_TRUE(clutter.ok()) << clutter.error();
  EXPECT_EQ(clutter->scene.panels.size(), 12u);
  auto again = loadScenario(kScenarioDir + "/plain_vlp32c_clutter.yaml");
  ASSERT_TRUE(again.ok());
  for (size_t k = 0; k < clutter->scene.panels.size(); ++k)
    EXPECT_TRUE(
        clutter->scene.panels[k].world_T_panel.isApprox(again->scene.panels[k].world_T_panel));
  const std::string yaml =
      "target: ../targets/plain_1016.yaml\n"
      "cameras: [{name: c, width: 640, height: 480, fx: 500, fy: 500, cx: 320, cy: 240}]\n"
      "scene: {posters: 5, board_marks: 4, clutter_seed: ";
  auto a = parseScenario(yaml + "1}\n", kScenarioDir);
  auto b = parseScenario(yaml + "2}\n", kScenarioDir);
  ASSERT_TRUE(a.ok()) << a.error();
  ASSERT_TRUE(b.ok()) << b.error();
  ASSERT_EQ(a->scene.panels.size(), 5u);
  ASSERT_EQ(a->scene.board_marks.size(), 4u);
  EXPECT_FALSE(a->scene.panels[0].world_T_panel.isApprox(b->scene.panels[0].world_T_panel));
  for (const auto& m : a->scene.board_marks) {
    EXPECT_GT(m.min.minCoeff(), 0.0);
    EXPECT_LT(m.max.x(), a->scene.target.width);
    EXPECT_LT(m.max.y(), a->scene.target.height);
  }
  // Board-sized: every non-door panel within 0.8..1.3 of the board's sides.
  for (const auto& p : clutter->scene.panels) {
    const double lo = std::min(p.width_m, p.height_m), hi = std::max(p.width_m, p.height_m);
    if (hi == 2.0) continue;  // a door
    EXPECT_GE(lo, 0.8 * 1.016 - 1e-9);
    EXPECT_LE(hi, 1.3 * 1.016 + 1e-9);
  }

  auto far = loadScenario(kScenarioDir + "/plain_vlp16_outdoor_far.yaml");
  ASSERT_TRUE(far.ok()) << far.error();
  EXPECT_TRUE(far->scene.outdoor);
  auto timeline = makeTimeline(*far);
  ASSERT_TRUE(timeline.ok()) << timeline.error();
  double nearest = 1e9, farthest = 0;
  for (const auto& pose : timeline->world_T_board_poses) {
    const double d = (far->world_T_rig.inverse() * pose * far->scene.target.center()).norm();
    nearest = std::min(nearest, d);
    farthest = std::max(farthest, d);
  }
  EXPECT_GE(nearest, 5.0);
  EXPECT_LE(farthest, 14.0);
  EXPECT_GT(farthest - nearest, 4.0) << "poses spread over the distance range";

  for (const auto* s : {&*clutter, &*far}) expectBoardInSight(*s);
  if (const char* dump = std::getenv("SIM_SCENARIO_DUMP"))  // eyeball the scenes
    for (const auto* s : {&*clutter, &*far}) dumpStillImages(*s, dump);
}

// render.mono in a scenario file: the camera's frames come as one grey channel.
TEST(SimScenario, MonoCameraFromTheScenarioFile) {
  auto s = parseScenario(
      "target: ../targets/plain_1016.yaml\n"
      "cameras: [{name: c, width: 320, height: 200, fx: 240, fy: 240, cx: 160, cy: 100,\n"
      "           render: {supersampling: 1, mono: true}}]\n"
      "motion: {poses: 1}\n",
      kScenarioDir);
  ASSERT_TRUE(s.ok()) << s.error();
  EXPECT_TRUE(s->cameras[0].render.mono);
  auto timeline = makeTimeline(*s);
  ASSERT_TRUE(timeline.ok()) << timeline.error();
  auto generator = FrameGenerator::create(*s);
  ASSERT_TRUE(generator.ok());
  for (size_t i = 0; i < timeline->frames.size(); ++i)
    if (timeline->frames[i].is_camera) {
      EXPECT_EQ(generator->image(timeline->frames[i], i).type(), CV_8UC1);
      break;
    }
}

TEST(SimScenario, BadFilesGiveReasonsNamingTheKey) {
  const std::string base = kScenarioDir;
  const std::string good_camera =
      "cameras: [{name: cam, width: 640, height: 480, fx: 500, fy: 500, cx: 320, cy: 240}]\n";
  struct Case {
    std::string yaml;
    std::string expect;
  };
  std::vector<Case> cases = {
      {"target: ../targets/plain_1016.yaml\n" + good_camera + "colour: red\n", "colour"},
      {good_camera, "target"},
      {"target: nope.yaml\n" + good_camera, "nope.yaml"},
      {"target: ../targets/plain_1016.yaml\nlidars: [{name: l, preset: HDL-1}]\n", "HDL-1"},
      {"target: ../targets/plain_1016.yaml\ncameras: [{name: c, width: 640, height: 480, fx: -5, "
       "fy: 500, cx: 1, "
       "cy: 1}]\n",
       "focal"},
      {"target: ../targets/plain_1016.yaml\n" + good_camera + "motion: {poses: 0}\n", "poses"},
      {"target: ../targets/plain_1016.yaml\n" + good_camera + "motion: {hold_s: fast}\n",
       "motion.hold_s"},
      {"target: ../targets/plain_1016.yaml\n", "no sensors"},
      {"target: [\n", "YAML"},
      {"target: ../targets/plain_1016.yaml\n" + good_camera + "scene: {posters: -1}\n",
       "scene.posters"},
      {"target: ../targets/plain_1016.yaml\n" + good_camera + "scene: {board_grey: 2}\n",
       "board_grey"},
      {"target: ../targets/plain_1016.yaml\n" + good_camera +
           "scene: {panels: [{center: [1, 2], width: 1, height: 1}]}\n",
       "scene.panels[0].center"},
      {"target: ../targets/plain_1016.yaml\n" + good_camera +
           "scene: {board_marks: [{min: [0, 0]}]}\n",
       "scene.board_marks[0].max"},
      // A barrel polynomial that peaks at a normalised radius of 1.06 while the corners of this
      // wide image need 1.62 (sweep 6's l08): rendered as a fan of rays before, silently.
      {"target: ../targets/plain_1016.yaml\ncameras: [{name: c, width: 1920, height: 1200, fx: "
       "700, "
       "fy: 700, cx: 960, cy: 600, distortion_model: plumb_bob, D: [-0.25, 0.07, 0, 0, -0.01]}]\n",
       "no inverse at image pixel (0, 0)"},
  };
  // Absurd values (trust sweep 7): a NaN pose was reported as "too few LiDAR rings on the
  // board"; a 200000 px wide camera, 1e9 poses or holds of 1e6 s ended in std::bad_alloc.
  const std::vector<Case> absurd = {
      {"target: ../targets/plain_1016.yaml\nlidars: [{name: l, preset: VLP-16, pose: "
       "{translation: [.nan, 0, 0]}}]\n",
       "lidars[0].pose.translation' must be a list of finite numbers"},
      {"target: ../targets/plain_1016.yaml\ncameras: [{name: c, width: 200000, height: 200000, "
       "fx: 500, fy: 500, cx: 1, cy: 1}]\n",
       "beyond 250 megapixels"},
      {"target: ../targets/plain_1016.yaml\n" + good_camera + "motion: {poses: 1000000000}\n",
       "poses must be <= 10000"},
      {"target: ../targets/plain_1016.yaml\n" + good_camera + "motion: {hold_s: 1e6}\n",
       "hold_s must be in (0, 3600]"},
      {"target: ../targets/plain_1016.yaml\n" + good_camera + "motion: {hold_s: .inf}\n",
       "must be a finite number"},
  };
  cases.insert(cases.end(), absurd.begin(), absurd.end());
  for (const auto& c : cases) {
    auto s = parseScenario(c.yaml, base);
    ASSERT_FALSE(s.ok()) << c.yaml;
    EXPECT_NE(s.error().find(c.expect), std::string::npos) << "reason: " << s.error();
  }
  // Fields of view that cannot overlap: a clear reason instead of a hang.
  auto s = parseScenario(
      "target: ../targets/plain_1016.yaml\n"
      "cameras: [{name: c, width: 640, height: 480, fx: 500, fy: 500, cx: 320, cy: 240,\n"
      "           pose: {rpy_deg: [0, 0, 180]}}]\n"
      "motion: {poses: 1}\n",
      base);
  ASSERT_TRUE(s.ok()) << s.error();
  auto timeline = makeTimeline(*s);
  ASSERT_FALSE(timeline.ok());
  EXPECT_NE(timeline.error().find("cannot place board pose 0"), std::string::npos)
      << timeline.error();
}

}  // namespace
}  // namespace sim
}  // namespace board_calib
