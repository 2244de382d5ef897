// SPDX-License-Identifier: BSD-3-Clause
#include "support/sim_session.h"

#include <algorithm>
#include <chrono>
#include <map>
#include <set>

namespace board_calib {
namespace test_support {

sim::Scenario captureScenario(const sim::Scenario& base, double image_scale, double camera_hz,
                              bool organized, int poses, unsigned seed) {
  constexpr double kImageNoise = 2.0;  // grey levels
  sim::Scenario s = base;
  auto& cam = s.cameras.front();
  cam.intrinsics.width = static_cast<int>(cam.intrinsics.width * image_scale);
  cam.intrinsics.height = static_cast<int>(cam.intrinsics.height * image_scale);
  cam.intrinsics.fx *= image_scale;
  cam.intrinsics.fy *= image_scale;
  cam.intrinsics.cx *= image_scale;
  cam.intrinsics.cy *= image_scale;
  cam.render.noise_sigma = kImageNoise;
  cam.rate_hz = camera_hz;
  s.lidars.front().spec.organized = organized;
  s.lidars.front().spec.with_ring = organized;
  s.motion.poses = poses;
  s.motion.still_frames_per_hold = 0;  // every frame of the holds ...
  s.motion.frames_per_move = -1;       // ... and of the moves
  s.seed = seed;
  return s;
}

namespace {

// Each found image board against the true one, compared where it matters for a view: its centre
// in the image, off by more than a quarter of the true board's size there is another object
// (a true board's PnP centre is off by a few px; other rectangles by 100-700 px).
void scoreImages(const BoardSightings& sightings,
                 const std::map<double, Eigen::Isometry3d>& camera_T_board_truth,
                 const Target& target, const CameraModel* camera, SimulatedSession* out) {
  if (!camera) return;
  const auto corners = target.outerCorners();
  for (const auto& [stamp, sighting] : sightings.images) {
    const auto truth = camera_T_board_truth.find(stamp);
    if (truth == camera_T_board_truth.end()) continue;
    Eigen::Vector2d found_px, true_px, lo(1e18, 1e18), hi(-1e18, -1e18);
    bool ok = camera->projectUndistorted(sighting.camera_T_board * target.center(), &found_px) &&
              camera->projectUndistorted(truth->second * target.center(), &true_px);
    for (const auto& c : corners) {
      Eigen::Vector2d px;
      ok = ok && camera->projectUndistorted(truth->second * c, &px);
      lo = lo.cwiseMin(px);
      hi = hi.cwiseMax(px);
    }
    const double size_px = std::max(hi.x() - lo.x(), hi.y() - lo.y());
    if (ok && (found_px - true_px).norm() <= 0.25 * size_px)
      ++out->images_true;
    else
      ++out->images_wrong;
  }
}

}  // namespace

Expected<SimulatedSession> runSimulatedSession(const sim::Scenario& scenario,
                                               const PipelineOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  auto timeline = sim::makeTimeline(scenario);
  if (!timeline) return Expected<SimulatedSession>::failure(timeline.error());
  auto generator = sim::FrameGenerator::create(scenario);
  if (!generator) return Expected<SimulatedSession>::failure(generator.error());
  // Offline, as calibrate_bag: the static scene learnt over the whole recording first (its own
  // generator, so the main pass renders the very frames it renders without the pre-pass).
  PipelineOptions run_options = options;
  int prepass_frames = 0;
  if (options.image_memory.enabled && options.image_prepass.frames_per_static > 0) {
    auto prepass = ScenePrepass::create(scenario.scene.target, options.image, options.image_memory,
                                        options.image_prepass);
    if (!prepass) return Expected<SimulatedSession>::failure(prepass.error());
    auto survey = sim::FrameGenerator::create(scenario);
    if (!survey) return Expected<SimulatedSession>::failure(survey.error());
    const auto& camera = scenario.cameras.front();
    for (size_t i = 0; i < timeline->frames.size(); ++i) {
      const sim::Frame& f = timeline->frames[i];
      if (f.sensor == 0 && f.is_camera && prepass->wants(f.stamp))
        prepass->add(survey->image(f, i), camera.intrinsics, f.stamp);
    }
    run_options.image_known_scene = prepass->scene();
    prepass_frames = prepass->frames();
  }
  auto pipeline = CalibrationPipeline::create(scenario.scene.target, run_options);
  if (!pipeline) return Expected<SimulatedSession>::failure(pipeline.error());

  // stamp -> (still, pose) per sensor kind: the truth about every frame a view may use.
  std::map<double, std::pair<bool, int>> camera_truth, lidar_truth;
  std::map<double, Eigen::Isometry3d> camera_T_board_truth;
  const Eigen::Isometry3d camera_T_world = sim::worldTCamera(scenario, 0).inverse();
  const auto& camera = scenario.cameras.front();
  for (size_t i = 0; i < timeline->frames.size(); ++i) {
    const sim::Frame& f = timeline->frames[i];
    if (f.sensor != 0) continue;
    if (f.is_camera) {
      camera_truth[f.stamp] = {f.still, f.pose};
      camera_T_board_truth[f.stamp] = camera_T_world * f.world_T_board;
      pipeline->addImage(generator->image(f, i), camera.intrinsics, camera.frame_id, f.stamp);
    } else {
      lidar_truth[f.stamp] = {f.still, f.pose};
      LidarCloud cloud = generator->cloud(f, i);
      cloud.stamp = f.stamp;
      cloud.frame_id = scenario.lidars.front().frame_id;
      pipeline->addCloud(cloud);
    }
  }
  pipeline->finish();

  SimulatedSession out;
  out.prepass_frames = prepass_frames;
  out.prepass_static_rectangles = static_cast<int>(run_options.image_known_scene.rectangles.size());
  out.prepass_static_lines = static_cast<int>(run_options.image_known_scene.lines_px.size());
  out.holds = static_cast<int>(timeline->world_T_board_poses.size());
  out.images = static_cast<int>(camera_T_board_truth.size());
  scoreImages(pipeline->sightings(), camera_T_board_truth, scenario.scene.target,
              pipeline->cameraModel(), &out);
  std::set<int> captured;
  for (const auto& sv : pipeline->session().views()) {
    out.views.push_back(sv.view);
    const auto c = camera_truth.find(sv.view.camera.stamp);
    const auto l = lidar_truth.find(sv.view.lidar.stamp);
    const bool still = c != camera_truth.end() && l != lidar_truth.end() && c->second.first &&
                       l->second.first && c->second.second == l->second.second &&
                       c->second.second >= 0;
    if (still)
      captured.insert(c->second.second);
    else
      ++out.moving_captured;
  }
  out.holds_captured = static_cast<int>(captured.size());
  out.capture_summary = pipeline->session().captureStats().summary();
  out.truth = sim::groundTruth(scenario);
  out.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return out;
}

}  // namespace test_support
}  // namespace board_calib
