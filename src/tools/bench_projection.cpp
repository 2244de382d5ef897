// Overlay throughput: project a 65k-point cloud into a 1920x1200 image, draw it, colour the
// cloud from the image; single-threaded. Uses the first frame of the basler_os1_plain
// recording (Ouster OS1-64, 64 x 1024 = 65,536 points; Basler 1920 x 1200) with the source
// authors' extrinsic when the bag is available, and a synthetic frame of the same size too.
//
//   bench_projection [--bag FILE] [--extrinsic FILE] [--iterations N] [--save DIR]
// (defaults expect the repository root as the working directory, ../shared beside it)
#include <board_calib/bag_reader.h>
#include <board_calib/core/projection/projection.h>
#include <board_calib/core/transform.h>
#include "support/basler_camera.h"

#include <opencv2/imgcodecs.hpp>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <random>
#include <string>

using namespace board_calib;

namespace {

// Relative to the repository root, where the benchmark is meant to be run from.
constexpr const char* kDefaultSharedDir = "../shared";

using Clock = std::chrono::steady_clock;

double msSince(Clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

struct Frame {
  std::string name;
  CameraModel camera;
  LidarCloud cloud;
  cv::Mat image;
  Eigen::Isometry3d camera_T_lidar = Eigen::Isometry3d::Identity();
};

// camera_T_lidar published by the recording's authors (shared/tools/mlre), 3 x 4 row-major.
Expected<Eigen::Isometry3d> readExtrinsic(const std::string& path) {
  std::ifstream in(path);
  std::vector<double> values;
  double v;
  while (in >> v) values.push_back(v);
  if (values.size() != 12)
    return Expected<Eigen::Isometry3d>::failure("cannot read 12 numbers from " + path);
  return fromRowMajor(values);
}

Expected<Frame> realFrame(const std::string& bag, const std::string& extrinsic_path) {
  Frame frame;
  frame.name = "basler_os1_plain frame 0";
  bool have_image = false, have_info = false, have_cloud = false;
  BagTopics topics;
  topics.image_topics = {"/camera/image_raw"};
  topics.camera_info_topics = {"/camera/camera_info"};
  topics.cloud_topics = {"/os1/points"};
  BagCallbacks callbacks;
  callbacks.on_image = [&](const ImageFrame& f) {
    if (!have_image) frame.image = f.image.clone();
    have_image = true;
  };
  callbacks.on_camera_info = [&](const std::string&, const std::string&,
                                 const CameraIntrinsics& in) {
    if (have_info) return;
    auto camera = CameraModel::create(in);
    if (camera.ok()) {
      frame.camera = *camera;
      have_info = true;
    }
  };
  callbacks.on_cloud = [&](const std::string&, const LidarCloud& c) {
    if (!have_cloud) frame.cloud = c;
    have_cloud = true;
  };
  const Status read = readBags({bag}, topics, callbacks);
  if (!read) return Expected<Frame>::failure(read.reason);
  if (!have_image || !have_info || !have_cloud)
    return Expected<Frame>::failure("bag lacks image, camera_info or cloud");
  const auto T = readExtrinsic(extrinsic_path);
  if (!T) return Expected<Frame>::failure(T.error());
  frame.camera_T_lidar = *T;
  return frame;
}

// Worst case: all 65,536 points in front of the camera and inside its field of view.
Frame syntheticFrame() {
  Frame frame;
  frame.name = "synthetic, every point in view";
  const CameraIntrinsics in = sim::baslerIntrinsics();
  frame.camera = CameraModel::create(in).value();
  frame.image = cv::Mat(in.height, in.width, CV_8UC3);
  cv::randu(frame.image, cv::Scalar::all(0), cv::Scalar::all(255));
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(0, in.width - 1), v(0, in.height - 1), z(1.0, 25.0);
  frame.cloud.frame_id = "lidar";
  frame.cloud.width = 1024;
  frame.cloud.height = 64;
  frame.cloud.has_intensity = true;
  for (int i = 0; i < 64 * 1024; ++i) {
    const Eigen::Vector3d ray = frame.camera.unprojectRay(Eigen::Vector2d(u(rng), v(rng)));
    const Eigen::Vector3d p = ray * (z(rng) / ray.z());
    LidarPoint lp;
    lp.x = static_cast<float>(p.x());
    lp.y = static_cast<float>(p.y());
    lp.z = static_cast<float>(p.z());
    lp.intensity = static_cast<float>(i % 256);
    frame.cloud.points.push_back(lp);
  }
  return frame;
}

void bench(const Frame& frame, int iterations, const std::string& save_dir) {
  ProjectionOptions projection;
  OverlayOptions overlay;
  overlay.point_radius_px = 2;
  double t_project = 0, t_draw = 0, t_color = 0, t_total = 0;
  size_t visible = 0, occluded = 0;
  cv::Mat out;
  for (int it = 0; it < iterations; ++it) {
    const auto t0 = Clock::now();
    const auto projected =
        projectCloud(frame.cloud, frame.camera, frame.camera_T_lidar, projection);
    const double a = msSince(t0);
    if (!projected) {
      std::fprintf(stderr, "projection failed: %s\n", projected.error().c_str());
      std::exit(1);
    }
    const auto t1 = Clock::now();
    out = frame.image.clone();  // the nodelet draws on a copy of the incoming image too
    drawProjectedCloud(*projected, overlay, &out);
    const double b = msSince(t1);
    const auto t2 = Clock::now();
    const auto colored = colorCloud(frame.cloud, *projected, frame.image);
    const double c = msSince(t2);
    t_project += a;
    t_draw += b;
    t_color += c;
    t_total += msSince(t0);
    visible = projected->points.size();
    occluded = projected->occluded;
  }
  const double n = iterations;
  std::printf("%s: %zu points, image %dx%d, %zu drawn (%zu occluded), %d iterations\n",
              frame.name.c_str(), frame.cloud.points.size(), frame.image.cols, frame.image.rows,
              visible, occluded, iterations);
  std::printf(
      "  project %.2f ms | copy+draw %.2f ms | colour cloud %.2f ms | total %.2f ms = %.1f Hz\n",
      t_project / n, t_draw / n, t_color / n, t_total / n, 1000.0 * n / t_total);
  if (!save_dir.empty()) {
    std::string file =
        save_dir + "/bench_projection_" + (frame.name[0] == 's' ? "synthetic" : "real") + ".png";
    cv::imwrite(file, out);
    std::printf("  saved %s\n", file.c_str());
  }
}

}  // namespace

int main(int argc, char** argv) {
  std::string bag = std::string(kDefaultSharedDir) + "/data/basler_os1_plain/session.bag";
  std::string extrinsic =
      std::string(kDefaultSharedDir) + "/tools/mlre/authors_extrinsic_basler_os1.txt";
  int iterations = 50;
  std::string save_dir;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    if (arg == "--bag" && i + 1 < argc)
      bag = argv[++i];
    else if (arg == "--extrinsic" && i + 1 < argc)
      extrinsic = argv[++i];
    else if (arg == "--iterations" && i + 1 < argc)
      iterations = std::max(1, std::atoi(argv[++i]));
    else if (arg == "--save" && i + 1 < argc)
      save_dir = argv[++i];
    else {
      std::printf(
          "usage: bench_projection [--bag FILE] [--extrinsic FILE] [--iterations N] [--save "
          "DIR]\n");
      return arg == "--help" || arg == "-h" ? 0 : 2;
    }
  }
  const auto real = realFrame(bag, extrinsic);
  if (real)
    bench(*real, iterations, save_dir);
  else
    std::printf("real frame skipped: %s\n", real.error().c_str());
  bench(syntheticFrame(), iterations, save_dir);
  return 0;
}
