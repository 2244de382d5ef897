// SPDX-License-Identifier: BSD-3-Clause
// The LiDAR detector's hand-written geometry against PCL's components, side by side on the same
// clouds: simulated (truth from the simulator) and the real recordings (no truth: agreement).
//   voxel grid        PCL VoxelGrid down-sampling        vs  the whole detection (ours keeps plane
//                                                           statistics per voxel, not separable)
//   convex hull       pcl::ConvexHull (qhull, 2D)        vs  lidar_detail::convexHull
//   plane (RANSAC)    SACSegmentation SACMODEL_PLANE     vs  the detector's plane
//   line fitting      SACSegmentation SACMODEL_LINE      vs  lidar_detail::fitLineRobust
//   clustering        EuclideanClusterExtraction, kd-tree vs the detector's region growing
// Usage (from the package root): bench_pcl [--scenario FILE]... [--data DIR] [--frames N]
// Prints medians per data set: times (ms, single thread) and errors against the truth.
#include <board_calib/bag_reader.h>
#include <board_calib/core/common/statistics.h>
#include <board_calib/core/lidar_detection/lidar_board_detector.h>
#include <board_calib/core/sim/scenario.h>

#include "lidar_detection/geometry_2d.h"

#include <pcl/ModelCoefficients.h>
#include <pcl/filters/voxel_grid.h>
#include <pcl/point_types.h>
#include <pcl/search/kdtree.h>
#include <pcl/segmentation/extract_clusters.h>
#include <pcl/segmentation/sac_segmentation.h>
#include <pcl/surface/convex_hull.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <random>
#include <string>
#include <vector>

using namespace board_calib;

namespace {

using Cloud = pcl::PointCloud<pcl::PointXYZ>;
constexpr double kRadToDeg = 180.0 / 3.14159265358979323846;
constexpr double kVoxelM = 0.2;         // the detector's default voxel size
constexpr double kPlaneInlierM = 0.05;  // the detector's plane RANSAC threshold
constexpr double kLineInlierM = 0.03;   // the detector's edge inlier threshold
constexpr int kIterations = 100;        // the detector's RANSAC hypotheses
constexpr double kClusterToleranceM = 0.2;

// A cloud to compare on, with the board's true plane and outer corners (LiDAR frame) when known.
struct Sample {
  LidarCloud cloud;
  bool has_truth = false;
  Plane plane;
  std::array<Eigen::Vector3d, 4> corners;
};

struct Figures {
  std::map<std::string, std::vector<double>> values;
  void add(const std::string& key, double v) {
    if (std::isfinite(v)) values[key].push_back(v);
  }
  double median(const std::string& key) {
    const auto& v = values[key];
    return v.empty() ? NAN : medianOf(v);
  }
};

template <typename F>
double timeMs(F&& f) {
  const auto t0 = std::chrono::steady_clock::now();
  f();
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

Cloud::Ptr toPcl(const LidarCloud& c) {
  Cloud::Ptr out(new Cloud);
  for (const auto& p : c.points)
    if (std::isfinite(p.x) && (p.x != 0 || p.y != 0 || p.z != 0))
      out->push_back(pcl::PointXYZ(p.x, p.y, p.z));
  return out;
}

Cloud::Ptr toPcl(const Points3& pts) {
  Cloud::Ptr out(new Cloud);
  for (const auto& p : pts) out->push_back(pcl::PointXYZ(p.x(), p.y(), p.z()));
  return out;
}

// In-plane 2D coordinates of points (any orthonormal basis of the plane).
Points2 inPlane(const Points3& pts, const Plane& plane) {
  const Eigen::Vector3d u = plane.normal.unitOrthogonal(), v = plane.normal.cross(u);
  Points2 out;
  for (const auto& p : pts) out.emplace_back(p.dot(u), p.dot(v));
  return out;
}

double planeAngleDeg(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return std::acos(std::min(1.0, std::abs(a.normalized().dot(b.normalized())))) * kRadToDeg;
}

// Offset error at the board's centre: distance along the true normal between the planes there.
double planeOffsetMm(const Plane& fit, const Sample& s) {
  const Eigen::Vector3d c = 0.25 * (s.corners[0] + s.corners[1] + s.corners[2] + s.corners[3]);
  const double t = (fit.offset - fit.normal.dot(c)) / fit.normal.dot(s.plane.normal);
  return std::abs(t) * 1000.0;
}

// A fitted 3D line against the nearest true edge: angle (deg) and the distance of that edge's
// midpoint from the line (mm).
std::pair<double, double> lineError(const Eigen::Vector3d& point, const Eigen::Vector3d& dir,
                                    const Sample& s) {
  double best_deg = 1e9, best_mm = 1e9;
  for (int e = 0; e < 4; ++e) {
    const Eigen::Vector3d a = s.corners[e], b = s.corners[(e + 1) % 4];
    const Eigen::Vector3d mid = 0.5 * (a + b);
    const double mm = (mid - point).cross(dir.normalized()).norm() * 1000.0;
    if (mm < best_mm) {
      best_mm = mm;
      best_deg = planeAngleDeg(dir, b - a);
    }
  }
  return {best_deg, best_mm};
}

// PCL RANSAC model on points, coefficients refined on the inliers.
bool pclSegment(const Cloud::Ptr& cloud, int model, double threshold,
                pcl::ModelCoefficients* coeff) {
  pcl::SACSegmentation<pcl::PointXYZ> seg;
  seg.setOptimizeCoefficients(true);
  seg.setModelType(model);
  seg.setMethodType(pcl::SAC_RANSAC);
  seg.setDistanceThreshold(threshold);
  seg.setMaxIterations(kIterations);
  seg.setInputCloud(cloud);
  pcl::PointIndices inliers;
  seg.segment(inliers, *coeff);
  return !inliers.indices.empty();
}

void compareHull(const LidarBoardFeatures& f, Figures* fig) {
  const Points2 pts = inPlane(f.board_points, f.plane);
  Points2 ours;
  fig->add("hull_ours_ms", timeMs([&] { ours = lidar_detail::convexHull(pts); }));
  Cloud::Ptr flat(new Cloud);
  for (const auto& p : pts) flat->push_back(pcl::PointXYZ(p.x(), p.y(), 0.0f));
  Cloud hull;
  fig->add("hull_pcl_ms", timeMs([&] {
             pcl::ConvexHull<pcl::PointXYZ> ch;
             ch.setDimension(2);
             ch.setInputCloud(flat);
             ch.reconstruct(hull);
           }));
  Points2 pcl_hull;  // PCL returns a 2D hull's vertices in order
  for (const auto& q : hull.points) pcl_hull.emplace_back(q.x, q.y);
  const double pcl_area = std::abs(lidar_detail::polygonArea(pcl_hull));
  const double ours_area = std::abs(lidar_detail::polygonArea(ours));
  fig->add("hull_area_diff_pct",
           100.0 * std::abs(ours_area - pcl_area) / std::max(ours_area, 1e-9));
}

void comparePlane(const Sample& s, const Cloud::Ptr& all, const LidarBoardFeatures& f,
                  Figures* fig) {
  // The board with its surroundings: every point within one board diagonal of its centroid.
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  for (const auto& p : f.board_points) centroid += p;
  centroid /= static_cast<double>(f.board_points.size());
  double radius = 0;
  for (const auto& p : f.board_points) radius = std::max(radius, (p - centroid).norm());
  Cloud::Ptr crop(new Cloud);
  for (const auto& p : all->points)
    if ((Eigen::Vector3d(p.x, p.y, p.z) - centroid).norm() < 2 * radius) crop->push_back(p);
  pcl::ModelCoefficients coeff;
  bool ok = false;
  fig->add("plane_pcl_ms",
           timeMs([&] { ok = pclSegment(crop, pcl::SACMODEL_PLANE, kPlaneInlierM, &coeff); }));
  if (!ok || coeff.values.size() < 4) return;
  Plane pcl_plane;
  pcl_plane.normal = Eigen::Vector3d(coeff.values[0], coeff.values[1], coeff.values[2]);
  pcl_plane.offset = -coeff.values[3] / pcl_plane.normal.norm();
  pcl_plane.normal.normalize();
  if (!s.has_truth) {
    fig->add("plane_pcl_vs_ours_deg", planeAngleDeg(pcl_plane.normal, f.plane.normal));
    return;
  }
  fig->add("plane_ours_deg", planeAngleDeg(f.plane.normal, s.plane.normal));
  fig->add("plane_pcl_deg", planeAngleDeg(pcl_plane.normal, s.plane.normal));
  fig->add("plane_ours_mm", planeOffsetMm(f.plane, s));
  fig->add("plane_pcl_mm", planeOffsetMm(pcl_plane, s));
}

void compareLines(const Sample& s, const LidarBoardFeatures& f, Figures* fig) {
  const Eigen::Vector3d u = f.plane.normal.unitOrthogonal(), v = f.plane.normal.cross(u);
  for (int e = 0; e < 4; ++e) {
    if (f.edge_points[e].size() < 3) continue;
    std::mt19937 rng(42);
    const Points2 pts = inPlane(f.edge_points[e], f.plane);
    lidar_detail::LineFit2D ours;
    fig->add("line_ours_ms", timeMs([&] {
               ours = lidar_detail::fitLineRobust(pts, kLineInlierM, kIterations, rng);
             }));
    pcl::ModelCoefficients coeff;
    bool ok = false;
    const Cloud::Ptr cloud = toPcl(f.edge_points[e]);
    fig->add("line_pcl_ms",
             timeMs([&] { ok = pclSegment(cloud, pcl::SACMODEL_LINE, kLineInlierM, &coeff); }));
    if (!s.has_truth || !ours.ok || !ok || coeff.values.size() < 6) continue;
    // Our 2D line back in 3D (on the plane).
    const Eigen::Vector3d origin = f.plane.offset * f.plane.normal;
    const Eigen::Vector3d p3 = origin + ours.point.x() * u + ours.point.y() * v;
    const Eigen::Vector3d d3 = ours.direction.x() * u + ours.direction.y() * v;
    const auto [ours_deg, ours_mm] = lineError(p3, d3, s);
    const auto [pcl_deg, pcl_mm] =
        lineError(Eigen::Vector3d(coeff.values[0], coeff.values[1], coeff.values[2]),
                  Eigen::Vector3d(coeff.values[3], coeff.values[4], coeff.values[5]), s);
    const auto [det_deg, det_mm] = lineError(f.edge_line_point[e], f.edge_line_direction[e], s);
    fig->add("line_ours_deg", ours_deg);
    fig->add("line_pcl_deg", pcl_deg);
    fig->add("line_ours_mm", ours_mm);
    fig->add("line_pcl_mm", pcl_mm);
    if (f.edge_valid[e]) fig->add("line_detector_mm", det_mm);
    (void)det_deg;
  }
}

// PCL's kd-tree clustering of the whole cloud: time, and whether the board is a cluster of its
// own (the cluster holding most board points has at most 20 % more points than the board).
void compareClusters(const Cloud::Ptr& all, const LidarBoardFeatures* f, Figures* fig) {
  std::vector<pcl::PointIndices> clusters;
  fig->add("cluster_pcl_ms", timeMs([&] {
             pcl::search::KdTree<pcl::PointXYZ>::Ptr tree(new pcl::search::KdTree<pcl::PointXYZ>);
             tree->setInputCloud(all);
             pcl::EuclideanClusterExtraction<pcl::PointXYZ> ec;
             ec.setClusterTolerance(kClusterToleranceM);
             ec.setMinClusterSize(10);
             ec.setSearchMethod(tree);
             ec.setInputCloud(all);
             ec.extract(clusters);
           }));
  if (!f) return;
  Eigen::Vector3d c = Eigen::Vector3d::Zero();
  for (const auto& p : f->board_points) c += p;
  c /= static_cast<double>(f->board_points.size());
  size_t nearest = 0;
  double best = 1e9;
  for (size_t i = 0; i < all->size(); ++i) {
    const double d = (Eigen::Vector3d((*all)[i].x, (*all)[i].y, (*all)[i].z) - c).norm();
    if (d < best) best = d, nearest = i;
  }
  for (const auto& cl : clusters)
    if (std::find(cl.indices.begin(), cl.indices.end(), static_cast<int>(nearest)) !=
        cl.indices.end())
      fig->add("cluster_board_alone",
               cl.indices.size() <= 1.2 * f->board_points.size() ? 1.0 : 0.0);
}

void compare(const Sample& s, const Target& target, Figures* fig) {
  const Cloud::Ptr all = toPcl(s.cloud);
  fig->add("points", static_cast<double>(all->size()));
  LidarBoardDetection det;
  fig->add("detect_ours_ms", timeMs([&] { det = detectLidarBoard(s.cloud, target); }));
  Cloud voxels;
  fig->add("voxel_pcl_ms", timeMs([&] {
             pcl::VoxelGrid<pcl::PointXYZ> grid;
             grid.setLeafSize(kVoxelM, kVoxelM, kVoxelM);
             grid.setInputCloud(all);
             grid.filter(voxels);
           }));
  const LidarBoardFeatures& f = det.features;
  fig->add("found", f.found ? 1.0 : 0.0);
  compareClusters(all, f.found ? &f : nullptr, fig);
  if (!f.found || f.board_points.size() < 3) return;
  compareHull(f, fig);
  comparePlane(s, all, f, fig);
  compareLines(s, f, fig);
}

void print(const std::string& name, Figures& fig) {
  const size_t n = fig.values["found"].size();
  double found = 0;
  for (double v : fig.values["found"]) found += v;
  std::printf("\n== %s: %zu clouds, median %.0f points, board found in %.0f\n", name.c_str(), n,
              fig.median("points"), found);
  std::printf("%-28s %12s %12s\n", "median", "ours", "PCL");
  auto row = [&](const char* what, const char* ours, const char* pcl) {
    std::printf("%-28s %12.3f %12.3f\n", what, ours ? fig.median(ours) : NAN,
                pcl ? fig.median(pcl) : NAN);
  };
  row("voxel grid / detection ms", "detect_ours_ms", "voxel_pcl_ms");
  row("convex hull ms", "hull_ours_ms", "hull_pcl_ms");
  row("hull area difference %", nullptr, "hull_area_diff_pct");
  row("plane (RANSAC) ms", nullptr, "plane_pcl_ms");
  row("plane normal error deg", "plane_ours_deg", "plane_pcl_deg");
  row("plane offset error mm", "plane_ours_mm", "plane_pcl_mm");
  row("plane PCL vs ours deg", nullptr, "plane_pcl_vs_ours_deg");
  row("line fit ms", "line_ours_ms", "line_pcl_ms");
  row("line angle error deg", "line_ours_deg", "line_pcl_deg");
  row("line offset error mm", "line_ours_mm", "line_pcl_mm");
  row("detector edge line mm", "line_detector_mm", nullptr);
  row("kd-tree clustering ms", nullptr, "cluster_pcl_ms");
  double alone = 0;
  for (double v : fig.values["cluster_board_alone"]) alone += v;
  std::printf("%-28s %12s %9.0f/%zu\n", "board its own cluster", "(found)", alone,
              fig.values["cluster_board_alone"].size());
}

int runScenario(const std::string& path, int frames) {
  auto scenario = sim::loadScenario(path);
  if (!scenario) return std::fprintf(stderr, "%s\n", scenario.error().c_str()), 1;
  auto timeline = sim::makeTimeline(*scenario);
  auto gen = sim::FrameGenerator::create(*scenario);
  if (!timeline || !gen) return std::fprintf(stderr, "%s: no timeline\n", path.c_str()), 1;
  const Target& target = scenario->scene.target;
  const auto outer = target.outerCorners();
  Figures fig;
  int done = 0;
  for (size_t i = 0; i < timeline->frames.size() && done < frames; ++i) {
    const sim::Frame& fr = timeline->frames[i];
    if (fr.is_camera || !fr.still) continue;
    Sample s;
    s.cloud = gen->cloud(fr, i);
    const Eigen::Isometry3d lidar_T_board =
        sim::worldTLidar(*scenario, fr.sensor).inverse() * fr.world_T_board;
    s.has_truth = true;
    s.plane.normal = lidar_T_board.linear().col(2);
    s.plane.offset = s.plane.normal.dot(lidar_T_board.translation());
    for (int k = 0; k < 4; ++k) s.corners[k] = lidar_T_board * outer[k];
    compare(s, target, &fig);
    ++done;
  }
  print(path, fig);
  return 0;
}

int runRecording(const std::string& dir, const std::string& topic, int frames) {
  auto target = loadTarget(dir + "/target.yaml");
  if (!target) return std::fprintf(stderr, "%s\n", target.error().c_str()), 1;
  std::vector<LidarCloud> clouds;
  BagTopics topics;
  topics.cloud_topics = {topic};
  BagCallbacks cb;
  cb.on_cloud = [&](const std::string&, const LidarCloud& c) {
    if (static_cast<int>(clouds.size()) < frames) clouds.push_back(c);
  };
  const Status st = readBags({dir + "/session.bag"}, topics, cb);
  if (!st) return std::fprintf(stderr, "%s: %s\n", dir.c_str(), st.reason.c_str()), 1;
  Figures fig;
  for (const auto& c : clouds) {
    Sample s;
    s.cloud = c;
    compare(s, *target, &fig);
  }
  print(dir, fig);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  std::vector<std::string> scenarios;
  std::string data =
      "../shared/data";  // the recordings beside the repository, from the package root
  int frames = 20;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--scenario" && i + 1 < argc) {
      scenarios.push_back(argv[++i]);
    } else if (a == "--data" && i + 1 < argc) {
      data = argv[++i];
    } else if (a == "--frames" && i + 1 < argc) {
      frames = std::max(1, std::atoi(argv[++i]));
    } else {
      std::fprintf(stderr, "usage: bench_pcl [--scenario FILE]... [--data DIR] [--frames N]\n");
      return a == "--help" || a == "-h" ? 0 : 2;
    }
  }
  if (scenarios.empty())
    scenarios = {"config/scenarios/plain_vlp32c_1920.yaml",
                 "config/scenarios/checker_vlp16_1280.yaml"};
  int rc = 0;
  for (const auto& s : scenarios) rc |= runScenario(s, frames);
  rc |= runRecording(data + "/basler_os1_plain", "/os1/points", frames);
  rc |= runRecording(data + "/left_vlp32_checker", "/lidar/points", frames);
  rc |= runRecording(data + "/rs16_plain", "/rslidar/points", frames);
  return rc;
}
