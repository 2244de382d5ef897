// ImageBoardTracker (issue 14, 3a) on synthetic frames with known truth: a static rectangle that
// passes every board check (a poster of the board's size and aspect, nearer and so with more edge
// support than the board) and a moving board. Alone, a frame gives the poster; the session memory
// must leave it once it has been at one place for static_after_s and return the moving board,
// must not lose a board held still for a normal hold, and must start over when time goes back.
// The offline pre-pass (ScenePrepass) must know the poster from the first frame and must not make
// a held board static more easily than the live memory does.
#include <board_calib/core/image_detection/image_board_tracker.h>
#include <board_calib/core/pipeline/scene_prepass.h>
#include <board_calib/core/transform.h>

#include <gtest/gtest.h>
#include <opencv2/imgproc.hpp>

#include <cmath>
#include <cstdio>

namespace board_calib {
namespace {

using Corners = std::array<Eigen::Vector2d, kNumEdges>;

CameraIntrinsics testIntrinsics() {
  CameraIntrinsics in;
  in.width = 1280;
  in.height = 960;
  in.fx = in.fy = 1000;
  in.cx = 639.5;
  in.cy = 479.5;
  in.model = DistortionModel::kNone;
  return in;
}

CameraModel testCamera() {
  auto camera = CameraModel::create(testIntrinsics());
  EXPECT_TRUE(camera.ok()) << camera.error();
  return *camera;
}

Target testTarget() {
  auto target =
      loadTarget(std::string(BOARD_CALIB_SOURCE_DIR) + "/config/targets/plain_890x1200.yaml");
  EXPECT_TRUE(target.ok()) << target.error();
  return *target;
}

// The board's outer corners in the image with its centre at (x, y, z) m, rolled by roll_deg.
Corners boardCorners(const CameraModel& camera, const Target& t, const Eigen::Vector3d& centre,
                     double roll_deg) {
  const Eigen::Matrix3d R =
      Eigen::AngleAxisd(roll_deg * kRadPerDeg, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  const Eigen::Isometry3d camera_T_board = makeTransform(R, centre - R * t.center());
  Corners c;
  const auto outer = t.outerCorners();
  for (int j = 0; j < kNumEdges; ++j)
    EXPECT_TRUE(camera.projectUndistorted(camera_T_board * outer[j], &c[j]));
  return c;
}

void fill(cv::Mat* image, const Corners& c, int grey) {
  constexpr int kShift = 4;  // sub-pixel polygon corners, anti-aliased edges
  std::vector<cv::Point> poly;
  for (const auto& p : c)
    poly.emplace_back(static_cast<int>(std::lround(p.x() * (1 << kShift))),
                      static_cast<int>(std::lround(p.y() * (1 << kShift))));
  cv::fillConvexPoly(*image, poly, cv::Scalar(grey), cv::LINE_AA, kShift);
}

// `image` (8-bit, any channels) with 2 grey levels of Gaussian noise per channel.
cv::Mat withNoise(const cv::Mat& image, cv::RNG& rng) {
  const int type = CV_16SC(image.channels());
  cv::Mat noise(image.size(), type);
  rng.fill(noise, cv::RNG::NORMAL, 0.0, 2.0);
  cv::Mat out;
  image.convertTo(out, type);
  out += noise;
  out.convertTo(out, image.type());
  return out;
}

// Grey background, the poster (bright) when given, the board (dark), 2 grey levels of noise.
cv::Mat render(const CameraModel& camera, const Corners* poster, const Corners& board,
               cv::RNG& rng) {
  cv::Mat image(camera.height(), camera.width(), CV_8UC1, cv::Scalar(120));
  if (poster) fill(&image, *poster, 215);
  fill(&image, board, 40);
  return withNoise(image, rng);
}

// Corners this close: the same quadrilateral (a found board's corners are within a px of the
// drawn ones; the poster and the board lie hundreds of px apart).
constexpr double kSamePx = 3.0;

double worstOffset(const Corners& a, const Corners& b) {
  double worst = 0;
  for (const auto& p : a) {
    double nearest = 1e18;
    for (const auto& q : b) nearest = std::min(nearest, (p - q).norm());
    worst = std::max(worst, nearest);
  }
  return worst;
}

// Board poses of a session: each held 1.5 s (the simulator's hold), then the next one.
const std::vector<std::pair<Eigen::Vector3d, double>> kBoardPoses = {
    {{1.2, 0.3, 7.0}, 45},  {{0.9, -0.4, 8.0}, 35}, {{1.5, 0.1, 6.5}, 55},  {{0.7, 0.5, 7.5}, 40},
    {{1.3, -0.2, 9.0}, 50}, {{1.0, 0.2, 6.0}, 30},  {{1.6, -0.5, 8.5}, 60}, {{0.8, 0.0, 7.0}, 45}};

// What of `scene` is the quadrilateral `c`: static rectangles at its place and static lines on
// its sides (both ends within kSamePx of a side's line).
int staticParts(const StaticScene& scene, const Corners& c) {
  int n = 0;
  for (const auto& r : scene.rectangles) n += worstOffset(r.corners_px, c) < kSamePx;
  for (const auto& l : scene.lines_px)
    for (int j = 0; j < kNumEdges; ++j) {
      const Eigen::Vector2d a = c[j], d = (c[(j + 1) % kNumEdges] - a).normalized();
      const auto off = [&](const Eigen::Vector2d& p) {
        return std::abs(d.x() * (p - a).y() - d.y() * (p - a).x());
      };
      if (off(l[0]) < kSamePx && off(l[1]) < kSamePx) {
        ++n;
        break;
      }
    }
  return n;
}

constexpr double kFrameS = 0.5;  // 2 Hz
constexpr double kHoldS = 2.5;   // 1.5 s hold + 1 s move, as the simulator's sessions

// The board's pose at t: held at the first pose for `first_hold_s`, then through the next ones
// for kHoldS each.
const std::pair<Eigen::Vector3d, double>& poseAt(double t, double first_hold_s) {
  if (t < first_hold_s) return kBoardPoses[0];
  return kBoardPoses[std::min(kBoardPoses.size() - 1,
                              1 + static_cast<size_t>((t - first_hold_s) / kHoldS))];
}

struct PrepassRun {
  int frames = 0, board = 0, poster = 0;  // main pass: frames, the board found, the poster found
  int held_static = 0;                    // static rectangles and lines of the held board
};

// A session with the poster: the board held `first_hold_s` at its first pose, then moved through
// the others, `session_s` long. With `prepass`, the static scene is learnt over the whole session
// first and the held board's static parts are counted at its end; live, the most at any frame.
PrepassRun runSession(double first_hold_s, double session_s, bool prepass) {
  const CameraModel camera = testCamera();
  const Target target = testTarget();
  auto tracker = ImageBoardTracker::create(target, {});
  EXPECT_TRUE(tracker.ok());
  const Corners poster = boardCorners(camera, target, {-1.2, 0.0, 3.5}, 0.0);
  const Corners held = boardCorners(camera, target, kBoardPoses[0].first, kBoardPoses[0].second);
  const auto boardAt = [&](double t) {
    const auto& pose = poseAt(t, first_hold_s);
    return boardCorners(camera, target, pose.first, pose.second);
  };
  PrepassRun out;
  if (prepass) {
    auto survey = ScenePrepass::create(target, {}, {});
    EXPECT_TRUE(survey.ok());
    cv::RNG rng(11);  // every frame rendered, as a recording holds them; the pre-pass picks
    for (double t = 0.0; t < session_s; t += kFrameS) {
      const cv::Mat image = render(camera, &poster, boardAt(t), rng);
      if (survey->wants(t)) {
        EXPECT_TRUE(survey->add(image, testIntrinsics(), t));
      }
    }
    tracker->setKnownScene(survey->scene());
    out.held_static = staticParts(survey->scene(), held);
  }
  cv::RNG rng(11);
  for (double t = 0.0; t < session_s; t += kFrameS) {
    const Corners board = boardAt(t);
    const ImageDetection d = tracker->detect(render(camera, &poster, board, rng), camera, t);
    ++out.frames;
    out.board += d.features.found && worstOffset(d.features.corners_px, board) < kSamePx;
    out.poster += d.features.found && worstOffset(d.features.corners_px, poster) < kSamePx;
    if (!prepass)
      out.held_static = std::max(out.held_static, staticParts(tracker->staticScene(), held));
  }
  std::printf(
      "[prepass] held %.1f s of %.1f s, %s: board %d/%d, poster %d, held board static "
      "(rectangles + sides) %d\n",
      first_hold_s, session_s, prepass ? "pre-pass" : "live", out.board, out.frames, out.poster,
      out.held_static);
  return out;
}

}  // namespace

TEST(ScenePrepass, PosterIsKnownFromTheFirstFrame) {
  // Normal holds only: the poster is static over the session, the board's places are not.
  const double session_s = kHoldS * kBoardPoses.size();
  const PrepassRun live = runSession(kHoldS, session_s, false);
  const PrepassRun pre = runSession(kHoldS, session_s, true);
  EXPECT_GT(live.poster, 0);  // live, the first 6 s meet the poster alone
  EXPECT_EQ(pre.poster, 0);
  EXPECT_EQ(pre.board, pre.frames);
  EXPECT_EQ(pre.held_static, 0);
}

TEST(ScenePrepass, HeldBoardIsNotStaticMoreEasilyThanLive) {
  // Held still for less than half of the session, but long enough for the live memory to see it
  // over static_after_s once the poster is static (from 6 s on): live makes it static, the
  // pre-pass (seen in half of its frames since the first sighting, to the recording's end) does
  // not.
  const double short_hold_s = 2.0 * StaticMemoryOptions().static_after_s + 2.0 * kFrameS;
  const double session_s = short_hold_s + kHoldS * (kBoardPoses.size() - 1);
  const PrepassRun live_short = runSession(short_hold_s, session_s, false);
  const PrepassRun pre_short = runSession(short_hold_s, session_s, true);
  EXPECT_GT(live_short.held_static, 0);
  EXPECT_EQ(pre_short.held_static, 0);
  EXPECT_GE(pre_short.board, live_short.board);
  EXPECT_EQ(pre_short.poster, 0);
  // Held for most of the session: static both ways (the same rule), never more parts than live.
  const double long_s = 16.0 + kHoldS * 3;
  const PrepassRun live_long = runSession(16.0, long_s, false);
  const PrepassRun pre_long = runSession(16.0, long_s, true);
  EXPECT_LE(pre_long.held_static, live_long.held_static);
  EXPECT_EQ(pre_long.poster, 0);
}

TEST(ImageBoardTracker, StaticRectangleIsLeftForTheMovingBoard) {
  const CameraModel camera = testCamera();
  const Target target = testTarget();
  auto alone = ImageBoardDetector::create(target, {});
  auto tracker = ImageBoardTracker::create(target, {});
  ASSERT_TRUE(alone.ok() && tracker.ok());
  const Corners poster = boardCorners(camera, target, {-1.2, 0.0, 3.5}, 0.0);
  cv::RNG rng(7);
  const double static_after_s = tracker->memory().static_after_s;
  int alone_poster = 0, late_frames = 0, late_board = 0, late_poster = 0;
  for (double t = 0.0; t < kHoldS * kBoardPoses.size(); t += kFrameS) {
    const auto& pose = kBoardPoses[static_cast<size_t>(t / kHoldS)];
    const Corners board = boardCorners(camera, target, pose.first, pose.second);
    const cv::Mat image = render(camera, &poster, board, rng);
    const ImageDetection a = alone->detect(image, camera);
    alone_poster += a.features.found && worstOffset(a.features.corners_px, poster) < kSamePx;
    const ImageDetection d = tracker->detect(image, camera, t);
    const bool is_board = d.features.found && worstOffset(d.features.corners_px, board) < kSamePx;
    const bool is_poster = d.features.found && worstOffset(d.features.corners_px, poster) < kSamePx;
    std::printf("[tracker] t %4.1f: %s (%d static places, %d static lines)\n", t,
                is_board    ? "board"
                : is_poster ? "POSTER"
                            : d.features.reason.c_str(),
                tracker->numStaticPlaces(), tracker->numStaticLines());
    // The poster is static once seen over static_after_s; the frame that makes it so is searched
    // again without it.
    if (t < static_after_s) continue;
    ++late_frames;
    late_board += is_board;
    late_poster += is_poster;
  }
  std::printf("[tracker] alone: poster in %d frames; after %.0f s: board %d/%d, poster %d\n",
              alone_poster, static_after_s, late_board, late_frames, late_poster);
  EXPECT_GT(alone_poster, 0);  // the scene is the hard case: alone the poster wins
  EXPECT_EQ(late_poster, 0);   // never returned once static
  EXPECT_EQ(late_board, late_frames);
}

TEST(ImageBoardTracker, BoardHeldStillForANormalHoldIsKept) {
  const CameraModel camera = testCamera();
  const Target target = testTarget();
  auto tracker = ImageBoardTracker::create(target, {});
  ASSERT_TRUE(tracker.ok());
  cv::RNG rng(8);
  // Held for twice the simulator's hold (1.5 s) at 10 Hz, then moved and held again.
  constexpr double kStillS = 3.0, kFastFrameS = 0.1;
  int frames = 0, found = 0;
  for (int hold = 0; hold < 3; ++hold) {
    const auto& pose = kBoardPoses[static_cast<size_t>(hold)];
    const Corners board = boardCorners(camera, target, pose.first, pose.second);
    for (double s = 0.0; s < kStillS; s += kFastFrameS) {
      const ImageDetection d =
          tracker->detect(render(camera, nullptr, board, rng), camera, hold * kStillS + s);
      ++frames;
      found += d.features.found && worstOffset(d.features.corners_px, board) < kSamePx;
    }
  }
  std::printf("[tracker] held still 3 x %.0f s: board in %d/%d frames\n", kStillS, found, frames);
  EXPECT_EQ(found, frames);
  EXPECT_EQ(tracker->numStaticPlaces(), 0);
}

TEST(ImageBoardTracker, TimeGoingBackForgetsTheStaticScene) {
  const CameraModel camera = testCamera();
  const Target target = testTarget();
  auto tracker = ImageBoardTracker::create(target, {});
  ASSERT_TRUE(tracker.ok());
  const Corners poster = boardCorners(camera, target, {-1.2, 0.0, 3.5}, 0.0);
  const Corners board = boardCorners(camera, target, kBoardPoses[0].first, kBoardPoses[0].second);
  cv::RNG rng(9);
  for (double t = 0.0; t <= 10.0; t += 1.0)
    tracker->detect(render(camera, &poster, board, rng), camera, 100.0 + t);
  EXPECT_GT(tracker->numStaticPlaces(), 0);
  tracker->detect(render(camera, &poster, board, rng), camera, 0.0);  // a replay started over
  EXPECT_EQ(tracker->numStaticPlaces(), 0);
  EXPECT_GT(tracker->numPlaces(), 0);  // the replay's first frame is remembered anew
}

// The session's background: per pixel the median of frames spread over the session. A board of
// the background's grey but another colour, moved from hold to hold, is not in it; it is used only
// once its frames span static_after_s; bad stamps and a camera that changes size leave it sane.
TEST(ImageBoardTracker, BackgroundIsTheSceneNotTheMovingBoard) {
  const CameraModel camera = testCamera();
  const Target target = testTarget();
  auto tracker = ImageBoardTracker::create(target, {});
  ASSERT_TRUE(tracker.ok());
  cv::RNG rng(11);
  const cv::Scalar scene(110, 120, 130), board_colour(60, 125, 175);  // bgr: orange-ish, one grey
  auto frame = [&](const Corners& board) {
    cv::Mat image(camera.height(), camera.width(), CV_8UC3, scene);
    std::vector<cv::Point> poly;
    for (const auto& p : board) poly.emplace_back(static_cast<int>(p.x()), static_cast<int>(p.y()));
    cv::fillConvexPoly(image, poly, board_colour);
    return withNoise(image, rng);
  };
  // Holds over the whole image (no two boards overlap, 7 m away).
  std::vector<Eigen::Vector3d> holds;
  for (double y : {-1.0, 1.0})
    for (double x : {-2.4, -0.8, 0.8, 2.4}) holds.emplace_back(x, y, 7.0);
  double t = 100.0;
  for (size_t k = 0; k < holds.size(); ++k, t += 1.5) {
    tracker->detect(frame(boardCorners(camera, target, holds[k], 30.0)), camera, t);
    // Frames 1.5 s apart span static_after_s (6 s) from the fifth on.
    EXPECT_EQ(tracker->staticScene().background.empty(), k < 4) << "frame " << k;
  }
  const cv::Mat background = tracker->staticScene().background;
  ASSERT_FALSE(background.empty());
  EXPECT_EQ(background.cols, ImageBoardDetectorOptions{}.segmentation_width_px);
  // Where every board was, the background is the scene (the median's noise is well under 3).
  const double scale = static_cast<double>(background.cols) / camera.width();
  for (const auto& centre : holds) {
    Eigen::Vector2d px;
    ASSERT_TRUE(camera.projectUndistorted(centre, &px));
    const cv::Vec3b v = background.at<cv::Vec3b>(static_cast<int>(px.y() * scale),
                                                 static_cast<int>(px.x() * scale));
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(v[c], scene[c], 3.0) << "at " << px.transpose();
  }
  // A NaN stamp and a camera of another size: no crash, the background is not corrupted.
  tracker->detect(frame(boardCorners(camera, target, holds[0], 0.0)), camera, std::nan(""));
  EXPECT_EQ(tracker->staticScene().background.size(), background.size());
  CameraIntrinsics small = testIntrinsics();
  small.width = 640;
  small.height = 480;
  small.cx = 319.5;
  small.cy = 239.5;
  const auto small_camera = CameraModel::create(small);
  ASSERT_TRUE(small_camera.ok());
  tracker->detect(cv::Mat(480, 640, CV_8UC3, scene), *small_camera, t + 1.5);
  EXPECT_TRUE(tracker->staticScene().background.empty());  // another camera: starts over
  // Time going back (a replay) starts the background over too, and it is built again.
  for (int k = 0; k < 6; ++k)
    tracker->detect(frame(boardCorners(camera, target, holds[k], 30.0)), camera, 10.0 + 1.5 * k);
  EXPECT_FALSE(tracker->staticScene().background.empty());
}

TEST(ImageBoardTracker, InvalidMemoryOptionsAreRefused) {
  StaticMemoryOptions memory;
  memory.static_after_s = 0.0;
  const auto tracker = ImageBoardTracker::create(testTarget(), {}, memory);
  ASSERT_FALSE(tracker.ok());
  EXPECT_NE(tracker.error().find("static_after_s"), std::string::npos);
}

}  // namespace board_calib
