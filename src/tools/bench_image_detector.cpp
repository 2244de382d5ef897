// Benchmark of the camera board detector: single-threaded detection time per frame on simulated
// 1920x1200 images (plain board, checkerboard, AprilTag grid) with their corner accuracy.
// Usage (from the package root): bench_image_detector [--frames N] [--targets DIR (default
// config/targets)]
//   [--board plain|checkerboard|apriltag_grid (default all)] [--tag-decimate X] [--tag-sigma PX]
//   [--tag-refine 0|1]
//   [--per-frame] [--stages (plain board: mean time per detection stage)]
#include <board_calib/core/image_detection/image_board_detector.h>
#include <board_calib/core/sim/simulator.h>
#include <board_calib/core/transform.h>

#include <opencv2/core/utility.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

using namespace board_calib;

namespace {

CameraModel benchCamera() {
  CameraIntrinsics in;
  in.width = 1920;
  in.height = 1200;
  in.fx = in.fy = 1500;
  in.cx = 960;
  in.cy = 600;
  in.model = DistortionModel::kPlumbBob;
  in.coeffs = {-0.13, -0.03, 0.002, 0.0008, 0.0};
  return *CameraModel::create(in);
}

struct BenchFigures {
  std::vector<double> times_ms;
  PlainStageTimes stage_sum;
  int found = 0;
  double sum_rms = 0, max_err = 0, max_point_err = 0;
};

// Detection time (median, p95, max) and accuracy over `frames` simulated views of one board.
BenchFigures benchTarget(const Target& board, ImageBoardDetector* detector,
                         const CameraModel& camera, const Eigen::Isometry3d& world_T_camera,
                         int frames, bool per_frame) {
  const Target* target = &board;
  sim::SceneSpec scene;
  scene.target = *target;
  scene.room = target->type != TargetType::kPlain;  // see test_image_detector: grey-on-grey room
  std::mt19937 rng(1);
  std::uniform_real_distribution<double> dist(2.0, 5.0), angle(-20, 20);
  BenchFigures r;
  for (int f = 0; f < frames; ++f) {
    const double roll = (target->type == TargetType::kPlain ? 45 : 15) + angle(rng) / 4;
    const Eigen::Matrix3d Rb =
        (Eigen::AngleAxisd(angle(rng) * kRadPerDeg, Eigen::Vector3d::UnitY()) *
         Eigen::AngleAxisd(angle(rng) * kRadPerDeg, Eigen::Vector3d::UnitX()) *
         Eigen::AngleAxisd(roll * kRadPerDeg, Eigen::Vector3d::UnitZ()))
            .toRotationMatrix();
    const Eigen::Isometry3d camera_T_board =
        makeTransform(Rb, Eigen::Vector3d(0, 0, dist(rng)) - Rb * target->center());
    const cv::Mat image = sim::renderCameraImage(
        camera, world_T_camera, scene, world_T_camera * camera_T_board, sim::RenderOptions(), rng);
    const ImageDetection d = detector->detect(image, camera);
    r.times_ms.push_back(d.details.time_ms);
    r.stage_sum += d.details.stage_times;
    if (per_frame) std::printf("  frame %d: %.1f ms\n", f, d.details.time_ms);
    if (!d.features.found) continue;
    ++r.found;
    r.sum_rms += d.features.reprojection_rms_px;
    for (const auto& o :
         d.features.pattern) {  // pattern points (checkerboard, tag corners) vs truth
      Eigen::Vector2d truth;
      camera.projectUndistorted(camera_T_board * o.board_point, &truth);
      r.max_point_err = std::max(r.max_point_err, (o.pixel - truth).norm());
    }
    const auto outer = target->outerCorners();
    for (int j = 0; j < 4; ++j) {  // outer corners vs truth (all types report them)
      Eigen::Vector2d truth;
      camera.projectUndistorted(camera_T_board * outer[j], &truth);
      double best = 1e9;
      for (int k = 0; k < 4; ++k) best = std::min(best, (d.features.corners_px[k] - truth).norm());
      r.max_err = std::max(r.max_err, best);
    }
  }
  return r;
}

double percentile(std::vector<double> v, double q) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v[static_cast<size_t>(
      std::min<double>(v.size() - 1, std::floor(q * (v.size() - 1) + 0.5)))];
}

}  // namespace

int main(int argc, char** argv) {
  int frames = 10;
  std::string targets_dir = "config/targets", only;
  ImageBoardDetectorOptions options;
  bool per_frame = false, stages = false;
  for (int i = 1; i < argc; ++i) {
    per_frame |= std::strcmp(argv[i], "--per-frame") == 0;
    stages |= std::strcmp(argv[i], "--stages") == 0;
  }
  for (int i = 1; i + 1 < argc; ++i) {
    if (std::strcmp(argv[i], "--frames") == 0) frames = std::max(1, std::atoi(argv[i + 1]));
    if (std::strcmp(argv[i], "--targets") == 0) targets_dir = argv[i + 1];
    if (std::strcmp(argv[i], "--board") == 0) only = argv[i + 1];
    if (std::strcmp(argv[i], "--tag-decimate") == 0) options.tag_decimate = std::atof(argv[i + 1]);
    if (std::strcmp(argv[i], "--tag-sigma") == 0) options.tag_sigma = std::atof(argv[i + 1]);
    if (std::strcmp(argv[i], "--tag-refine") == 0)
      options.tag_refine_edges = std::atoi(argv[i + 1]) != 0;
  }
  cv::setNumThreads(1);  // single-threaded figures
  const CameraModel camera = benchCamera();
  Eigen::Matrix3d R;
  R << 0, 0, 1, -1, 0, 0, 0, -1, 0;
  const Eigen::Isometry3d world_T_camera = makeTransform(R, Eigen::Vector3d(0, 0, 0.2));
  std::printf("%-14s %8s %8s %9s %8s %8s %10s %12s %14s\n", "board", "found", "mean_ms",
              "median_ms", "p95_ms", "max_ms", "rms_px", "max_err_px", "max_point_px");
  for (const std::string name :
       {"plain_1016.yaml", "checkerboard_7x5.yaml", "apriltag_grid_4x4.yaml"}) {
    auto target = loadTarget(targets_dir + "/" + name);
    if (!target) {
      std::fprintf(stderr, "%s\n", target.error().c_str());
      return 1;
    }
    if (!only.empty() && only != targetTypeName(target->type)) continue;
    auto detector = ImageBoardDetector::create(*target, options);
    if (!detector) {
      std::fprintf(stderr, "%s\n", detector.error().c_str());
      return 1;
    }
    const BenchFigures r =
        benchTarget(*target, &*detector, camera, world_T_camera, frames, per_frame);
    double sum_ms = 0;
    for (double t : r.times_ms) sum_ms += t;
    std::printf("%-14s %5d/%-3d %8.1f %9.1f %8.1f %8.1f %10.3f %12.3f %14.3f\n",
                targetTypeName(target->type), r.found, frames, sum_ms / frames,
                percentile(r.times_ms, 0.5), percentile(r.times_ms, 0.95),
                percentile(r.times_ms, 1.0), r.found ? r.sum_rms / r.found : 0.0, r.max_err,
                r.max_point_err);
    if (stages && target->type == TargetType::kPlain)
      std::printf("  stages, mean ms per frame: %s\n",
                  r.stage_sum.scaled(1.0 / frames).text().c_str());
  }
  return 0;
}
