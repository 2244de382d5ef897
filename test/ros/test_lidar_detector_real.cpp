// LiDAR board detector on the real recordings in ../shared/data (skipped only when ../shared is
// absent), plus the conversion-level bad input (missing x/y/z fields).
#include <board_calib/bag_reader.h>
#include <board_calib/conversions.h>
#include <board_calib/core/lidar_detection/lidar_board_detector.h>

#include <gtest/gtest.h>
#include <sys/stat.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <ctime>

using namespace board_calib;

namespace {

const std::string kShared = BOARD_CALIB_SHARED_DIR;

bool exists(const std::string& path) {
  struct stat st;
  return stat(path.c_str(), &st) == 0;
}

std::vector<LidarCloud> readClouds(const std::string& folder, const std::string& topic) {
  std::vector<LidarCloud> clouds;
  BagTopics topics;
  topics.cloud_topics = {topic};
  BagCallbacks cb;
  cb.on_cloud = [&](const std::string&, const LidarCloud& c) { clouds.push_back(c); };
  const Status st = readBags({kShared + "/data/" + folder + "/session.bag"}, topics, cb);
  EXPECT_TRUE(st.ok) << st.reason;
  return clouds;
}

LidarCloud withoutRing(LidarCloud c, bool flatten) {
  c.has_ring = false;
  for (auto& p : c.points) p.ring = -1;
  if (flatten) {
    c.width = static_cast<int>(c.points.size());
    c.height = 1;
  }
  return c;
}

struct Tally {
  int frames = 0, planes = 0, four_edges = 0;
  double size_sum = 0.0;
};

Tally run(const std::vector<LidarCloud>& clouds, const Target& target, const char* label) {
  Tally t;
  std::vector<double> cpu_ms;
  for (const auto& c : clouds) {
    timespec t0, t1;
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t0);
    const auto det = detectLidarBoard(c, target);
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t1);
    cpu_ms.push_back((t1.tv_sec - t0.tv_sec) * 1e3 + (t1.tv_nsec - t0.tv_nsec) * 1e-6);
    const auto& f = det.features;
    ++t.frames;
    t.planes += f.found;
    if (f.found && f.allEdgesValid()) {
      ++t.four_edges;
      t.size_sum += 0.5 * (f.measured_size_m.x() + f.measured_size_m.y());
    }
    std::printf(
        "[%s] frame %2d: found %d edges %d%d%d%d n=%zu edge pts %zu/%zu/%zu/%zu d=%.3f size %.3f x "
        "%.3f | %s\n",
        label, t.frames - 1, f.found, f.edge_valid[0], f.edge_valid[1], f.edge_valid[2],
        f.edge_valid[3], f.board_points.size(), f.edge_points[0].size(), f.edge_points[1].size(),
        f.edge_points[2].size(), f.edge_points[3].size(), f.plane.offset, f.measured_size_m.x(),
        f.measured_size_m.y(), f.reason.c_str());
    if (std::getenv("LIDAR_TEST_VERBOSE"))
      for (const auto& c : det.candidates)
        std::printf(
            "    cand n=%d at (%.2f %.2f %.2f) rect %.2f x %.2f fill %.2f rms %.3f score %.3f %s\n",
            c.num_points, c.centroid.x(), c.centroid.y(), c.centroid.z(), c.rectangle_m.x(),
            c.rectangle_m.y(), c.fill_ratio, c.rms_m, c.score, c.rejected_because.c_str());
  }
  std::sort(cpu_ms.begin(), cpu_ms.end());
  if (!cpu_ms.empty())
    std::printf(
        "[%s] detector CPU time per cloud: median %.2f ms, max %.2f ms (%zu points per cloud)\n",
        label, cpu_ms[cpu_ms.size() / 2], cpu_ms.back(), clouds.front().points.size());
  return t;
}

}  // namespace

TEST(LidarDetectorReal, Os1PlainBoardAndEdges) {
  const std::string folder = kShared + "/data/basler_os1_plain";
  if (!exists(folder)) GTEST_SKIP() << "no " << folder;
  const auto target = loadTarget(folder + "/target.yaml");
  ASSERT_TRUE(target.ok()) << target.error();
  const auto clouds = readClouds("basler_os1_plain", "/os1/points");
  ASSERT_EQ(clouds.size(), 16u);
  const Tally t = run(clouds, *target, "os1");
  // Issue target: board and four edges in >= 15 of 16 frames.
  EXPECT_GE(t.four_edges, 15);
  EXPECT_EQ(t.planes, 16);
  // The README measures ~1.045 m per side in the LiDAR (declared 1.016 m): the detector must
  // report that figure; +-2.5 cm covers the edge-point spacing (0.35 deg columns ~ 2 cm at 3 m).
  ASSERT_GT(t.four_edges, 0);
  const double mean_size = t.size_sum / t.four_edges;
  std::printf("os1: mean measured side %.3f m\n", mean_size);
  EXPECT_NEAR(mean_size, 1.045, 0.025);
}

TEST(LidarDetectorReal, Os1WithoutRingField) {
  const std::string folder = kShared + "/data/basler_os1_plain";
  if (!exists(folder)) GTEST_SKIP() << "no " << folder;
  const auto target = loadTarget(folder + "/target.yaml");
  ASSERT_TRUE(target.ok()) << target.error();
  const auto clouds = readClouds("basler_os1_plain", "/os1/points");
  std::vector<LidarCloud> organized, flat;
  for (const auto& c : clouds) {
    organized.push_back(withoutRing(c, false));
    flat.push_back(withoutRing(c, true));
  }
  const Tally by_row = run(organized, *target, "os1-rows");
  const Tally by_elevation = run(flat, *target, "os1-elevation");
  EXPECT_GE(by_row.four_edges, 15);
  // Unorganized without ring: scan lines come from elevation clustering.
  EXPECT_GE(by_elevation.four_edges, 15);
}

TEST(LidarDetectorReal, Vlp32CheckerboardPlaneEveryFrame) {
  const std::string folder = kShared + "/data/left_vlp32_checker";
  if (!exists(folder)) GTEST_SKIP() << "no " << folder;
  const auto target = loadTarget(folder + "/target.yaml");
  ASSERT_TRUE(target.ok()) << target.error();
  const auto clouds = readClouds("left_vlp32_checker", "/lidar/points");
  ASSERT_EQ(clouds.size(), 32u);
  const Tally t = run(clouds, *target, "vlp32");
  EXPECT_EQ(t.planes, 32);
  std::vector<LidarCloud> flat;
  for (const auto& c : clouds) flat.push_back(withoutRing(c, true));
  const Tally t2 = run(flat, *target, "vlp32-elevation");
  EXPECT_EQ(t2.planes, 32);
}

// RoboSense RS-16 without ring, unorganized, 1.2-1.9 m, plain grey 0.80 x 0.60 m board held by
// its left and right edges (hands stick out 1-3 cm, legs within 4 cm of the plane below it;
// README of the data). 12-15 scan lines cross the board. The board must be found in every
// cloud, right where the board is (its points' elevations span at least 10 lines, as the
// README counts), and its four edges in at least 6 of 8 (hands on two edges).
TEST(LidarDetectorReal, Rs16PlainBoardWithoutRing) {
  const std::string folder = kShared + "/data/rs16_plain";
  if (!exists(folder)) GTEST_SKIP() << "no " << folder;
  const auto target = loadTarget(folder + "/target.yaml");
  ASSERT_TRUE(target.ok()) << target.error();
  const auto clouds = readClouds("rs16_plain", "/rslidar/points");
  ASSERT_EQ(clouds.size(), 8u);
  const Tally t = run(clouds, *target, "rs16");
  EXPECT_EQ(t.planes, 8);
  EXPECT_GE(t.four_edges, 6);
  for (const auto& c : clouds) {
    const auto det = detectLidarBoard(c, *target);
    if (!det.features.found) continue;
    // The board lies 1.2-1.9 m ahead at -y (README), not on a wall or the floor.
    const Eigen::Vector3d n = det.features.plane.normal;
    EXPECT_GT(det.features.plane.offset, 1.0);
    EXPECT_LT(det.features.plane.offset, 2.2);
    EXPECT_GT(std::abs(n.x()), 0.7) << "board faces the LiDAR";
    EXPECT_GE(det.num_scan_lines, 10);
  }
}

TEST(LidarDetectorReal, MissingXyzFieldsGiveAReason) {
  sensor_msgs::PointCloud2 msg;
  msg.height = 1;
  msg.width = 2;
  msg.point_step = 8;
  msg.row_step = 16;
  msg.data.assign(16, 0);
  sensor_msgs::PointField fx, fy;
  fx.name = "x";
  fx.offset = 0;
  fx.datatype = sensor_msgs::PointField::FLOAT32;
  fx.count = 1;
  fy = fx;
  fy.name = "y";
  fy.offset = 4;
  msg.fields = {fx, fy};
  const auto cloud = fromPointCloud2(msg);
  ASSERT_FALSE(cloud.ok());
  EXPECT_NE(cloud.error().find("x/y/z"), std::string::npos) << cloud.error();
}
