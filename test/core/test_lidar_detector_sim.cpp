// LiDAR board detector against the simulator's ground truth: VLP-16, VLP-32C and OS1-64,
// organized with ring and unorganized without ring, in a room with a person behind the board;
// plus no board, two boards and the background model.
#include <board_calib/core/lidar_detection/lidar_board_detector.h>
#include <board_calib/core/sim/scenario.h>
#include <board_calib/core/sim/simulator.h>
#include <board_calib/core/transform.h>

#include <gtest/gtest.h>

#include "lidar_truth.h"
#include "sim_test_helpers.h"

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <map>

namespace board_calib {
namespace {

using namespace lidar_truth;

// Board facing the LiDAR (board x right, y down as seen from it), rolled about its normal by
// roll_deg (45 = diamond), then yawed and pitched: the simulator tests' pose.
using sim::boardPose;

sim::SceneSpec scene(const Target& target) {
  sim::SceneSpec s;
  s.target = target;
  return s;
}

sim::LidarSpec spec(const std::string& name, bool organized_with_ring) {
  auto s = sim::lidarPreset(name);
  EXPECT_TRUE(s.ok()) << s.error();
  s->organized = organized_with_ring;
  s->with_ring = organized_with_ring;
  return *s;
}

struct SweepResult {
  int frames = 0, found = 0, four_edges = 0;
  double max_normal_deg = 0.0, max_edge_m = 0.0, sum_edge_m = 0.0;
  int edges_measured = 0;
  int normals_within = 0, edges_within = 0;  // against kMaxNormalDeg / kMaxEdgeLineM
};

// Issue targets: normal within 0.5 deg, edge lines within kMaxEdgeLineM of truth at 3 m,
// detection >= 95 % of still frames (20 frames: at most one miss).
constexpr int kFrames = 20;
constexpr int kMinDetected = 19;
constexpr double kMaxNormalDeg = 0.5;

// A board held at a random pose: centre ± spread per axis (m), roll ± roll spread, yaw and
// pitch ± their limits (deg); the cloud of `s` seeing it.
struct PoseDraw {
  Eigen::Vector3d centre, spread;
  double roll_deg, roll_spread_deg, yaw_deg, pitch_deg;
};

LidarCloud drawCloud(const sim::LidarSpec& s, const sim::SceneSpec& world, const Target& target,
                     const PoseDraw& d, std::mt19937& rng, Eigen::Isometry3d* board) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const Eigen::Vector3d centre(d.centre.x() + d.spread.x() * u(rng),
                               d.centre.y() + d.spread.y() * u(rng),
                               d.centre.z() + d.spread.z() * u(rng));
  *board = boardPose(target, centre, d.roll_deg + d.roll_spread_deg * u(rng), d.yaw_deg * u(rng),
                     d.pitch_deg * u(rng));
  return sim::simulateLidarScan(s, Eigen::Isometry3d::Identity(), world, *board, rng);
}

// Random diamond-held poses around 3 m, as a person holds the board in front of the rig.
SweepResult sweep(const std::string& lidar, bool organized_with_ring, bool person, int frames,
                  unsigned seed) {
  const Target target = plainBoard();
  const sim::LidarSpec s = spec(lidar, organized_with_ring);
  sim::SceneSpec world = scene(target);
  world.occluder = person;
  std::mt19937 rng(seed);
  const PoseDraw diamond{{3.0, 0.0, 0.0}, {0.2, 0.6, 0.1}, 45.0, 10.0, 25.0, 15.0};
  SweepResult r;
  for (int i = 0; i < frames; ++i) {
    Eigen::Isometry3d board;
    const LidarCloud cloud = drawCloud(s, world, target, diamond, rng, &board);
    const LidarBoardDetection det = detectLidarBoard(cloud, target);
    const Truth truth = truthOf(target, board);
    ++r.frames;
    const auto& f = det.features;
    if (!f.found) {
      std::printf("%s %s frame %d: %s\n", lidar.c_str(), organized_with_ring ? "organized" : "flat",
                  i, f.reason.c_str());
      for (const auto& c : det.candidates)
        if (c.num_points > 200) printCandidate(c);
      continue;
    }
    ++r.found;
    const double normal_deg =
        std::acos(std::min(1.0, f.plane.normal.dot(truth.plane.normal))) * kDegPerRad;
    r.max_normal_deg = std::max(r.max_normal_deg, normal_deg);
    r.normals_within += normal_deg < kMaxNormalDeg;
    if (!f.allEdgesValid()) {
      std::printf("%s %s frame %d: edges: %s\n", lidar.c_str(),
                  organized_with_ring ? "organized" : "flat", i, f.reason.c_str());
      continue;
    }
    ++r.four_edges;
    if (std::getenv("LIDAR_TEST_VERBOSE"))
      std::printf(
          "  %d: normal %.3f deg, edges %.4f %.4f %.4f %.4f m, pts %zu %zu %zu %zu, size %.3f "
          "%.3f\n",
          i, std::acos(std::min(1.0, f.plane.normal.dot(truth.plane.normal))) * kDegPerRad,
          edgeLineError(f, 0, truth), edgeLineError(f, 1, truth), edgeLineError(f, 2, truth),
          edgeLineError(f, 3, truth), f.edge_points[0].size(), f.edge_points[1].size(),
          f.edge_points[2].size(), f.edge_points[3].size(), f.measured_size_m.x(),
          f.measured_size_m.y());
    if (std::getenv("LIDAR_TEST_DUMP") && std::atoi(std::getenv("LIDAR_TEST_DUMP")) == i) {
      FILE* out = std::fopen("/tmp/lidar_dump.csv", "w");
      for (const auto& p : f.board_points) std::fprintf(out, "b,%f,%f,%f\n", p.x(), p.y(), p.z());
      for (int j = 0; j < kNumEdges; ++j)
        for (const auto& p : f.edge_points[j])
          std::fprintf(out, "e%d,%f,%f,%f\n", j, p.x(), p.y(), p.z());
      for (int j = 0; j < kNumEdges; ++j)
        std::fprintf(out, "c%d,%f,%f,%f\n", j, truth.corners[j].x(), truth.corners[j].y(),
                     truth.corners[j].z());
      for (int j = 0; j < kNumEdges; ++j)
        std::fprintf(out, "d%d,%f,%f,%f\n", j, f.corners[j].x(), f.corners[j].y(),
                     f.corners[j].z());
      std::fclose(out);
    }
    for (int j = 0; j < kNumEdges; ++j) {
      const double e = edgeLineError(f, j, truth);
      r.max_edge_m = std::max(r.max_edge_m, e);
      r.sum_edge_m += e;
      ++r.edges_measured;
      r.edges_within += e < kMaxEdgeLineM;
    }
  }
  std::printf(
      "%-8s %-9s %-9s: found %d/%d, four edges %d, normal < 0.5 deg %d (max %.3f deg), edge line "
      "RMS < 1.5 cm "
      "%d/%d (mean %.4f max %.4f m)\n",
      lidar.c_str(), organized_with_ring ? "organized" : "flat", person ? "person" : "no person",
      r.found, r.frames, r.four_edges, r.normals_within, r.max_normal_deg, r.edges_within,
      r.edges_measured, r.edges_measured ? r.sum_edge_m / r.edges_measured : 0.0, r.max_edge_m);
  return r;
}

class SimSweep : public ::testing::TestWithParam<std::tuple<std::string, bool>> {};

TEST_P(SimSweep, PlaneAndEdgesMatchTruth) {
  const auto& [lidar, organized] = GetParam();
  // The board in a room, held still: every figure must meet the targets.
  const SweepResult clean = sweep(lidar, organized, false, kFrames, 7);
  EXPECT_GE(clean.found, kMinDetected);
  EXPECT_GE(clean.four_edges, kMinDetected);
  EXPECT_EQ(clean.normals_within, clean.found);
  EXPECT_EQ(clean.edges_within, clean.edges_measured);
  EXPECT_LT(clean.sum_edge_m / std::max(1, clean.edges_measured), 0.5 * kMaxEdgeLineM);
}

TEST_P(SimSweep, PersonBehindTheBoard) {
  const auto& [lidar, organized] = GetParam();
  // The simulated person is a box right behind the board; when the board is pitched it touches
  // (or passes through) the board's lower corner within the range noise of the plane, which a
  // detector cannot tell from the board. Detection must not suffer; at least 85 % of normals and
  // 90 % of edges must still meet the targets, the mean edge error stay within half the target,
  // and nothing may be grossly off.
  const SweepResult r = sweep(lidar, organized, true, kFrames, 7);
  EXPECT_GE(r.found, kMinDetected);
  EXPECT_GE(r.four_edges, kMinDetected - 1);
  EXPECT_GE(r.normals_within, (r.found * 85) / 100);
  EXPECT_GE(r.edges_within, (r.edges_measured * 90) / 100);
  EXPECT_LT(r.sum_edge_m / std::max(1, r.edges_measured), 0.5 * kMaxEdgeLineM);
  EXPECT_LT(r.max_normal_deg, 2 * kMaxNormalDeg);
  EXPECT_LT(r.max_edge_m, 4 * kMaxEdgeLineM);
}

INSTANTIATE_TEST_SUITE_P(Lidars, SimSweep,
                         ::testing::Combine(::testing::Values("VLP-16", "VLP-32C", "OS1-64"),
                                            ::testing::Bool()),
                         [](const auto& info) {
                           std::string name = std::get<0>(info.param) +
                                              (std::get<1>(info.param) ? "_organized" : "_flat");
                           name.erase(std::remove(name.begin(), name.end(), '-'), name.end());
                           return name;
                         });

// A board held nearly upright at arm's length in front of its holder: the body shows right
// below the board's lower side, and the voxels across that side mix both. The lower rim must
// stay on the board (PBPC's lower edge line is fitted to it).
struct RimCount {
  int rim_returns = 0, rim_kept = 0, frames = 0, found = 0;
  double worst_frame_share = 1.0;
};

RimCount lowerRimKept(const std::string& lidar, bool organized, unsigned seed, int frames) {
  Target target = plainBoard();
  target.width = 0.8;
  target.height = 0.6;
  const sim::LidarSpec s = spec(lidar, organized);
  sim::SceneSpec world = scene(target);
  world.occluder = true;
  std::mt19937 rng(seed);
  const PoseDraw upright{{1.9, 0.0, 0.0}, {0.5, 0.5, 0.2}, 0.0, 6.0, 25.0, 8.0};
  // The board's extent in its own coordinates.
  const auto outer = target.outerCorners();
  Eigen::Vector3d lo = outer[0], hi = outer[0];
  for (const auto& c : outer) {
    lo = lo.cwiseMin(c);
    hi = hi.cwiseMax(c);
  }
  RimCount r;
  for (int i = 0; i < frames; ++i) {
    Eigen::Isometry3d board;
    const LidarCloud cloud = drawCloud(s, world, target, upright, rng, &board);
    const LidarBoardDetection det = detectLidarBoard(cloud, target);
    ++r.frames;
    if (!det.features.found) {
      std::printf("%s frame %d: %s\n", lidar.c_str(), i, det.features.reason.c_str());
      continue;
    }
    ++r.found;
    // Returns on the board within 5 cm of its lowest side, in board coordinates.
    const Eigen::Isometry3d board_T_lidar = board.inverse();
    // The LiDAR's down direction in board coordinates: the lowest side is the one it points at.
    const Eigen::Vector3d down = board_T_lidar.linear() * -Eigen::Vector3d::UnitZ();
    const std::vector<Eigen::Vector3d>& kept = det.features.board_points;
    int rim = 0, rim_kept = 0;
    for (const auto& p : cloud.points) {
      if (!std::isfinite(p.x)) continue;
      const Eigen::Vector3d q(p.x, p.y, p.z);
      const Eigen::Vector3d b = board_T_lidar * q;
      if (std::abs(b.z()) > 0.02 || (b.head<2>().array() < lo.head<2>().array()).any() ||
          (b.head<2>().array() > hi.head<2>().array()).any())
        continue;
      // Distance to the side the "down" direction points at.
      const double along = down.head<2>().dot(b.head<2>() - 0.5 * (lo + hi).head<2>());
      const double reach =
          0.5 * (std::abs(down.x()) * (hi.x() - lo.x()) + std::abs(down.y()) * (hi.y() - lo.y()));
      if (reach - along > 0.05) continue;
      ++rim;
      for (const auto& k : kept)
        if ((k - q).squaredNorm() < 1e-10) {
          ++rim_kept;
          break;
        }
    }
    r.rim_returns += rim;
    r.rim_kept += rim_kept;
    if (rim > 0) r.worst_frame_share = std::min(r.worst_frame_share, double(rim_kept) / rim);
    if (std::getenv("LIDAR_TEST_VERBOSE"))
      std::printf("  %s %d: rim %d kept %d\n", lidar.c_str(), i, rim, rim_kept);
  }
  std::printf("%-8s %-9s: found %d/%d, lower rim returns kept %d/%d (worst frame %.2f)\n",
              lidar.c_str(), organized ? "organized" : "flat", r.found, r.frames, r.rim_kept,
              r.rim_returns, r.worst_frame_share);
  return r;
}

TEST(LidarDetectorSim, UprightBoardBeforeItsHolderKeepsItsLowerRim) {
  // Two draws of 20 clouds pooled per LiDAR. Before the holder's body was told from the board's
  // rim, seeds 11 and 12 kept 76 % (OS1-64; single clouds 6 %), 94 % (VLP-32C) and 94 %
  // (VLP-16); since, 98.5-99.7 %. Over other draws a LiDAR's 20 clouds keep 94-100 %: a voxel
  // that straddles the rim and holds many mixed returns still loses its rows now and then.
  const char* env_seed = std::getenv("LIDAR_TEST_SEED");
  const unsigned seed = env_seed ? static_cast<unsigned>(std::atoi(env_seed)) : 11u;
  for (const char* lidar : {"OS1-64", "VLP-32C", "VLP-16"})
    for (bool organized : {true, false}) {
      const RimCount a = lowerRimKept(lidar, organized, seed, 20);
      const RimCount b = lowerRimKept(lidar, organized, seed + 1, 20);
      EXPECT_EQ(a.found + b.found, a.frames + b.frames) << lidar;
      EXPECT_GE(a.rim_kept + b.rim_kept, 0.95 * (a.rim_returns + b.rim_returns)) << lidar;
    }
}

// Nearest return per direction of two organized scans of the same sensor: a scene with both
// boards (each scan sees one board and the same room).
LidarCloud mergeNearest(const LidarCloud& a, const LidarCloud& b) {
  LidarCloud out = a;
  for (size_t i = 0; i < a.points.size(); ++i) {
    const auto& p = a.points[i];
    const auto& q = b.points[i];
    const double ra = std::isfinite(p.x) ? std::hypot(p.x, p.y, p.z) : 1e9;
    const double rb = std::isfinite(q.x) ? std::hypot(q.x, q.y, q.z) : 1e9;
    if (rb < ra) out.points[i] = q;
  }
  return out;
}

TEST(LidarDetectorSim, NoBoardGivesAReason) {
  const Target target = plainBoard();
  const sim::LidarSpec s = spec("VLP-32C", true);
  std::mt19937 rng(3);
  // The board is placed outside the room: only floor, walls, ceiling and the person remain.
  const Eigen::Isometry3d far_away = boardPose(target, {40.0, 0.0, 0.0}, 45, 0, 0);
  const auto det = detectLidarBoard(
      sim::simulateLidarScan(s, Eigen::Isometry3d::Identity(), scene(target), far_away, rng),
      target);
  EXPECT_FALSE(det.features.found);
  EXPECT_TRUE(det.code == LidarDetectionCode::kWrongSize ||
              det.code == LidarDetectionCode::kNoPlane)
      << lidarDetectionCodeName(det.code) << ": " << det.features.reason;
  EXPECT_FALSE(det.features.reason.empty());
}

TEST(LidarDetectorSim, TwoBoardsAreAmbiguous) {
  const Target target = plainBoard();
  const sim::LidarSpec s = spec("OS1-64", true);
  sim::SceneSpec world = scene(target);
  world.occluder = false;
  std::mt19937 rng(4);
  const auto left = boardPose(target, {3.0, 1.0, 0.0}, 45, 10, 0);
  const auto right = boardPose(target, {3.0, -1.0, 0.0}, 40, -10, 0);
  const LidarCloud both =
      mergeNearest(sim::simulateLidarScan(s, Eigen::Isometry3d::Identity(), world, left, rng),
                   sim::simulateLidarScan(s, Eigen::Isometry3d::Identity(), world, right, rng));
  const auto det = detectLidarBoard(both, target);
  EXPECT_FALSE(det.features.found);
  EXPECT_EQ(det.code, LidarDetectionCode::kAmbiguous) << det.features.reason;
  EXPECT_NE(det.features.reason.find("ambiguous"), std::string::npos);
}

TEST(LidarDetectorSim, BackgroundModelKeepsOnlyTheNewBoard) {
  const Target target = plainBoard();
  sim::SceneSpec world = scene(target);
  world.occluder = false;
  const auto static_board = boardPose(target, {3.0, 1.0, 0.0}, 45, 10, 0);
  const auto held_board = boardPose(target, {3.0, -1.0, 0.0}, 40, -10, 5);
  for (const bool organized : {true, false}) {
    for (const bool with_ring : {true, false}) {
      if (organized && !with_ring) continue;
      sim::LidarSpec s = spec("VLP-32C", true);
      s.organized = organized;
      s.with_ring = with_ring;
      std::mt19937 rng(5);
      // Background: the room with a board-sized static panel (the first board), three scans.
      BackgroundModel background;
      for (int k = 0; k < 3; ++k) {
        const Status st = background.addFrame(
            sim::simulateLidarScan(s, Eigen::Isometry3d::Identity(), world, static_board, rng));
        ASSERT_TRUE(st.ok) << st.reason;
      }
      EXPECT_EQ(background.numFrames(), 3);
      // The empty scene again: almost nothing is new.
      const LidarCloud empty_again =
          sim::simulateLidarScan(s, Eigen::Isometry3d::Identity(), world, static_board, rng);
      const auto mask = background.foregroundMask(empty_again);
      int valid = 0, new_points = 0;
      for (size_t i = 0; i < mask.size(); ++i) {
        if (std::isfinite(empty_again.points[i].x)) ++valid;
        new_points += mask[i];
      }
      // Noise can push a few returns in front of the model (range margin 0.15 m = 15 sigma of
      // the VLP-32C's 1 cm noise; mixed returns at edges move more): well under 1 %.
      EXPECT_LT(new_points, valid / 100) << "organized " << organized << " ring " << with_ring;

      // Both boards present: without the model it is ambiguous, with it the held board is found.
      LidarCloud scene_cloud;
      const LidarCloud a =
          sim::simulateLidarScan(s, Eigen::Isometry3d::Identity(), world, static_board, rng);
      const LidarCloud b =
          sim::simulateLidarScan(s, Eigen::Isometry3d::Identity(), world, held_board, rng);
      if (organized) {
        scene_cloud = mergeNearest(a, b);
      } else {
        // Unorganized: the held board's scan, plus the static board's own returns.
        scene_cloud = b;
        const Truth st = truthOf(target, static_board);
        for (const auto& p : a.points)
          if (std::abs(st.plane.signedDistance(Eigen::Vector3d(p.x, p.y, p.z))) < 0.05 && p.y > 0.2)
            scene_cloud.points.push_back(p);
        scene_cloud.width = static_cast<int>(scene_cloud.points.size());
      }
      const auto without = detectLidarBoard(scene_cloud, target);
      EXPECT_EQ(without.code, LidarDetectionCode::kAmbiguous) << without.features.reason;
      const auto with = detectLidarBoard(scene_cloud, target, {}, &background);
      ASSERT_TRUE(with.features.found) << with.features.reason;
      const Truth truth = truthOf(target, held_board);
      EXPECT_LT(
          std::acos(std::min(1.0, with.features.plane.normal.dot(truth.plane.normal))) * kDegPerRad,
          0.5);
      EXPECT_NEAR(with.features.plane.offset, truth.plane.offset, 0.01);
      background.clear();
      EXPECT_TRUE(background.empty());
    }
  }
}

}  // namespace
}  // namespace board_calib
