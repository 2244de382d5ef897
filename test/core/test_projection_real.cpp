// The projected-edges check on real data against an independent implementation: the
// reference features of basler_os1_plain (shared/tools/mlre, extracted without any extrinsic)
// scored with the source authors' extrinsic must reproduce the numbers of shared/tools/mlre
// (Python/numpy): MLRE 6.086 px (mean over frames of the mean over lines), 1551 points with a
// pooled mean of 6.191 px.
#include <board_calib/core/projection/projection.h>
#include <board_calib/core/transform.h>

#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <filesystem>
#include <fstream>

using namespace board_calib;

namespace {

const std::string kMlreDir = std::string(BOARD_CALIB_SHARED_DIR) + "/tools/mlre";
const char* kEdgeNames[kNumEdges] = {"UL", "UR", "LR", "LL"};

int edgeIndex(const std::string& name) {
  for (int j = 0; j < kNumEdges; ++j)
    if (name == kEdgeNames[j]) return j;
  return -1;
}

}  // namespace

TEST(ProjectionReal, EdgeCheckReproducesTheIndependentMlreTool) {
  if (!std::filesystem::exists(kMlreDir)) GTEST_SKIP() << "../shared is absent";
  std::ifstream extrinsic_file(kMlreDir + "/authors_extrinsic_basler_os1.txt");
  std::vector<double> values;
  double v;
  while (extrinsic_file >> v) values.push_back(v);
  const auto camera_T_lidar = fromRowMajor(values);
  ASSERT_TRUE(camera_T_lidar.ok()) << camera_T_lidar.error();

  int frames = 0, points = 0;
  double sum_frame_mlre = 0, sum_point_residuals = 0;
  for (const auto& entry :
       std::filesystem::directory_iterator(kMlreDir + "/ref_basler_os1_plain")) {
    if (entry.path().extension() != ".yaml") continue;
    const YAML::Node ref = YAML::LoadFile(entry.path().string());
    const YAML::Node cam = ref["camera"];
    CameraIntrinsics in;
    in.width = cam["width"].as<int>();
    in.height = cam["height"].as<int>();
    const auto K = cam["K"].as<std::vector<double>>();
    in.fx = K[0];
    in.cx = K[2];
    in.fy = K[4];
    in.cy = K[5];
    in.model = DistortionModel::kPlumbBob;
    in.coeffs = cam["D"].as<std::vector<double>>();
    const auto camera = CameraModel::create(in);
    ASSERT_TRUE(camera.ok()) << camera.error();

    // Image edge j is paired with LiDAR edge pairs[j]: put that LiDAR edge at index j.
    CameraBoardFeatures image;
    LidarBoardFeatures lidar;
    image.found = lidar.found = true;
    for (const auto& pair : ref["association"]["pairs"]) {
      const int j = edgeIndex(pair.first.as<std::string>());
      const std::string lidar_name = pair.second.as<std::string>();
      ASSERT_GE(j, 0);
      const YAML::Node ie = ref["image"]["edges"][kEdgeNames[j]];
      const YAML::Node le = ref["lidar"]["edges"][lidar_name];
      if (!ie || !le || !ie["valid"].as<bool>() || !le["valid"].as<bool>()) continue;
      const auto line = ie["line_undist"].as<std::vector<double>>();
      image.edge_lines[j] = Eigen::Vector3d(line[0], line[1], line[2]);
      image.edge_valid[j] = true;
      lidar.edge_valid[j] = true;
      for (const auto& p : le["points"]) {
        const auto xyz = p.as<std::vector<double>>();
        lidar.edge_points[j].emplace_back(xyz[0], xyz[1], xyz[2]);
      }
    }
    EdgeCheckOptions options;
    options.reassociate = false;  // the reference association is the one to score
    const auto check = checkProjectedEdges(lidar, image, *camera, *camera_T_lidar, options);
    ASSERT_TRUE(check.ok()) << entry.path() << ": " << check.error();
    double sum_lines = 0;
    int lines = 0;
    for (int j = 0; j < kNumEdges; ++j) {
      if (check->image_edge[j] < 0) continue;
      sum_lines += check->mean_residual_px[j];
      ++lines;
    }
    ASSERT_GT(lines, 0);
    sum_frame_mlre += sum_lines / lines;
    sum_point_residuals += check->mlre_px * check->num_points;
    points += check->num_points;
    ++frames;

    // With the association left to the check, the best assignment is the reference one.
    const auto reassociated =
        checkProjectedEdges(lidar, image, *camera, *camera_T_lidar, EdgeCheckOptions());
    ASSERT_TRUE(reassociated.ok());
    EXPECT_NEAR(reassociated->mlre_px, check->mlre_px, 1e-9) << entry.path();
  }
  ASSERT_EQ(frames, 16);
  // The tool prints 3 decimals; both evaluate the same pinhole maths in double precision.
  EXPECT_EQ(points, 1551);
  EXPECT_NEAR(sum_frame_mlre / frames, 6.086, 0.001);
  EXPECT_NEAR(sum_point_residuals / points, 6.191, 0.001);
}
