// Sessions of augmented REAL frames (issues 10 and 14): the single-frame plain-board detector
// still takes a wrong board on some augmentation draws it was never tuned on (a far side on a
// hand or a leg, a 4:3 board named a quarter turn round, a scene rectangle under wood grain:
// docs/BENCHMARKS.md, session 37). A calibration must not turn such a frame into a wrong answer
// reported as good: the session's view-consistency check (camera plane against LiDAR plane) and
// the verdict are the guard. Each draw's frames of one camera form a session; the LiDAR side is
// simulated (an OS1-64 at a known extrinsic ray-cast against the board where the frame's reference
// lines put it, then the real LiDAR detector), so the reference lines are the ground truth of both
// sensors.
#include "augmented_frames.h"

#include <board_calib/core/image_detection/image_board_detector.h>
#include <board_calib/core/lidar_detection/lidar_board_detector.h>
#include <board_calib/core/pipeline/pair_calibration.h>
#include <board_calib/core/sim/simulator.h>
#include <board_calib/core/transform.h>

#include <gtest/gtest.h>
#include <opencv2/calib3d.hpp>
#include <opencv2/core/eigen.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <random>
#include <string>
#include <vector>

namespace board_calib {
namespace {

using augmented::Frame;

// The camera in the simulated world (x forward, z up): its optical axis along world x.
Eigen::Isometry3d worldTCamera() {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() << 0, 0, 1, -1, 0, 0, 0, -1, 0;
  return T;
}

// The true extrinsic: the LiDAR 12 cm above and 6 cm beside the camera, turned a little.
Eigen::Isometry3d trueCameraTLidar() {
  Eigen::Isometry3d world_T_lidar = Eigen::Isometry3d::Identity();
  world_T_lidar.linear() = (Eigen::AngleAxisd(0.03, Eigen::Vector3d::UnitZ()) *
                            Eigen::AngleAxisd(-0.02, Eigen::Vector3d::UnitY()))
                               .toRotationMatrix();
  world_T_lidar.translation() = Eigen::Vector3d(0.02, 0.06, 0.12);
  return worldTCamera().inverse() * world_T_lidar;
}

// Distances (px) of each reference segment's two ends from the board edge the pose projects.
Eigen::Matrix<double, 8, 1> edgeResiduals(const Frame& f, const Eigen::Matrix3d& K,
                                          const Eigen::Isometry3d& camera_T_board) {
  const auto outer = f.target.outerCorners();
  Eigen::Matrix<double, 8, 1> r;
  for (int j = 0; j < kNumEdges; ++j) {
    // Edge j runs from corner j - 1 to corner j.
    const Eigen::Vector3d a = K * (camera_T_board * outer[(j + 3) % 4]),
                          b = K * (camera_T_board * outer[j]);
    Eigen::Vector3d line = a.cross(b);
    line /= line.head<2>().norm();
    for (int e = 0; e < 2; ++e) r(2 * j + e) = line.dot(f.segments[j][e].homogeneous());
  }
  return r;
}

// The board pose whose projected edges pass through the frame's reference segments (the visible
// parts of its sides), started from the PnP of the reference corners; false when they do not fit
// the declared board (more than 2.5 px rms: the recorded frames' lines fit it to 0.30-0.71 px on
// rs16_plain, 0.56-2.47 px on basler_os1_plain). Not the corners alone: on the close basler frames
// they lie far outside the image, where the lines' intersections carry the lens model's
// extrapolation (up to 21 px rms against the declared square).
bool referencePose(const Frame& f, Eigen::Isometry3d* camera_T_board) {
  std::vector<cv::Point3d> object;
  std::vector<cv::Point2d> image;
  const auto outer = f.target.outerCorners();
  for (int j = 0; j < kNumEdges; ++j) {
    object.emplace_back(outer[j].x(), outer[j].y(), outer[j].z());
    image.emplace_back(f.corners[j].x(), f.corners[j].y());
  }
  const Eigen::Matrix3d K = f.camera().K();
  cv::Mat k_cv, rvec, tvec;
  cv::eigen2cv(K, k_cv);
  if (!cv::solvePnP(object, image, k_cv, cv::noArray(), rvec, tvec, false, cv::SOLVEPNP_IPPE))
    return false;
  Eigen::Vector3d r, t;
  cv::cv2eigen(rvec, r);
  cv::cv2eigen(tvec, t);
  Eigen::Isometry3d T = makeTransform(expSO3(r), t);
  // Gauss-Newton on a left-multiplied update (rotation vector, translation), numeric Jacobian.
  auto moved = [&](const Eigen::Matrix<double, 6, 1>& d) {
    return makeTransform(expSO3(d.head<3>()), d.tail<3>()) * T;
  };
  for (int iteration = 0; iteration < 20; ++iteration) {
    const Eigen::Matrix<double, 8, 1> r0 = edgeResiduals(f, K, T);
    Eigen::Matrix<double, 8, 6> J;
    for (int k = 0; k < 6; ++k) {
      Eigen::Matrix<double, 6, 1> d = Eigen::Matrix<double, 6, 1>::Zero();
      d(k) = 1e-6;
      J.col(k) = (edgeResiduals(f, K, moved(d)) - r0) / 1e-6;
    }
    const Eigen::Matrix<double, 6, 1> step =
        -(J.transpose() * J + 1e-9 * Eigen::Matrix<double, 6, 6>::Identity())
             .ldlt()
             .solve(J.transpose() * r0);
    T = moved(step);
    if (step.norm() < 1e-10) break;
  }
  *camera_T_board = T;
  return edgeResiduals(f, K, T).norm() / std::sqrt(8.0) < 2.5;
}

// The simulated LiDAR's board features for a board at camera_T_board.
LidarBoardFeatures lidarView(const Target& target, const Eigen::Isometry3d& camera_T_board,
                             std::mt19937& rng) {
  const auto spec = sim::lidarPreset("OS1-64");
  sim::SceneSpec scene;
  scene.target = target;
  scene.room_half_size_m = 40;  // far boards stay inside the room
  scene.floor_z_m = -3.0;       // below every reference board
  scene.ceiling_z_m = 6.0;
  const Eigen::Isometry3d world_T_lidar = worldTCamera() * trueCameraTLidar();
  const LidarCloud cloud =
      sim::simulateLidarScan(*spec, world_T_lidar, scene, worldTCamera() * camera_T_board, rng);
  return detectLidarBoard(cloud, target).features;
}

// Largest distance of the frame's reference segments from the found lines (1000: a line of
// another orientation, i.e. another object or a board named round).
double worstEdgePx(const Frame& f, const CameraBoardFeatures& fe) {
  double worst = 0;
  for (int j = 0; j < kNumEdges; ++j) worst = std::max(worst, augmented::edgeErrorPx(f, fe, j));
  return worst;
}

struct Session {
  std::vector<View> views;
  std::vector<double> worst_px;  // per view
  int frames = 0;
};

// One draw's frames, as the augmented table draws them (every frame is augmented, so the draw is
// the table's), split into a basler and an rs16 session; basler frames are detected only when
// asked.
std::array<Session, 2> drawSessions(unsigned seed, bool with_basler) {
  const std::vector<Frame>& frames = augmented::recordedFrames();
  std::mt19937 rng(seed);
  std::array<Session, 2> sessions;
  const auto& cases = augmented::augmentedCases();
  for (size_t k = 0; k < cases.size(); ++k)
    for (size_t i = 0; i < frames.size(); ++i) {
      const Frame f = augmented::augment(frames[i], cases[k], static_cast<int>(i), rng);
      const bool basler = f.name.rfind("basler", 0) == 0;
      if (basler && !with_basler) continue;
      Session& s = sessions[basler ? 0 : 1];
      ++s.frames;
      auto det = ImageBoardDetector::create(f.target, ImageBoardDetectorOptions{});
      if (!det.ok()) {
        ADD_FAILURE() << det.error();
        continue;
      }
      const CameraBoardFeatures camera = det->detect(f.image, f.camera()).features;
      Eigen::Isometry3d camera_T_board;
      if (!camera.found) continue;
      if (!referencePose(f, &camera_T_board)) {
        ADD_FAILURE() << f.name << " " << cases[k].name << ": the reference lines do not fit";
        continue;
      }
      View v;
      v.id = static_cast<int>(s.views.size());
      v.camera = camera;
      v.camera.frame_id = "camera";
      v.camera.stamp = v.id;
      // Each frame's scan draws its own noise: a view found or lost elsewhere (a detector
      // change) leaves the other views' clouds as they were.
      std::mt19937 lidar_rng(seed * 100003u + static_cast<unsigned>(k * frames.size() + i));
      v.lidar = lidarView(f.target, camera_T_board, lidar_rng);
      v.lidar.stamp = v.id;
      s.views.push_back(v);
      s.worst_px.push_back(camera.allEdgesValid() ? worstEdgePx(f, camera) : 0.0);
    }
  return sessions;
}

// The draws whose single frames took wrong boards (session 37), all in rs16_plain frames: a far
// side 5.28 px (19) and 9.44 px (22; no longer found since session 40) off, a 4:3 board named a
// quarter turn round (21), a scene rectangle under wood grain (23). Each wrong board must be left
// out by the consistency check, the check must keep the right boards (at least 80 % of those the
// LiDAR found too), and a result judged good must be right: within 3 of its own sigmas and within
// 0.3 deg and 20 mm (a "good" verdict's 1 sigma limits) of the truth. A side over 5 px off is a
// wrong board (right ones measured up to 3.59 px,
// ImageDetectorAugmented.OtherDrawsGiveNoWrongBoard); smaller misfits only weigh in the solve. The
// verdicts themselves are reported, not asserted: 5 board poses, 3 of them nearly the same, moved
// about the camera centre for the far cases, may not determine a calibration, and saying so is
// right. Development aid: BOARD_CALIB_AUG_SESSION_BASLER=1 adds the basler_os1_plain sessions (192
// frames per draw, twice the time; docs/BENCHMARKS.md has their figures).
TEST(AugmentedSessions, WrongBoardsAreLeftOutAndNoWrongResultIsGood) {
  if (!std::filesystem::exists(BOARD_CALIB_SHARED_DIR)) GTEST_SKIP() << "../shared absent";
  const auto methods = parseMethods("all");
  ASSERT_TRUE(methods.ok());
  const bool with_basler = std::getenv("BOARD_CALIB_AUG_SESSION_BASLER") != nullptr;
  const Eigen::Isometry3d truth = trueCameraTLidar();
  int wrong_total = 0;
  for (const unsigned seed : {19u, 21u, 22u, 23u, 41u}) {
    const auto sessions = drawSessions(seed, with_basler);
    for (int c = with_basler ? 0 : 1; c < 2; ++c) {
      const Session& s = sessions[c];
      const std::string name =
          std::string(c == 0 ? "basler" : "rs16") + " draw " + std::to_string(seed);
      ASSERT_GE(s.views.size(), 10u) << name;
      const Target& target = augmented::recordedFrames()[c == 0 ? 0 : 16].target;
      const PairCalibration cal = calibratePair(s.views, *methods, target, "camera", "lidar");
      int usable = 0, wrong = 0, wrong_kept = 0, right = 0, right_kept = 0;
      for (size_t i = 0; i < s.views.size(); ++i) {
        const ViewConsistency& vc = cal.consistency.views[i];
        usable += vc.usable;
        const bool board_wrong = s.worst_px[i] > 5.0;
        if (vc.usable && !board_wrong) {
          ++right;
          right_kept += vc.consistent;
        }
        if (s.worst_px[i] <= 2.0) continue;
        wrong += board_wrong;
        wrong_kept += board_wrong && vc.consistent;
        std::printf("  %s view %zu: worst edge %.2f px, %s (normal %.2f deg, offset %.1f cm)\n",
                    name.c_str(), i, s.worst_px[i],
                    !vc.usable      ? "no LiDAR board"
                    : vc.consistent ? "consistent"
                                    : "left out",
                    vc.normal_residual_deg, vc.offset_residual_m * 100);
        if (board_wrong) {
          EXPECT_FALSE(vc.consistent) << name << " view " << i;
        }
      }
      wrong_total += wrong;
      const MethodRun& run = cal.shownRun();
      const Eigen::Isometry3d& got = run.solution.camera_T_lidar;
      const double rot = rotationErrorDeg(got, truth), trans = translationErrorM(got, truth);
      const double sigma_rot = run.verdict.stddev.rotation_deg.norm(),
                   sigma_trans = run.verdict.stddev.translation_m.norm();
      std::printf(
          "%s: %d frames, %zu found, %d with a LiDAR board; right boards kept %d/%d, wrong boards "
          "kept %d/%d; %s %s, error %.3f deg %.1f mm (1 sigma %.3f deg %.1f mm): %s\n",
          name.c_str(), s.frames, s.views.size(), usable, right_kept, right, wrong_kept, wrong,
          verdictName(cal.verdict), cal.chosen >= 0 ? methodName(run.solution.method) : "none", rot,
          trans * 1e3, sigma_rot, sigma_trans * 1e3, cal.reason.c_str());
      // Every method's own verdict, as the side-by-side table shows it (the chosen run's is the
      // session's): none may be good and wrong.
      for (const MethodRun& r : cal.runs) {
        const Eigen::Isometry3d& m = r.solution.camera_T_lidar;
        const double r_rot = rotationErrorDeg(m, truth), r_trans = translationErrorM(m, truth);
        const double r_sigma_rot = r.verdict.stddev.rotation_deg.norm(),
                     r_sigma_trans = r.verdict.stddev.translation_m.norm();
        std::printf("    %s: %s, error %.3f deg %.1f mm (1 sigma %.3f deg %.1f mm)\n",
                    methodName(r.solution.method), verdictName(r.verdict.verdict), r_rot,
                    r_trans * 1e3, r_sigma_rot, r_sigma_trans * 1e3);
        if (c == 0 || r.verdict.verdict != Verdict::kGood) continue;
        EXPECT_LT(r_rot, std::min(0.3, 3 * r_sigma_rot))
            << name << " " << methodName(r.solution.method);
        EXPECT_LT(r_trans, std::min(0.02, 3 * r_sigma_trans))
            << name << " " << methodName(r.solution.method);
      }
      if (c == 0) continue;  // basler: reported only
      EXPECT_GE(right_kept, 0.8 * right) << name;
    }
  }
  // Draws 21 and 41 hold one wrong board each (a board named a quarter turn round; a far board
  // with one side on the background beside it, found since session 46 ranks the far lines by
  // their corners). Draw 19's is no longer taken since session 46, draw 23's (a scene rectangle
  // crossing the board) since session 43 (ASceneRectangleCrossingTheBoardLosesToIt).
  EXPECT_GE(wrong_total, 2) << "the draws no longer hold the wrong boards this test is about";
}

}  // namespace
}  // namespace board_calib
