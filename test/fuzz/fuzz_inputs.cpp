// Deterministic fuzzer over every reader of outside input: the message conversions (PointCloud2,
// Image, CameraInfo, Transform) and the target / session / result / rig YAML readers. Fixed
// seeds, thousands of random and structured mutations of valid messages and files. A crash, an
// uncaught exception or a sanitizer report (scripts/test.sh --sanitize) fails the suite; each
// accepted input is checked against an independent oracle (no silently accepted nonsense).
#include <board_calib/conversions.h>
#include <board_calib/core/file_io.h>
#include <board_calib/core/result_io.h>
#include <board_calib/core/session/session.h>
#include <board_calib/core/target.h>
#include <board_calib/core/transform.h>
#include "fuzz_text.h"

#include <gtest/gtest.h>
#include <sensor_msgs/image_encodings.h>

#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <random>
#include <set>
#include <sstream>

using namespace board_calib;
using fuzz::mutateText;

namespace {

// Iterations per reader: enough for every mutation kind to hit every field many times, and
// the whole binary stays well under a minute in Release (and a few minutes under ASan).
constexpr int kMessageIterations = 4000;
constexpr int kYamlIterations = 1500;

std::string readFile(const std::string& path) {
  std::ifstream in(path);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

uint32_t pick32(std::mt19937& rng, uint32_t sane) {
  // Boundary values and near-misses find the arithmetic bugs; random values the rest.
  const uint32_t specials[] = {0u,   1u,          2u,          3u,          4u,      7u,     8u,
                               16u,  0x7fffffffu, 0x80000000u, 0xffffffffu, 65535u,  65536u, 65537u,
                               sane, sane + 1,    sane - 1,    sane * 2,    sane / 2};
  switch (rng() % 3) {
    case 0: return specials[rng() % (sizeof(specials) / sizeof(specials[0]))];
    case 1: return sane + static_cast<uint32_t>(static_cast<int>(rng() % 17) - 8);
    default: return rng();
  }
}

double pickDouble(std::mt19937& rng, double sane) {
  const double specials[] = {0.0, -0.0,     -1.0,      1.0,  1e-300, 1e300,     -1e300,
                             NAN, INFINITY, -INFINITY, sane, -sane,  sane * 1e6};
  if (rng() % 2) return specials[rng() % (sizeof(specials) / sizeof(specials[0]))];
  return sane * std::uniform_real_distribution<double>(-3, 3)(rng);
}

// --- PointCloud2 ---------------------------------------------------------------------------

sensor_msgs::PointCloud2 baseCloud(std::mt19937& rng) {
  LidarCloud cloud;
  cloud.frame_id = "lidar";
  cloud.height = 1 + static_cast<int>(rng() % 4);
  cloud.width = 1 + static_cast<int>(rng() % 6);
  cloud.has_ring = rng() % 2;
  cloud.has_intensity = true;
  for (int r = 0; r < cloud.height; ++r)
    for (int c = 0; c < cloud.width; ++c) {
      LidarPoint p;
      p.x = static_cast<float>(c);
      p.y = static_cast<float>(r);
      p.z = 1.0f;
      p.ring = cloud.has_ring ? r : -1;
      cloud.points.push_back(p);
    }
  return toPointCloud2(cloud);
}

void mutateCloud(std::mt19937& rng, sensor_msgs::PointCloud2* m) {
  const int mutations = 1 + static_cast<int>(rng() % 3);
  for (int k = 0; k < mutations; ++k) {
    switch (rng() % 10) {
      case 0: m->width = pick32(rng, m->width); break;
      case 1: m->height = pick32(rng, m->height); break;
      case 2: m->point_step = pick32(rng, m->point_step); break;
      case 3: m->row_step = pick32(rng, m->row_step); break;
      case 4: m->data.resize(rng() % (m->data.size() + 64)); break;
      case 5: m->is_bigendian = !m->is_bigendian; break;
      case 6:
        if (!m->fields.empty()) m->fields[rng() % m->fields.size()].offset = pick32(rng, 4);
        break;
      case 7:
        if (!m->fields.empty())
          m->fields[rng() % m->fields.size()].datatype = static_cast<uint8_t>(rng() % 12);
        break;
      case 8:
        if (!m->fields.empty()) m->fields[rng() % m->fields.size()].count = pick32(rng, 1);
        break;
      default:
        for (auto& b : m->data)
          if (rng() % 8 == 0) b = static_cast<uint8_t>(rng());
        break;
    }
  }
}

// --- Image -------------------------------------------------------------------------------------

sensor_msgs::Image baseImage(std::mt19937& rng) {
  static const char* kEncodings[] = {"mono8", "mono16", "bgr8",        "rgb8",
                                     "bgra8", "rgba8",  "bayer_rggb8", "16UC1"};
  sensor_msgs::Image m;
  m.encoding = kEncodings[rng() % 8];
  m.width = 1 + rng() % 9;
  m.height = 1 + rng() % 7;
  const uint32_t bytes = sensor_msgs::image_encodings::numChannels(m.encoding) *
                         sensor_msgs::image_encodings::bitDepth(m.encoding) / 8;
  m.step = m.width * bytes + rng() % 3;
  m.data.resize(size_t(m.step) * m.height);
  for (auto& b : m.data) b = static_cast<uint8_t>(rng());
  return m;
}

void mutateImage(std::mt19937& rng, sensor_msgs::Image* m) {
  static const char* kEncodings[] = {"mono8",  "mono16",   "bgr8",         "32FC1",
                                     "",       "yuv422",   "bayer_bggr16", "8UC3",
                                     "rgba16", "nonsense", "16UC1",        "bgra8"};
  const int mutations = 1 + static_cast<int>(rng() % 3);
  for (int k = 0; k < mutations; ++k) {
    switch (rng() % 6) {
      case 0: m->width = pick32(rng, m->width); break;
      case 1: m->height = pick32(rng, m->height); break;
      case 2: m->step = pick32(rng, m->step); break;
      case 3: m->data.resize(rng() % (m->data.size() + 64)); break;
      case 4: m->is_bigendian = !m->is_bigendian; break;
      default: m->encoding = kEncodings[rng() % 12]; break;
    }
  }
}

// --- CameraInfo --------------------------------------------------------------------------------

sensor_msgs::CameraInfo baseInfo() {
  CameraIntrinsics in;
  in.width = 640;
  in.height = 480;
  in.fx = in.fy = 500;
  in.cx = 320;
  in.cy = 240;
  in.model = DistortionModel::kPlumbBob;
  in.coeffs = {-0.1, 0.02, 0.001, -0.001, 0.0};
  return toCameraInfo(in);
}

void mutateInfo(std::mt19937& rng, sensor_msgs::CameraInfo* m) {
  static const char* kModels[] = {"plumb_bob", "rational_polynomial", "equidistant", "", "none",
                                  "weird"};
  const int mutations = 1 + static_cast<int>(rng() % 3);
  for (int k = 0; k < mutations; ++k) {
    switch (rng() % 5) {
      case 0: m->width = pick32(rng, m->width); break;
      case 1: m->height = pick32(rng, m->height); break;
      case 2: m->K[rng() % 9] = pickDouble(rng, 300); break;
      case 3:
        if (rng() % 3 == 0) m->D.resize(rng() % 20);
        if (!m->D.empty()) m->D[rng() % m->D.size()] = pickDouble(rng, 0.1);
        break;
      default: m->distortion_model = kModels[rng() % 6]; break;
    }
  }
}

// A saved session with a few plausible views (plain board seen 2-4 m ahead).
std::string sessionText(const std::string& dir) {
  Target target;
  target.type = TargetType::kPlain;
  target.width = target.height = 1.0;
  PairSession session(target, SessionOptions{});
  for (int i = 0; i < 3; ++i) {
    View v;
    v.camera.found = v.lidar.found = true;
    v.camera.frame_id = "camera";
    v.lidar.frame_id = "lidar";
    v.camera.stamp = v.lidar.stamp = i;
    v.camera.K << 800, 0, 640, 0, 800, 360, 0, 0, 1;
    v.camera.image_width = 1280;
    v.camera.image_height = 720;
    v.camera.camera_T_board =
        makeTransform(Eigen::Vector3d(0.1 * i, 0, 2 + i), Eigen::Vector4d(0.1 * i, 0, 0, 1));
    v.camera.plane.normal = v.camera.camera_T_board.linear().col(2);
    v.camera.plane.offset = v.camera.plane.normal.dot(v.camera.camera_T_board.translation());
    v.lidar.plane = v.camera.plane;
    for (int k = 0; k < 5; ++k) v.lidar.board_points.emplace_back(2 + i, 0.1 * k, 0.05 * k);
    v.camera.pattern.push_back({1, {0.1, 0.1, 0}, {600, 300}});
    session.addView(v, "fuzz seed", false);
  }
  const std::string path = dir + "/seed_session.yaml";
  EXPECT_TRUE(session.save(path).ok);
  return readFile(path);
}

class FuzzInputs : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ =
        std::filesystem::temp_directory_path() / ("board_calib_fuzz_" + std::to_string(::getpid()));
    std::filesystem::create_directories(dir_);
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }
  std::filesystem::path dir_;
};

}  // namespace

TEST_F(FuzzInputs, PointCloud2) {
  std::mt19937 rng(fuzz::seed(15001));
  int accepted = 0;
  for (int i = 0; i < kMessageIterations; ++i) {
    sensor_msgs::PointCloud2 msg = baseCloud(rng);
    mutateCloud(rng, &msg);
    const auto cloud = fromPointCloud2(msg);
    if (!cloud) {
      EXPECT_FALSE(cloud.error().empty());
      continue;
    }
    ++accepted;
    // Oracle, computed independently: every byte the conversion may read lies inside data.
    const uint64_t points = uint64_t(msg.width) * msg.height;
    ASSERT_EQ(cloud->points.size(), points);
    if (points == 0) continue;
    uint64_t field_end = 0;
    for (const auto& f : msg.fields)
      if (f.name == "x" || f.name == "y" || f.name == "z" || f.name == "intensity" ||
          f.name == "ring")
        field_end = std::max<uint64_t>(field_end, uint64_t(f.offset) + 8);
    const uint64_t last =
        uint64_t(msg.height - 1) * msg.row_step + uint64_t(msg.width - 1) * msg.point_step;
    ASSERT_LE(last + std::min<uint64_t>(field_end, msg.point_step), msg.data.size())
        << "iteration " << i;
  }
  // Some mutations (byte flips, toggled endianness) keep the message valid: the happy path runs
  // too.
  EXPECT_GT(accepted, kMessageIterations / 20);
}

TEST_F(FuzzInputs, Image) {
  std::mt19937 rng(fuzz::seed(15002));
  int accepted = 0;
  for (int i = 0; i < kMessageIterations; ++i) {
    sensor_msgs::Image msg = baseImage(rng);
    if (rng() % 4) mutateImage(rng, &msg);
    const auto image = imageFromMsg(msg);
    if (!image) {
      EXPECT_FALSE(image.error().empty());
      // OpenCV's multi-line assertion text never reaches the user.
      EXPECT_EQ(image.error().find("Assertion"), std::string::npos) << image.error();
      continue;
    }
    ++accepted;
    ASSERT_EQ(uint64_t(image->cols), msg.width);
    ASSERT_EQ(uint64_t(image->rows), msg.height);
    ASSERT_TRUE(image->type() == CV_8UC1 || image->type() == CV_8UC3);
    ASSERT_GE(uint64_t(msg.data.size()), uint64_t(msg.height) * msg.step);
  }
  EXPECT_GT(accepted, kMessageIterations / 5);
}

TEST_F(FuzzInputs, CameraInfoAndTransform) {
  std::mt19937 rng(fuzz::seed(15003));
  int accepted = 0;
  for (int i = 0; i < kMessageIterations; ++i) {
    sensor_msgs::CameraInfo msg = baseInfo();
    mutateInfo(rng, &msg);
    const auto in = fromCameraInfo(msg);
    if (!in) continue;
    const auto model = CameraModel::create(*in);
    if (!model) continue;
    ++accepted;
    ASSERT_GT(model->width(), 0);
    ASSERT_TRUE(model->K().allFinite());
    Eigen::Vector2d pixel;
    (void)model->project(Eigen::Vector3d(0.1, -0.2, 2.0), &pixel);

    geometry_msgs::Transform t;
    t.translation.x = pickDouble(rng, 1.0);
    t.rotation.x = pickDouble(rng, 0.5);
    t.rotation.w = pickDouble(rng, 0.5);
    if (validateTransform(t).empty()) {
      ASSERT_TRUE(fromTransformMsg(t).matrix().allFinite());
    }
  }
  EXPECT_GT(accepted, kMessageIterations / 20);
}

TEST_F(FuzzInputs, TargetYaml) {
  std::mt19937 rng(fuzz::seed(15004));
  const std::string root = BOARD_CALIB_SOURCE_DIR;
  const std::vector<std::string> seeds = {
      readFile(root + "/config/targets/plain_1016.yaml"),
      readFile(root + "/config/targets/checkerboard_7x5.yaml"),
      readFile(root + "/config/targets/apriltag_grid_4x4.yaml")};
  for (const auto& s : seeds) ASSERT_TRUE(parseTarget(s).ok()) << s;
  for (int i = 0; i < kYamlIterations; ++i) {
    const auto target = parseTarget(mutateText(rng, seeds[rng() % seeds.size()]));
    if (!target) continue;
    ASSERT_EQ(target->validate(), "");
    ASSERT_TRUE(std::isfinite(target->width) && std::isfinite(target->height));
    ASSERT_LE(target->aprilTagCorners().size(), 587u);
    ASSERT_LE(target->checkerboardCorners().size(), 10000u);
  }
}

TEST_F(FuzzInputs, SessionYaml) {
  std::mt19937 rng(fuzz::seed(15005));
  const std::string seed = sessionText(dir_.string());
  const std::string path = (dir_ / "session.yaml").string();
  Target target;
  target.type = TargetType::kPlain;
  target.width = target.height = 1.0;
  int accepted = 0;
  for (int i = 0; i < kYamlIterations; ++i) {
    std::ofstream(path) << mutateText(rng, seed);
    PairSession session(target, SessionOptions{});
    const Status st = session.load(path);
    if (!st) {
      EXPECT_FALSE(st.reason.empty());
      continue;
    }
    ++accepted;
    std::set<int> ids;
    for (const auto& v : session.views()) {
      ASSERT_TRUE(ids.insert(v.view.id).second);
      ASSERT_TRUE(v.view.camera.plane.normal.allFinite() &&
                  std::isfinite(v.view.camera.plane.offset));
      ASSERT_TRUE(v.view.lidar.plane.normal.allFinite() &&
                  std::isfinite(v.view.lidar.plane.offset));
      ASSERT_TRUE(v.view.camera.image_width > 0 && v.view.camera.image_height > 0);
      ASSERT_TRUE(v.view.camera.camera_T_board.matrix().allFinite());
    }
    (void)session.coverage();
  }
  EXPECT_GT(accepted, 0);
}

TEST_F(FuzzInputs, ResultYaml) {
  std::mt19937 rng(fuzz::seed(15006));
  const std::string root = BOARD_CALIB_SOURCE_DIR;
  const std::vector<std::string> results = {readFile(root + "/test/data/result_pair_example.yaml"),
                                            readFile(root + "/test/data/result_rig_example.yaml")};
  for (const auto& r : results) ASSERT_TRUE(parseResult(r).ok());
  for (int i = 0; i < kYamlIterations; ++i) {
    const auto result = parseResult(mutateText(rng, results[rng() % results.size()]));
    if (result) {
      ASSERT_TRUE(result->camera_T_lidar.matrix().allFinite());
    }
  }
}

// Files that are not files: a directory, an empty file, /dev/null, a missing path.
TEST_F(FuzzInputs, NonFiles) {
  const std::string d = dir_.string();
  std::ofstream(d + "/empty.yaml").close();
  for (const std::string& path :
       {d, d + "/empty.yaml", std::string("/dev/null"), d + "/missing.yaml"}) {
    EXPECT_FALSE(loadTarget(path).ok()) << path;
    EXPECT_FALSE(loadResultFile(path).ok()) << path;
    PairSession session(Target{}, SessionOptions{});
    const Status st = session.load(path);
    EXPECT_FALSE(st.ok) << path;
  }
  PairSession session(Target{}, SessionOptions{});
  EXPECT_NE(session.load(d).reason.find("directory"), std::string::npos) << session.load(d).reason;
}
