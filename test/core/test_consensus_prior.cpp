// A second chance's prior without a first calibration (issue 14, 3a): the board is what moves.
// Synthetic sightings with a known extrinsic: the LiDAR's boards at spread positions, each moment
// with image candidates (the true board's centre with the PnP's depth noise in some moments, scene
// rectangles that stay put in every moment). The consensus must find the extrinsic when enough
// positions show the board, and refuse when only scene rectangles or too few positions agree.
#include <board_calib/core/pipeline/second_chance.h>
#include <board_calib/core/transform.h>

#include <gtest/gtest.h>

#include <random>

namespace board_calib {
namespace {

struct Session {
  BoardSightings sightings;
  Eigen::Isometry3d camera_T_lidar = Eigen::Isometry3d::Identity();
  Target target;
};

// `positions` holds of 4 moments each (10 Hz), 5-14 m, +-3 m lateral; the true board among the
// candidates in the first `showing` holds only; 3 static scene rectangles in every moment.
Session makeSession(unsigned seed, int positions, int showing) {
  std::mt19937 rng(seed);
  Session s;
  s.target.type = TargetType::kPlain;
  s.target.width = 0.89;
  s.target.height = 1.2;
  // LiDAR x forward, camera z forward.
  Eigen::Matrix3d R;
  R << 0, -1, 0, 0, 0, -1, 1, 0, 0;
  s.camera_T_lidar.linear() =
      Eigen::AngleAxisd(0.03, Eigen::Vector3d(0.3, 1, 0.2).normalized()).toRotationMatrix() * R;
  s.camera_T_lidar.translation() = Eigen::Vector3d(0.08, -0.12, -0.05);
  std::uniform_real_distribution<double> range(5.0, 14.0), lateral(-3.0, 3.0), height(-0.3, 0.6);
  std::normal_distribution<double> unit(0.0, 1.0);
  const double spacing_rad = 2.0 * M_PI / 180.0;  // VLP-16 line spacing
  const std::vector<Eigen::Vector3d> rectangles = {
      {-3.0, -1.5, 12.0}, {2.5, -1.0, 9.0}, {0.5, 0.5, 20.0}};  // camera frame, static
  double stamp = 100.0;
  for (int p = 0; p < positions; ++p) {
    const Eigen::Vector3d board(range(rng), lateral(rng), height(rng));  // LiDAR frame
    for (int m = 0; m < 4; ++m, stamp += 0.1) {
      LidarSighting lidar;
      lidar.line_spacing_m = spacing_rad * board.norm();
      lidar.centroid = board + Eigen::Vector3d(0, 0, 0.25 * lidar.line_spacing_m * unit(rng));
      s.sightings.clouds[stamp] = lidar;
      std::vector<BoardCandidate> candidates;
      const double depth = board.norm(), f = 1150.0;
      auto candidate = [&](const Eigen::Vector3d& centre) {
        BoardCandidate c;
        c.depth_sigma_m = depth * depth / (f * 0.89);
        c.lateral_sigma_m = depth / f;
        const Eigen::Vector3d ray = centre.normalized();
        c.centre = centre + ray * c.depth_sigma_m * unit(rng);
        return c;
      };
      if (p < showing) candidates.push_back(candidate(s.camera_T_lidar * board));
      for (const auto& r : rectangles) candidates.push_back(candidate(r));
      s.sightings.image_candidates[stamp + 0.004] = candidates;
    }
  }
  return s;
}

TEST(ConsensusPrior, TheMovingBoardFixesThePrior) {
  for (unsigned seed : {1u, 2u, 3u}) {
    const Session s = makeSession(seed, 12, 8);
    std::string why, summary;
    const auto prior = consensusPrior(s.sightings, 0.05, s.target, {}, &why, &summary);
    ASSERT_TRUE(prior.has_value()) << "seed " << seed << ": " << why;
    const double rot = rotationErrorDeg(prior->camera_T_lidar, s.camera_T_lidar);
    const double trans = translationErrorM(prior->camera_T_lidar, s.camera_T_lidar);
    // The truth within 3 of the prior's own sigmas (what the second chance's windows use).
    EXPECT_LE(rot, 3.0 * prior->rotation_sigma_rad * 180.0 / M_PI) << summary;
    EXPECT_LE(trans, 3.0 * (prior->translation_sigma_m + 10.0 * prior->rotation_sigma_rad))
        << summary;
    // Good enough to find far boards: within a few degrees and a few decimetres.
    EXPECT_LT(rot, 3.0);
    EXPECT_LT(trans, 0.3);
  }
}

TEST(ConsensusPrior, SceneRectanglesAloneGiveNoPrior) {
  for (unsigned seed : {1u, 2u, 3u}) {
    const Session s = makeSession(seed, 12, 0);
    std::string why, summary;
    EXPECT_FALSE(consensusPrior(s.sightings, 0.05, s.target, {}, &why, &summary).has_value())
        << summary;
    EXPECT_FALSE(why.empty());
  }
}

TEST(ConsensusPrior, TooFewPositionsShowingTheBoardGiveNoPrior) {
  const Session s = makeSession(4, 12, 3);  // 3 holds < min_consensus_boards (5)
  std::string why, summary;
  EXPECT_FALSE(consensusPrior(s.sightings, 0.05, s.target, {}, &why, &summary).has_value())
      << summary;
  EXPECT_NE(why.find("need 5"), std::string::npos) << why;
}

}  // namespace
}  // namespace board_calib
