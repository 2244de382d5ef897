// Deterministic fuzzer of the two board detectors on whole frames: simulated scenes with random
// cameras (focal lengths, principal points, every distortion model), boards of every type at
// random poses, clutter, then hostile edits of the pixels or the returns (saturated and dead
// blocks, stripes, inverted parts, NaN / infinite / huge / duplicated points, wrong ring
// indices, shuffled or truncated scans). Every call must return: a board found must pass
// malformedFeatures (finite, consistent), a miss must carry a reason. Driven: the single frame,
// the second chance near a random prior, the trackers, the detectors as the nodelets build them
// from any dynamic_reconfigure setting, the projection path and the session memories (image
// pre-pass, LiDAR background); and whole calibrations of hostile view sets, whose "good" must
// be right. A crash, an exception or a sanitizer report
// (scripts/test.sh --sanitize) fails the suite.
// BOARD_CALIB_FUZZ_ROUND=N draws other frames; BOARD_CALIB_FUZZ_VERBOSE prints each call's outcome
// (the frame a crash stopped at is the last one printed); BOARD_CALIB_DEBUG_DIR gets the view
// sets' debug images.
#include <board_calib/core/features.h>
#include <board_calib/core/image_detection/image_board_detector.h>
#include <board_calib/core/image_detection/image_board_tracker.h>
#include <board_calib/core/lidar_detection/lidar_board_detector.h>
#include <board_calib/core/pipeline/pair_calibration.h>
#include <board_calib/core/projection/projection.h>
#include <board_calib/core/sim/simulator.h>
#include <board_calib/core/target.h>
#include <board_calib/core/transform.h>
#include "cloud_detector_options.h"
#include "fuzz_text.h"
#include "image_detector_options.h"

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <random>
#include <string>
#include <type_traits>
#include <vector>

using namespace board_calib;

namespace {

// Frames per detector: enough for every edit to meet every board type and distortion model
// several times; the binary stays under a minute in Release (a few under ASan).
constexpr int kImageFrames = 90;
constexpr int kCloudFrames = 120;
// Settings of each detector's dynamic_reconfigure parameters drawn, one frame each.
constexpr int kSettingsDrawn = 40;
// Scans projected into a random camera.
constexpr int kProjectionFrames = 60;
// Recordings of one scene (a camera and a LiDAR) for the session memories, and their frames.
constexpr int kRecordings = 6;
constexpr int kRecordingFrames = 6;
// Simulated rigs and board poses for the hostile view sets.
constexpr int kRigs = 4;
constexpr int kRigPoses = 14;

double uniform(std::mt19937& rng, double lo, double hi) {
  return std::uniform_real_distribution<double>(lo, hi)(rng);
}
int uniformInt(std::mt19937& rng, int lo, int hi) {
  return std::uniform_int_distribution<int>(lo, hi)(rng);
}
bool chance(std::mt19937& rng, double p) { return uniform(rng, 0, 1) < p; }
// Components drawn in order (an argument list's order of evaluation is unspecified).
Eigen::Vector3d uniform3(std::mt19937& rng, const Eigen::Vector3d& lo, const Eigen::Vector3d& hi) {
  Eigen::Vector3d v;
  for (int k = 0; k < 3; ++k) v[k] = uniform(rng, lo[k], hi[k]);
  return v;
}

Target targetOf(int kind) {
  const char* yaml[] = {
      "type: plain\nwidth: 0.8\nheight: 0.6\n", "type: plain\nwidth: 1.016\nheight: 1.016\n",
      "type: checkerboard\nwidth: 1.016\nheight: 1.016\n"
      "checkerboard: {cols: 7, rows: 5, square: 0.10, origin: [0.208, 0.308]}\n",
      "type: apriltag_grid\nwidth: 1.016\nheight: 1.016\n"
      "apriltag_grid: {family: tag36h11, cols: 4, rows: 4, tag_size: 0.16, spacing: 0.04, "
      "first_id: 0, origin: [0.1, 0.1]}\n"};
  auto target = parseTarget(yaml[kind]);
  EXPECT_TRUE(target.ok()) << target.error();
  return *target;
}

// A camera of any kind a driver may announce: odd sizes, focal lengths from fisheye-wide to
// telephoto, principal points off centre (even outside the image) and strong distortion.
// Intrinsics the camera model refuses are drawn again (their refusal is the conversions' test).
CameraModel randomCamera(std::mt19937& rng) {
  for (;;) {
    CameraIntrinsics in;
    const bool tiny = chance(rng, 0.12);
    in.width = tiny ? uniformInt(rng, 1, 48) : uniformInt(rng, 120, 900);
    in.height = tiny ? uniformInt(rng, 1, 48) : uniformInt(rng, 90, 700);
    const double side = std::max(in.width, in.height);
    in.fx = side * std::exp(uniform(rng, std::log(0.15), std::log(8.0)));
    in.fy = in.fx * uniform(rng, 0.7, 1.4);
    for (double* c : {&in.cx, &in.cy}) {
      const double lo = chance(rng, 0.15) ? -0.5 : 0.3;
      const double hi = chance(rng, 0.15) ? 1.5 : 0.7;
      *c = (c == &in.cx ? in.width : in.height) * uniform(rng, lo, hi);
    }
    switch (uniformInt(rng, 0, 3)) {
      case 0: break;
      case 1:
        in.model = DistortionModel::kPlumbBob;
        in.coeffs = {uniform(rng, -0.5, 0.3), uniform(rng, -0.2, 0.2), uniform(rng, -0.01, 0.01),
                     uniform(rng, -0.01, 0.01), uniform(rng, -0.05, 0.05)};
        break;
      case 2:
        in.model = DistortionModel::kRationalPolynomial;
        in.coeffs = {uniform(rng, -0.5, 0.5),   uniform(rng, -0.2, 0.2),
                     uniform(rng, -0.01, 0.01), uniform(rng, -0.01, 0.01),
                     uniform(rng, -0.05, 0.05), uniform(rng, -0.3, 0.3),
                     uniform(rng, -0.1, 0.1),   uniform(rng, -0.05, 0.05)};
        break;
      default:
        in.model = DistortionModel::kEquidistant;
        in.coeffs = {uniform(rng, -0.2, 0.2), uniform(rng, -0.1, 0.1), uniform(rng, -0.05, 0.05),
                     uniform(rng, -0.02, 0.02)};
        break;
    }
    auto camera = CameraModel::create(in);
    if (camera.ok()) return *camera;
  }
}

// Camera optical frame in a world with z up, looking along world +x.
Eigen::Isometry3d worldTCamera() {
  Eigen::Matrix3d R;
  R << 0, 0, 1, -1, 0, 0, 0, -1, 0;
  return makeTransform(R, Eigen::Vector3d(0, 0, 0.2));
}

// Mostly a board the camera can see (over 15-50 % of the image width, tilted up to 40 deg about
// each axis), so the fitting stages run; otherwise anywhere from touching the lens to far away, at
// any tilt and roll, half out of view or behind the camera.
Eigen::Isometry3d randomCameraTBoard(std::mt19937& rng, const CameraModel& camera,
                                     const Target& t) {
  const bool seen = chance(rng, 0.7);
  const double size = std::max(t.width, t.height);
  const double distance =
      seen ? size * camera.intrinsics().fx / (uniform(rng, 0.15, 0.5) * camera.width())
           : std::exp(uniform(rng, std::log(0.2), std::log(40.0)));
  // Where its centre lands, as a share of the image size from the image centre.
  const double spread = seen ? 0.12 : 1.0;
  const Eigen::Vector3d at = uniform3(rng, {-spread, -spread, 0}, {spread, spread, 0});
  const CameraIntrinsics& in = camera.intrinsics();
  Eigen::Vector3d centre(((0.5 + at.x()) * in.width - in.cx) / in.fx * distance,
                         ((0.5 + at.y()) * in.height - in.cy) / in.fy * distance, distance);
  if (!seen && chance(rng, 0.1)) centre.z() = -distance;  // behind the camera
  const double tilt = seen ? 0.5 : 1.5;
  Eigen::Matrix3d R;
  R = Eigen::AngleAxisd(uniform(rng, -tilt, tilt), Eigen::Vector3d::UnitY()) *
      Eigen::AngleAxisd(uniform(rng, -tilt, tilt), Eigen::Vector3d::UnitX()) *
      Eigen::AngleAxisd(uniform(rng, -M_PI, M_PI), Eigen::Vector3d::UnitZ());
  return makeTransform(R, centre - R * t.center());
}

sim::SceneSpec randomScene(std::mt19937& rng, const Target& target) {
  sim::SceneSpec scene;
  scene.target = target;
  scene.outdoor = chance(rng, 0.3);
  scene.room = !scene.outdoor && chance(rng, 0.8);
  scene.occluder = chance(rng, 0.6);
  scene.board_grey = uniform(rng, 0.05, 0.95);
  for (int c = 0; c < 3; ++c) scene.board_tint[c] = uniform(rng, 0.5, 1);
  scene.board_texture = chance(rng, 0.3) ? uniform(rng, 0, 0.5) : 0.0;
  scene.ground_grey = uniform(rng, 0.05, 0.95);
  const int marks = chance(rng, 0.3) ? uniformInt(rng, 1, 6) : 0;
  for (int k = 0; k < marks; ++k) {
    sim::BoardMark m;
    m.min.x() = uniform(rng, 0, target.width);
    m.min.y() = uniform(rng, 0, target.height);
    m.max.x() = m.min.x() + uniform(rng, 0.01, 0.4);
    m.max.y() = m.min.y() + uniform(rng, 0.01, 0.3);
    m.max = m.max.cwiseMin(Eigen::Vector2d(target.width, target.height));
    scene.board_marks.push_back(m);
  }
  const int panels = chance(rng, 0.5) ? uniformInt(rng, 1, 5) : 0;
  for (int k = 0; k < panels; ++k) {
    sim::Panel p;
    const Eigen::Matrix3d R =
        (Eigen::AngleAxisd(uniform(rng, -M_PI, M_PI), Eigen::Vector3d::UnitZ()) *
         Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitY()) *
         Eigen::AngleAxisd(uniform(rng, -0.8, 0.8), Eigen::Vector3d::UnitX()))
            .toRotationMatrix();
    p.world_T_panel = makeTransform(R, uniform3(rng, {1, -5, -0.5}, {9, 5, 2}));
    p.width_m = target.width * uniform(rng, 0.5, 2);
    p.height_m = target.height * uniform(rng, 0.5, 2);
    p.grey = uniform(rng, 0.05, 0.95);
    scene.panels.push_back(p);
  }
  return scene;
}

// Hostile edits of a rendered frame: what a broken driver, a lens flare or a dying sensor
// gives. Each is applied with its own chance; the size never changes (the detector's size
// check is the conversions' concern).
void editPixels(std::mt19937& rng, cv::Mat* image) {
  const int w = image->cols, h = image->rows;
  if (chance(rng, 0.4)) return;  // as rendered
  auto randomRect = [&] {
    const int x = uniformInt(rng, 0, w - 1), y = uniformInt(rng, 0, h - 1);
    return cv::Rect(x, y, uniformInt(rng, 1, w - x), uniformInt(rng, 1, h - y));
  };
  if (chance(rng, 0.2)) (*image)(randomRect()).setTo(cv::Scalar::all(255));  // saturated
  if (chance(rng, 0.2)) (*image)(randomRect()).setTo(cv::Scalar::all(0));    // dead
  if (chance(rng, 0.15)) {                                                   // inverted part
    cv::Mat part = (*image)(randomRect());
    cv::bitwise_not(part, part);
  }
  if (chance(rng, 0.15)) {  // stripes: a rolling shutter's banding, a bad row or column
    const bool rows = chance(rng, 0.5);
    const int period = uniformInt(rng, 1, 12);
    for (int i = 0; i < (rows ? h : w); i += period)
      (rows ? image->row(i) : image->col(i)).setTo(cv::Scalar::all(uniformInt(rng, 0, 255)));
  }
  if (chance(rng, 0.15)) {  // salt and pepper
    cv::Mat mask(h, w, CV_8U);
    cv::randu(mask, 0, 100);
    image->setTo(cv::Scalar::all(255), mask < 3);
    image->setTo(cv::Scalar::all(0), mask > 96);
  }
  if (chance(rng, 0.1)) {  // strong noise
    cv::Mat noise(h, w, image->type());
    cv::randn(noise, cv::Scalar::all(0), cv::Scalar::all(uniform(rng, 5, 60)));
    cv::add(*image, noise, *image);
  }
  if (chance(rng, 0.1) && w > 2 && h > 2) {  // out of focus
    const double sigma = uniform(rng, 0.5, 8);
    cv::GaussianBlur(*image, *image, cv::Size(), sigma);
  }
  if (chance(rng, 0.05)) image->setTo(cv::Scalar::all(uniformInt(rng, 0, 255)));  // flat
}

// Boards found over the run (the fuzzer must reach the fitting stages, not only the early exits).
int g_found = 0;

// An image or a LiDAR detection: a found board well formed, a miss with a reason.
template <typename Detection>
void expectWellFormed(const Detection& d, const std::string& what) {
  const auto& f = d.features;
  g_found += f.found;
  if (std::getenv("BOARD_CALIB_FUZZ_VERBOSE"))
    std::printf("%s: %s\n", what.c_str(), f.found ? "found" : f.reason.c_str());
  if (f.found) {
    EXPECT_EQ(malformedFeatures(f), "") << what;
  } else {
    EXPECT_FALSE(f.reason.empty()) << what;
  }
}

// A prior for the second chance: the true corners (when the board is in front) moved by up to
// the tolerance or far beyond it, sometimes far outside the image, in either cyclic order.
ExpectedBoard randomExpected(std::mt19937& rng, const CameraModel& camera, const Target& target,
                             const Eigen::Isometry3d& camera_T_board) {
  ExpectedBoard e;
  e.tolerance_px = chance(rng, 0.1) ? 0.0 : std::exp(uniform(rng, std::log(1.0), std::log(400.0)));
  e.inside = chance(rng, 0.3);
  const auto outer = target.outerCorners();
  const double spread = chance(rng, 0.2) ? 5000.0 : e.tolerance_px;
  for (int k = 0; k < kNumEdges; ++k) {
    Eigen::Vector2d px;
    if (!camera.projectUndistorted(camera_T_board * outer[k], &px))
      px = uniform3(rng, {-100, -100, 0}, {camera.width() + 100.0, camera.height() + 100.0, 0})
               .head<2>();
    e.corners_px[k] = px + uniform3(rng, {-spread, -spread, 0}, {spread, spread, 0}).head<2>();
  }
  if (chance(rng, 0.3)) std::reverse(e.corners_px.begin(), e.corners_px.end());
  if (chance(rng, 0.1)) e.corners_px[1] = e.corners_px[0];  // degenerate quadrilateral
  return e;
}

// Hostile edits of a scan: what a broken driver or a misconfigured LiDAR gives.
void editCloud(std::mt19937& rng, LidarCloud* cloud) {
  auto& pts = cloud->points;
  if (pts.empty()) return;
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const float inf = std::numeric_limits<float>::infinity();
  auto some = [&](double share, auto&& edit) {
    for (auto& p : pts)
      if (chance(rng, share)) edit(p);
  };
  if (chance(rng, 0.2)) some(uniform(rng, 0, 0.5), [&](LidarPoint& p) { p.x = p.y = p.z = nan; });
  if (chance(rng, 0.15)) some(uniform(rng, 0, 0.2), [&](LidarPoint& p) { p.x = p.y = p.z = 0; });
  if (chance(rng, 0.1)) some(0.01, [&](LidarPoint& p) { p.x = chance(rng, 0.5) ? inf : -inf; });
  if (chance(rng, 0.1))
    some(0.01, [&](LidarPoint& p) {
      p.x = static_cast<float>(uniform(rng, -1, 1) * 1e30);
      p.z = static_cast<float>(uniform(rng, -1, 1) * 1e30);
    });
  if (chance(rng, 0.1)) some(0.02, [&](LidarPoint& p) { p.y = nan; });  // half-valid points
  if (chance(rng, 0.1)) some(0.05, [&](LidarPoint& p) { p.intensity = nan; });
  if (chance(rng, 0.15)) {  // every return at one place (a stuck driver)
    const LidarPoint first = pts.front();
    some(uniform(rng, 0.2, 1.0), [&](LidarPoint& p) { p = first; });
  }
  if (chance(rng, 0.15)) {  // rings that do not match the layout
    cloud->has_ring = true;
    some(uniform(rng, 0.01, 1.0), [&](LidarPoint& p) {
      p.ring = chance(rng, 0.5) ? uniformInt(rng, -1000, -1) : uniformInt(rng, 0, 100000);
    });
  }
  if (chance(rng, 0.1)) {  // scaled units (mm for m, or the reverse)
    const float s = chance(rng, 0.5) ? 1000.f : 0.001f;
    some(1.0, [&](LidarPoint& p) {
      p.x *= s;
      p.y *= s;
      p.z *= s;
    });
  }
  if (chance(rng, 0.1)) {  // flattened into one plane (a 2D LiDAR's scan)
    some(1.0, [&](LidarPoint& p) { p.z = 0; });
  }
  if (!cloud->organized()) {
    if (chance(rng, 0.2)) std::shuffle(pts.begin(), pts.end(), rng);
    if (chance(rng, 0.15))
      pts.resize(static_cast<size_t>(uniformInt(rng, 0, static_cast<int>(pts.size()))));
    cloud->width = static_cast<int>(pts.size());
  } else if (chance(rng, 0.1)) {
    // Rows and columns swapped: the layout says one thing, the points another.
    std::swap(cloud->width, cloud->height);
    if (cloud->height <= 1) cloud->height = 2, cloud->width = static_cast<int>(pts.size()) / 2;
    pts.resize(static_cast<size_t>(cloud->width) * cloud->height);
  }
}

sim::LidarSpec randomLidar(std::mt19937& rng) {
  const char* presets[] = {"VLP-16", "VLP-32C", "OS1-64"};
  auto spec = sim::lidarPreset(presets[uniformInt(rng, 0, 2)]);
  EXPECT_TRUE(spec.ok()) << spec.error();
  sim::LidarSpec s = *spec;
  s.organized = chance(rng, 0.5);
  s.with_ring = chance(rng, 0.5);
  s.horizontal_resolution_deg = uniform(rng, 0.1, 0.8);  // a cheaper scan, wider columns
  s.range_noise_m = uniform(rng, 0, 0.08);
  s.dropout_probability = chance(rng, 0.3) ? uniform(rng, 0, 0.6) : 0.0;
  return s;
}

struct ImageFrame {
  CameraModel camera;
  cv::Mat image;
  Eigen::Isometry3d camera_T_board;
};

// A rendered frame of a random camera, scene and board pose, then the hostile edits.
ImageFrame renderFrame(std::mt19937& rng, const CameraModel& camera, const sim::SceneSpec& scene,
                       const Target& target) {
  ImageFrame f{camera, {}, {}};
  f.camera_T_board = randomCameraTBoard(rng, f.camera, target);
  sim::RenderOptions render;
  render.supersampling = 1;
  render.noise_sigma = uniform(rng, 0, 10);
  render.vignetting = uniform(rng, 0, 0.6);
  render.mono = chance(rng, 0.3);
  std::mt19937 render_rng(rng());
  f.image = sim::renderCameraImage(f.camera, worldTCamera(), scene,
                                   worldTCamera() * f.camera_T_board, render, render_rng);
  EXPECT_FALSE(f.image.empty());
  if (!f.image.empty()) editPixels(rng, &f.image);
  return f;
}

ImageFrame randomImageFrame(std::mt19937& rng, const Target& target) {
  const CameraModel camera = randomCamera(rng);
  const sim::SceneSpec scene = randomScene(rng, target);
  return renderFrame(rng, camera, scene, target);
}

struct CloudFrame {
  LidarCloud cloud;
  Eigen::Isometry3d world_T_board;
};

// A scan of a random LiDAR and scene with the board in front (x forward), from arm's length to
// far beyond its rings, then the hostile edits.
CloudFrame scanFrame(std::mt19937& rng, const sim::LidarSpec& spec, const sim::SceneSpec& scene,
                     const Target& target) {
  const double distance = std::exp(uniform(rng, std::log(0.4), std::log(40.0)));
  const Eigen::Matrix3d R =
      (Eigen::AngleAxisd(uniform(rng, -M_PI, M_PI), Eigen::Vector3d::UnitZ()) *
       Eigen::AngleAxisd(M_PI / 2 + uniform(rng, -1.2, 1.2), Eigen::Vector3d::UnitY()) *
       Eigen::AngleAxisd(uniform(rng, -M_PI, M_PI), Eigen::Vector3d::UnitZ()))
          .toRotationMatrix();
  const Eigen::Vector3d centre = uniform3(rng, {1, -0.5, -0.3}, {1, 0.5, 0.3}) * distance;
  CloudFrame f;
  f.world_T_board = makeTransform(R, centre - R * target.center());
  std::mt19937 scan_rng(rng());
  f.cloud =
      sim::simulateLidarScan(spec, Eigen::Isometry3d::Identity(), scene, f.world_T_board, scan_rng);
  editCloud(rng, &f.cloud);
  return f;
}

CloudFrame randomCloudFrame(std::mt19937& rng, const Target& target) {
  const sim::LidarSpec spec = randomLidar(rng);
  const sim::SceneSpec scene = randomScene(rng, target);
  return scanFrame(rng, spec, scene, target);
}

}  // namespace

TEST(FuzzDetectors, ImagesGiveWellFormedBoardsOrReasons) {
  std::mt19937 rng(fuzz::seed(31));
  g_found = 0;
  int calls = 0;
  for (int kind = 0; kind < 4; ++kind) {
    const Target target = targetOf(kind);
    auto detector = ImageBoardDetector::create(target, ImageBoardDetectorOptions{});
    ASSERT_TRUE(detector.ok()) << detector.error();
    auto tracker = ImageBoardTracker::create(target, ImageBoardDetectorOptions{});
    ASSERT_TRUE(tracker.ok()) << tracker.error();
    double stamp = 0;
    for (int i = 0; i < kImageFrames / 4; ++i) {
      const ImageFrame frame = randomImageFrame(rng, target);
      const CameraModel& camera = frame.camera;
      const cv::Mat& image = frame.image;
      const Eigen::Isometry3d& camera_T_board = frame.camera_T_board;
      const std::string what = "kind " + std::to_string(kind) + " frame " + std::to_string(i) +
                               " (" + std::to_string(image.cols) + "x" +
                               std::to_string(image.rows) + ", " +
                               std::to_string(image.channels()) + " channels)";
      expectWellFormed(detector->detect(image, camera), what + " detect");
      ++calls;
      if (target.type == TargetType::kPlain) {
        calls += 2;
        expectWellFormed(detector->detectNear(image, camera,
                                              randomExpected(rng, camera, target, camera_T_board)),
                         what + " detectNear");
        // A session: the stamp mostly advances, sometimes stands still or goes back (a bag
        // replayed in a loop); the camera may change under the tracker.
        stamp += chance(rng, 0.1) ? -uniform(rng, 0, 5) : uniform(rng, 0, 2);
        expectWellFormed(tracker->detect(image, camera, stamp), what + " tracker");
      }
    }
  }
  std::printf("images: %d boards found in %d calls\n", g_found, calls);
  // Measured 12-34 of 176 over rounds 0-15; the floor keeps the fuzzer honest should the scenes
  // stop showing a findable board (every call an early exit).
  EXPECT_GE(g_found, calls / 20);
}

TEST(FuzzDetectors, CloudsGiveWellFormedBoardsOrReasons) {
  std::mt19937 rng(fuzz::seed(37));
  g_found = 0;
  int calls = 0;
  for (int kind = 0; kind < 3; ++kind) {  // the AprilTag grid's LiDAR side is a plain board's
    const Target target = targetOf(kind);
    LidarBoardTracker tracker(target);
    double stamp = 0;
    for (int i = 0; i < kCloudFrames / 3; ++i) {
      CloudFrame frame = randomCloudFrame(rng, target);
      LidarCloud& cloud = frame.cloud;
      const Eigen::Isometry3d& world_T_board = frame.world_T_board;
      stamp += chance(rng, 0.1) ? -uniform(rng, 0, 5) : uniform(rng, 0, 2);
      cloud.stamp = stamp;
      const std::string what = "kind " + std::to_string(kind) + " cloud " + std::to_string(i) +
                               " (" + std::to_string(cloud.width) + "x" +
                               std::to_string(cloud.height) + ", " +
                               std::to_string(cloud.points.size()) + " points)";
      expectWellFormed(detectLidarBoard(cloud, target), what + " detect");
      ExpectedLidarBoard expected;
      const auto outer = target.outerCorners();
      const double off = chance(rng, 0.2) ? 50.0 : 0.3;
      for (int k = 0; k < kNumEdges; ++k)
        expected.corners[k] =
            world_T_board * outer[k] +
            uniform3(rng, Eigen::Vector3d::Constant(-off), Eigen::Vector3d::Constant(off));
      expected.tolerance_m = chance(rng, 0.1) ? 0.0 : uniform(rng, 0.01, 3.0);
      expectWellFormed(detectLidarBoardNear(cloud, target, LidarBoardDetectorOptions{}, expected),
                       what + " detectNear");
      expectWellFormed(tracker.detect(cloud), what + " tracker");
      calls += 3;
    }
  }
  std::printf("clouds: %d boards found in %d calls\n", g_found, calls);
  EXPECT_GE(g_found, calls / 20);  // measured 101-172 of 360 over rounds 0-15
}

namespace {

// One parameter as a user may set it in rqt_reconfigure: mostly its default, else its minimum,
// its maximum or anything between (the .cfg ranges bound what a live nodelet can be given).
template <typename T>
T pickSetting(std::mt19937& rng, T value, T lo, T hi) {
  if (chance(rng, 0.7)) return value;
  switch (uniformInt(rng, 0, 2)) {
    case 0: return lo;
    case 1: return hi;
    default: break;
  }
  if constexpr (std::is_same_v<T, bool>) {
    return chance(rng, 0.5);
  } else if constexpr (std::is_integral_v<T>) {
    return static_cast<T>(uniformInt(rng, static_cast<int>(lo), static_cast<int>(hi)));
  } else {
    return static_cast<T>(uniform(rng, lo, hi));
  }
}

ImageBoardDetectorConfig randomImageConfig(std::mt19937& rng) {
  ImageBoardDetectorConfig c = ImageBoardDetectorConfig::__getDefault__();
  const ImageBoardDetectorConfig& lo = ImageBoardDetectorConfig::__getMin__();
  const ImageBoardDetectorConfig& hi = ImageBoardDetectorConfig::__getMax__();
#define BOARD_CALIB_PICK(cfg, member) c.cfg = pickSetting(rng, c.cfg, lo.cfg, hi.cfg);
  BOARD_CALIB_IMAGE_DETECTOR_FIELDS(BOARD_CALIB_PICK)
#undef BOARD_CALIB_PICK
  if (std::getenv("BOARD_CALIB_FUZZ_VERBOSE")) {  // the settings that differ from the defaults
    const ImageBoardDetectorConfig& d = ImageBoardDetectorConfig::__getDefault__();
#define BOARD_CALIB_PRINT(cfg, member) \
  if (c.cfg != d.cfg) std::printf(" " #cfg "=%g", static_cast<double>(c.cfg));
    BOARD_CALIB_IMAGE_DETECTOR_FIELDS(BOARD_CALIB_PRINT)
#undef BOARD_CALIB_PRINT
    std::printf("\n");
  }
  return c;
}

CloudBoardDetectorConfig randomCloudConfig(std::mt19937& rng) {
  CloudBoardDetectorConfig c = CloudBoardDetectorConfig::__getDefault__();
  const CloudBoardDetectorConfig& lo = CloudBoardDetectorConfig::__getMin__();
  const CloudBoardDetectorConfig& hi = CloudBoardDetectorConfig::__getMax__();
#define BOARD_CALIB_PICK(cfg, member) c.cfg = pickSetting(rng, c.cfg, lo.cfg, hi.cfg);
  BOARD_CALIB_CLOUD_DETECTOR_FIELDS(BOARD_CALIB_PICK)
  // The ROI box corners map to one option each, outside the field list.
  // clang-format off
  BOARD_CALIB_PICK(roi_min_x, )
  BOARD_CALIB_PICK(roi_min_y, )
  BOARD_CALIB_PICK(roi_min_z, )
  BOARD_CALIB_PICK(roi_max_x, )
  BOARD_CALIB_PICK(roi_max_y, )
  BOARD_CALIB_PICK(roi_max_z, )
  // clang-format on
#undef BOARD_CALIB_PICK
  return c;
}

}  // namespace

// The detectors as the nodelets build them from any setting of their dynamic_reconfigure
// parameters within the .cfg ranges: either the options are refused with a reason (the
// nodelet keeps its previous ones) or every frame gives a well-formed board or a reason.
TEST(FuzzDetectors, ReconfigureSettingsGiveReasonsOrWellFormedBoards) {
  std::mt19937 rng(fuzz::seed(41));
  g_found = 0;
  int refused = 0, runs = 0;
  for (int k = 0; k < kSettingsDrawn; ++k) {
    const Target target = targetOf(k % 4);
    const ImageBoardDetectorOptions options = optionsFromConfig(randomImageConfig(rng));
    auto detector = ImageBoardDetector::create(target, options);
    if (!detector.ok()) {
      EXPECT_FALSE(detector.error().empty());
      ++refused;
      continue;
    }
    const ImageFrame frame = randomImageFrame(rng, target);
    const std::string what = "image settings " + std::to_string(k);
    expectWellFormed(detector->detect(frame.image, frame.camera), what + " detect");
    ++runs;
  }
  for (int k = 0; k < kSettingsDrawn; ++k) {
    const Target target = targetOf(k % 3);
    const LidarBoardDetectorOptions options = optionsFromConfig(randomCloudConfig(rng));
    if (const std::string why = options.validate(); !why.empty()) {
      ++refused;
      continue;
    }
    const CloudFrame frame = randomCloudFrame(rng, target);
    const std::string what = "cloud settings " + std::to_string(k);
    expectWellFormed(detectLidarBoard(frame.cloud, target, options), what + " detect");
    LidarBoardTracker tracker(target, options);
    expectWellFormed(tracker.detect(frame.cloud), what + " tracker");
    ++runs;
  }
  std::printf("settings: %d refused, %d run, %d boards found\n", refused, runs, g_found);
  EXPECT_GE(runs, kSettingsDrawn);  // most drawn settings are valid: the frames are reached
}

// What the projection nodelet does with each cloud: the hostile scans above into a random
// camera with a random extrinsic (near, far, turned away, huge) at settings within
// cfg/Projection.cfg, then drawn, coloured and, with the frame's detections, edge-checked.
// Every projected point must lie inside the image (plus the margin) with a finite depth.
TEST(FuzzDetectors, ProjectionOfHostileScansStaysInTheImage) {
  std::mt19937 rng(fuzz::seed(43));
  int projected = 0, checked = 0;
  for (int i = 0; i < kProjectionFrames; ++i) {
    const Target target = targetOf(i % 2);
    CloudFrame frame = randomCloudFrame(rng, target);
    const CameraModel camera = randomCamera(rng);
    // The LiDAR's x forward is the camera's z, then a random turn and shift.
    Eigen::Matrix3d to_optical;
    to_optical << 0, -1, 0, 0, 0, -1, 1, 0, 0;
    const Eigen::Vector3d turn =
        uniform3(rng, Eigen::Vector3d::Constant(-0.5), Eigen::Vector3d::Constant(0.5));
    Eigen::Vector3d shift = uniform3(rng, Eigen::Vector3d::Constant(-1), Eigen::Vector3d::Ones());
    if (chance(rng, 0.1)) shift *= 1e6;
    const Eigen::Matrix3d R =
        (Eigen::AngleAxisd(chance(rng, 0.1) ? M_PI : 0.0, Eigen::Vector3d::UnitY()) *
         Eigen::AngleAxisd(turn.norm(), turn.normalized()))
            .toRotationMatrix() *
        to_optical;
    const Eigen::Isometry3d camera_T_lidar = makeTransform(R, shift);
    ProjectionOptions p;
    p.min_depth_m = chance(rng, 0.7) ? 0.3 : uniform(rng, 0, 100);
    p.max_depth_m = chance(rng, 0.7) ? 30.0 : uniform(rng, 0.1, 300);
    p.zbuffer_cell_px = chance(rng, 0.7) ? 6 : uniformInt(rng, 0, 64);
    p.occlusion_tolerance_m = chance(rng, 0.7) ? 0.3 : uniform(rng, 0, 10);
    p.margin_px = chance(rng, 0.8) ? 0.0 : uniform(rng, 0, 50);
    const std::string what = "projection " + std::to_string(i);
    auto result = projectCloud(frame.cloud, camera, camera_T_lidar, p);
    if (!result.ok()) {
      EXPECT_FALSE(result.error().empty()) << what;
      continue;
    }
    ++projected;
    for (const ProjectedPoint& q : result->points) {
      ASSERT_TRUE(std::isfinite(q.u) && std::isfinite(q.v) && std::isfinite(q.depth)) << what;
      ASSERT_GE(q.u, -p.margin_px - 1) << what;
      ASSERT_GE(q.v, -p.margin_px - 1) << what;
      ASSERT_LE(q.u, camera.width() + p.margin_px) << what;
      ASSERT_LE(q.v, camera.height() + p.margin_px) << what;
      ASSERT_LT(static_cast<size_t>(q.index), frame.cloud.points.size()) << what;
    }
    cv::Mat image(camera.height(), camera.width(), chance(rng, 0.5) ? CV_8UC3 : CV_8UC1,
                  cv::Scalar::all(uniformInt(rng, 0, 255)));
    OverlayOptions overlay;
    overlay.color_mode = static_cast<ColorMode>(uniformInt(rng, 0, 2));
    overlay.point_radius_px = uniformInt(rng, 0, 10);
    overlay.alpha = uniform(rng, 0, 1);
    overlay.intensity_min = chance(rng, 0.5) ? 0.0 : uniform(rng, 0, 65535);
    overlay.intensity_max = chance(rng, 0.5) ? 0.0 : uniform(rng, 0, 65535);
    auto colored = colorCloud(frame.cloud, *result, image);
    if (colored.ok()) EXPECT_LE(colored->points.size(), result->points.size()) << what;
    const Status drawn = drawProjectedCloud(*result, overlay, &image);
    if (!drawn.ok) EXPECT_FALSE(drawn.reason.empty()) << what;
    // The edge check with this cloud's board (when found) against a board from another frame:
    // a score or a reason.
    const LidarBoardDetection lidar = detectLidarBoard(frame.cloud, target);
    if (!lidar.features.found) continue;
    const ImageFrame shot = randomImageFrame(rng, target);
    auto detector = ImageBoardDetector::create(target, ImageBoardDetectorOptions{});
    ASSERT_TRUE(detector.ok());
    const ImageDetection seen = detector->detect(shot.image, shot.camera);
    if (!seen.features.found) continue;
    EdgeCheckOptions edges;
    edges.reassociate = chance(rng, 0.5);
    auto check =
        checkProjectedEdges(lidar.features, seen.features, shot.camera, camera_T_lidar, edges);
    if (check.ok()) {
      EXPECT_TRUE(std::isfinite(check->mlre_px)) << what;
      cv::Mat canvas(shot.camera.height(), shot.camera.width(), CV_8UC3, cv::Scalar::all(0));
      EXPECT_TRUE(drawEdgeCheck(seen.features, *check, shot.camera, edges, &canvas).ok) << what;
      ++checked;
    }
  }
  std::printf("projection: %d of %d scans projected, %d edge checks\n", projected,
              kProjectionFrames, checked);
  EXPECT_GE(projected, kProjectionFrames / 2);
}

// The session memories on hostile recordings: one camera and one LiDAR in one scene, the board
// moving, every frame edited as above. The image tracker's offline pre-pass learns the scene and
// hands it to the main pass's tracker and to the detector as exclusions; the LiDAR's background
// model is built from scans of the same sensor (an edit that changes the layout must be refused
// with a reason) and used by the detector and the tracker.
TEST(FuzzDetectors, SessionMemoriesOfHostileRecordingsGiveReasons) {
  std::mt19937 rng(fuzz::seed(47));
  int found = 0, calls = 0, refused_layouts = 0;
  for (int recording = 0; recording < kRecordings; ++recording) {
    const Target target = targetOf(recording % 2);
    const CameraModel camera = randomCamera(rng);
    const sim::SceneSpec scene = randomScene(rng, target);
    auto learner = ImageBoardTracker::create(target, ImageBoardDetectorOptions{});
    auto tracker = ImageBoardTracker::create(target, ImageBoardDetectorOptions{});
    ASSERT_TRUE(learner.ok() && tracker.ok());
    std::vector<ImageFrame> frames;
    for (int i = 0; i < kRecordingFrames; ++i)
      frames.push_back(renderFrame(rng, camera, scene, target));
    // Over static_after_s (6 s): the places seen in every frame become static.
    for (int i = 0; i < kRecordingFrames; ++i)
      learner->learnScene(frames[i].image, camera, 2.0 * i, chance(rng, 0.7));
    const StaticScene known = learner->staticScene();
    tracker->setKnownScene(known);
    for (int i = 0; i < kRecordingFrames; ++i) {
      const std::string what =
          "recording " + std::to_string(recording) + " frame " + std::to_string(i);
      const ImageDetection tracked = tracker->detect(frames[i].image, camera, 2.0 * i);
      expectWellFormed(tracked, what + " tracker");
      const ImageDetection excluded = tracker->detector().detect(frames[i].image, camera, known);
      expectWellFormed(excluded, what + " excluded");
      found += tracked.features.found + excluded.features.found;
      calls += 2;
    }
    const sim::LidarSpec spec = randomLidar(rng);
    BackgroundModelOptions background_options;
    background_options.voxel_size_m = chance(rng, 0.7) ? 0.1 : uniform(rng, 0.02, 1.0);
    BackgroundModel background(background_options);
    for (int i = 0; i < 3; ++i) {
      const Status added = background.addFrame(scanFrame(rng, spec, scene, target).cloud);
      if (!added.ok) {
        EXPECT_FALSE(added.reason.empty());
        ++refused_layouts;
      }
    }
    LidarBoardTracker lidar_tracker(target);
    for (int i = 0; i < kRecordingFrames; ++i) {
      CloudFrame frame = scanFrame(rng, spec, scene, target);
      frame.cloud.stamp = 2.0 * i;
      const std::string what =
          "recording " + std::to_string(recording) + " scan " + std::to_string(i);
      const LidarBoardDetection alone = detectLidarBoard(frame.cloud, target, {}, &background);
      expectWellFormed(alone, what + " background");
      const LidarBoardDetection tracked = lidar_tracker.detect(frame.cloud, &background);
      expectWellFormed(tracked, what + " tracker");
      found += alone.features.found + tracked.features.found;
      calls += 2;
    }
  }
  std::printf("session memories: %d boards found in %d calls, %d background scans refused\n", found,
              calls, refused_layouts);
  EXPECT_GE(found, calls / 20);
}

// A wrong answer reported as good is the worst defect: simulated rigs (random LiDAR model and
// mounting, boards at random poses, a plain board), their views as the detectors give them, then
// hostile view sets (views whose LiDAR side belongs to another pose, one view repeated, only a
// few views). Every method's "good" must be within 1 deg and 5 cm of the truth.
TEST(FuzzDetectors, HostileViewSetsAreNeverAWrongGood) {
  std::mt19937 rng(fuzz::seed(53));
  int runs = 0, good = 0;
  int image_right = 0, image_wrong = 0, image_missed = 0;  // single frames, for the record
  for (int rig = 0; rig < kRigs; ++rig) {
    const Target target = targetOf(rig % 2);
    CameraIntrinsics in;
    in.width = 960;
    in.height = 600;
    in.fx = in.fy = uniform(rng, 500, 1100);
    in.cx = 480 + uniform(rng, -20, 20);
    in.cy = 300 + uniform(rng, -20, 20);
    in.model = DistortionModel::kPlumbBob;
    in.coeffs = {uniform(rng, -0.2, 0.05), uniform(rng, -0.05, 0.05), 0, 0, 0};
    const CameraModel camera = *CameraModel::create(in);
    sim::LidarSpec spec = randomLidar(rng);
    spec.dropout_probability = 0;
    spec.range_noise_m = uniform(rng, 0.005, 0.03);
    sim::SceneSpec scene = randomScene(rng, target);
    scene.panels.clear();
    const Eigen::Vector3d turn =
        uniform3(rng, Eigen::Vector3d::Constant(-0.2), Eigen::Vector3d::Constant(0.2));
    const Eigen::Isometry3d world_T_lidar =
        makeTransform(Eigen::AngleAxisd(turn.norm(), turn.normalized()).toRotationMatrix(),
                      uniform3(rng, {-0.3, -0.5, -0.3}, {0.3, 0.5, 0.5}));
    const Eigen::Isometry3d truth = worldTCamera().inverse() * world_T_lidar;
    auto detector = ImageBoardDetector::create(target, ImageBoardDetectorOptions{});
    ASSERT_TRUE(detector.ok());
    std::vector<View> views;
    for (int pose = 0; pose < kRigPoses; ++pose) {
      const double distance = uniform(rng, 2.0, 6.0);
      const Eigen::Vector3d centre = uniform3(rng, {-0.25, -0.15, 1}, {0.25, 0.15, 1}) * distance;
      Eigen::Matrix3d R;
      R = Eigen::AngleAxisd(uniform(rng, -0.6, 0.6), Eigen::Vector3d::UnitY()) *
          Eigen::AngleAxisd(uniform(rng, -0.5, 0.5), Eigen::Vector3d::UnitX()) *
          Eigen::AngleAxisd(uniform(rng, -M_PI, M_PI), Eigen::Vector3d::UnitZ());
      const Eigen::Isometry3d world_T_board =
          worldTCamera() * makeTransform(R, centre - R * target.center());
      sim::RenderOptions render;
      render.supersampling = 2;
      std::mt19937 render_rng(rng());
      const cv::Mat image =
          sim::renderCameraImage(camera, worldTCamera(), scene, world_T_board, render, render_rng);
      std::mt19937 scan_rng(rng());
      const LidarCloud cloud =
          sim::simulateLidarScan(spec, world_T_lidar, scene, world_T_board, scan_rng);
      const ImageDetection seen = detector->detect(image, camera);
      const LidarBoardDetection scanned = detectLidarBoard(cloud, target);
      // Each detector's board against the truth.
      auto off = [](const Plane& p, const Eigen::Vector3d& n) {
        return std::acos(std::min(1.0, std::abs(p.normal.dot(n)))) * 180.0 / M_PI;
      };
      const Eigen::Isometry3d camera_T_board = worldTCamera().inverse() * world_T_board;
      const double image_normal_off = off(seen.features.plane, camera_T_board.linear().col(2));
      if (seen.features.found) {
        const double centre_off =
            (seen.features.camera_T_board * target.center() - camera_T_board * target.center())
                .norm();
        (image_normal_off > 5.0 || centre_off > 0.3 ? image_wrong : image_right) += 1;
      } else {
        ++image_missed;
      }
      if (std::getenv("BOARD_CALIB_FUZZ_VERBOSE")) {
        const Eigen::Vector3d lidar_normal =
            (world_T_lidar.inverse() * world_T_board).linear().col(2);
        std::printf("rig %d pose %d at %.1f m: image %s%s, lidar %s%s\n", rig, pose, distance,
                    seen.features.found ? ("normal " + std::to_string(image_normal_off) +
                                           " deg off (" + seen.details.board_source + ")")
                                              .c_str()
                                        : "missed: ",
                    seen.features.found ? "" : seen.features.reason.c_str(),
                    scanned.features.found
                        ? ("normal " + std::to_string(off(scanned.features.plane, lidar_normal)) +
                           " deg off")
                              .c_str()
                        : "missed: ",
                    scanned.features.found ? "" : scanned.features.reason.c_str());
      }
      if (const char* dir = std::getenv("BOARD_CALIB_DEBUG_DIR"))
        cv::imwrite(std::string(dir) + "/rig" + std::to_string(rig) + "_pose" +
                        std::to_string(pose) + ".png",
                    drawImageDetection(image, camera, seen));
      if (!seen.features.found || !scanned.features.found) continue;
      View v;
      v.id = pose;
      v.camera = seen.features;
      v.lidar = scanned.features;
      views.push_back(v);
    }
    // The variants draw from their own generator: how many views were found must not change
    // the next rig.
    std::mt19937 variant_rng(rng());
    for (int variant = 0; variant < 4; ++variant) {
      std::vector<View> set = views;
      std::string what = "rig " + std::to_string(rig) + " (" + std::to_string(views.size()) +
                         " views) variant " + std::to_string(variant);
      if (variant == 1 && set.size() >= 4) {  // two LiDAR sides from other poses
        for (int k = 0; k < 2; ++k) {
          const size_t a =
              static_cast<size_t>(uniformInt(variant_rng, 0, static_cast<int>(set.size()) - 1));
          const size_t b =
              (a + 1 +
               static_cast<size_t>(uniformInt(variant_rng, 0, static_cast<int>(set.size()) - 2))) %
              set.size();
          set[a].lidar = views[b].lidar;
        }
      } else if (variant == 2 && !set.empty()) {  // one view four times
        const View repeated =
            set[static_cast<size_t>(uniformInt(variant_rng, 0, static_cast<int>(set.size()) - 1))];
        for (int k = 0; k < 3; ++k) {
          View copy = repeated;
          copy.id = 1000 + k;
          set.push_back(copy);
        }
      } else if (variant == 3) {  // few views
        set.resize(std::min(set.size(), static_cast<size_t>(uniformInt(variant_rng, 1, 4))));
      }
      if (set.empty()) continue;
      const PairCalibration run = calibratePair(
          set, {Method::kPpc, Method::kPbpc, Method::kMsgPair}, target, "camera", "lidar");
      for (const MethodRun& m : run.runs) {
        ++runs;
        if (m.verdict.verdict != Verdict::kGood) continue;
        ++good;
        const double rot = rotationErrorDeg(m.solution.camera_T_lidar, truth);
        const double trans = translationErrorM(m.solution.camera_T_lidar, truth);
        EXPECT_LT(rot, 1.0) << what << " " << methodName(m.solution.method) << ": good but " << rot
                            << " deg / " << trans << " m off";
        EXPECT_LT(trans, 0.05) << what << " " << methodName(m.solution.method) << ": good but "
                               << rot << " deg / " << trans << " m off";
      }
      std::printf("%s: %s\n", what.c_str(), run.reason.c_str());
    }
  }
  // Measured 14 good runs of 36 at the default seed, none off; 0-16 a round over rounds 1-10.
  std::printf("view sets: %d method runs, %d good\n", runs, good);
  std::printf(
      "view sets' frames: image board right %d, wrong %d (> 5 deg or 0.3 m off), missed %d\n",
      image_right, image_wrong, image_missed);
  EXPECT_GT(runs, 0);
}
