// Solvers on synthetic features at known ground truth (issue 3 targets).
#include <board_calib/core/solvers/solvers.h>
#include <board_calib/core/transform.h>
#include "support/synthetic_views.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>

namespace board_calib {
namespace {

// 30 views, 2 cm range noise, 0.2 deg horizontal step, 0.3 px lines: the accuracy scenario.
sim::SyntheticFeatureOptions thirtyViewsAt2cmRangeNoise() {
  sim::SyntheticFeatureOptions o;
  o.num_views = 30;
  o.lidar_range_noise_m = 0.02;
  o.lidar_horizontal_resolution_deg = 0.2;
  o.line_noise_px = 0.3;
  return o;
}

sim::SyntheticScene makeScene(
    unsigned seed, const sim::SyntheticFeatureOptions& o = thirtyViewsAt2cmRangeNoise()) {
  std::mt19937 rng(seed);
  const Eigen::Isometry3d truth = sim::randomCameraTLidar(rng);
  auto scene = sim::generateSyntheticViews(o, truth, rng);
  EXPECT_TRUE(scene.ok()) << scene.error();
  return *scene;
}

struct Errors {
  double rot_deg;
  double trans_m;
};

Errors errors(const CalibrationSolution& sol, const Eigen::Isometry3d& truth) {
  return {rotationErrorDeg(sol.camera_T_lidar, truth),
          translationErrorM(sol.camera_T_lidar, truth)};
}

// Worst axis of `sol` off the truth in units of the 1 sigma that `covariance` gives.
double worstSigmas(const CalibrationSolution& sol, const Eigen::Isometry3d& truth,
                   const Matrix6d& covariance) {
  const Vector6d d = poseDelta(sol.camera_T_lidar, truth);
  double worst = 0.0;
  for (int i = 0; i < 6; ++i) worst = std::max(worst, std::abs(d(i)) / std::sqrt(covariance(i, i)));
  return worst;
}

TEST(Solvers, MethodNamesRoundTrip) {
  for (Method m : {Method::kPpc, Method::kPbpc, Method::kMsgPair}) {
    auto parsed = parseMethod(methodName(m));
    ASSERT_TRUE(parsed.ok());
    EXPECT_EQ(*parsed, m);
  }
  EXPECT_FALSE(parseMethod("icp").ok());
  EXPECT_FALSE(parseRobustLoss("l1").ok());
  EXPECT_TRUE(parseRobustLoss("Tukey").ok());
  SolverOptions bad;
  bad.loss_scale_m = 0.0;
  EXPECT_NE(bad.validate(), "");
  EXPECT_EQ(SolverOptions().validate(), "");
}

TEST(Solvers, SyntheticGeneratorIsConsistent) {
  const auto scene = makeScene(7);
  ASSERT_EQ(scene.views.size(), 30u);
  for (const View& v : scene.views) {
    // LiDAR board points lie on the true board plane within the range noise (4 sigma).
    const Plane truth = Plane{Eigen::Vector3d::UnitZ(), 0.0}.transformed(
        scene.camera_T_lidar.inverse() * scene.camera_T_board[v.id]);
    for (const auto& p : v.lidar.board_points) EXPECT_LT(std::abs(truth.signedDistance(p)), 0.08);
    EXPECT_GT(v.lidar.board_points.size(), 100u);
    int edges = 0;
    for (int j = 0; j < kNumEdges; ++j) edges += v.lidar.edge_valid[j] && v.camera.edge_valid[j];
    EXPECT_EQ(edges, 4) << "view " << v.id;
  }
  // With the true extrinsic the LiDAR edge points sit inside the image lines by up to one
  // horizontal step (~ 0.2 deg * f = 4 px at f = 1200): MLRE a few px, not tens.
  const auto mlre = meanLineReprojectionErrorPx(scene.views, scene.camera_T_lidar);
  ASSERT_TRUE(mlre.has_value());
  EXPECT_LT(*mlre, 4.0);
}

// PPC and PBPC within 0.2 deg / 1 cm of the truth over 10 seeds; PBPC not worse than PPC.
// (Camera planes from a PnP on the noisy corners; with the earlier distance-free plane noise,
// PPC's translation on one of the bench's 10 seeds was 11.1 mm off, about 3 sigma along its
// weakest direction by its own covariance: see docs/BENCHMARKS.md.)
TEST(Solvers, PpcAndPbpcRecoverGroundTruth) {
  SolverOptions options;
  double ppc_sum = 0.0, pbpc_sum = 0.0;
  for (unsigned seed = 1; seed <= 10; ++seed) {
    const auto scene = makeScene(seed);
    const auto ppc = calibrate(scene.views, Method::kPpc, options);
    const auto pbpc = calibrate(scene.views, Method::kPbpc, options);
    ASSERT_TRUE(ppc.success) << ppc.reason;
    ASSERT_TRUE(pbpc.success) << pbpc.reason;
    const Errors e_ppc = errors(ppc, scene.camera_T_lidar),
                 e_pbpc = errors(pbpc, scene.camera_T_lidar);
    EXPECT_LT(e_ppc.rot_deg, 0.2) << "seed " << seed;
    EXPECT_LT(e_ppc.trans_m, 0.01) << "seed " << seed;
    EXPECT_LT(e_pbpc.rot_deg, 0.2) << "seed " << seed;
    EXPECT_LT(e_pbpc.trans_m, 0.01) << "seed " << seed;
    ppc_sum += e_ppc.trans_m + e_ppc.rot_deg * kRadPerDeg;  // 1 rad ~ 1 m at the board distance
    pbpc_sum += e_pbpc.trans_m + e_pbpc.rot_deg * kRadPerDeg;
    EXPECT_TRUE(pbpc.mlre_px.has_value());
    EXPECT_TRUE(pbpc.used_closed_form_init);
    EXPECT_EQ(pbpc.views_used, 30);
  }
  // Summed over seeds so one lucky PPC draw does not decide it.
  EXPECT_LE(pbpc_sum, ppc_sum);
}

// A camera rolled 90 degrees (portrait) names the board's edges one place round from the LiDAR.
// PPC and MSG have no edge terms; their MLRE must still pair edges at their pose as the overlay
// does (PPC paired them by name: 100+ px on right results, and the verdict failed them; MSG
// weighted each edge's error by the other edge's point count).
TEST(Solvers, PlaneMethodsPairEdgesAtTheirPoseWhateverTheNames) {
  const auto scene = makeScene(3);
  std::vector<View> portrait = scene.views;
  for (View& v : portrait) {
    const auto lines = v.camera.edge_lines;
    const auto valid = v.camera.edge_valid;
    const auto corners = v.camera.corners_px;
    for (int j = 0; j < kNumEdges; ++j) {
      v.camera.edge_lines[j] = lines[(j + 1) % kNumEdges];
      v.camera.edge_valid[j] = valid[(j + 1) % kNumEdges];
      v.camera.corners_px[j] = corners[(j + 1) % kNumEdges];
    }
  }
  const SolverOptions options;
  for (Method m : {Method::kPpc, Method::kMsgPair}) {  // neither has edge terms
    const auto named = calibrate(scene.views, m, options);
    const auto rolled = calibrate(portrait, m, options);
    ASSERT_TRUE(named.success && rolled.success) << methodName(m);
    ASSERT_TRUE(named.mlre_px && rolled.mlre_px) << methodName(m);
    // The same planes give the same pose, and the same pairs the same MLRE (about 1 px here).
    EXPECT_LT(rotationErrorDeg(named.camera_T_lidar, rolled.camera_T_lidar), 1e-6);
    EXPECT_LT(*named.mlre_px, 2.0) << methodName(m);
    EXPECT_NEAR(*rolled.mlre_px, *named.mlre_px, 1e-6) << methodName(m);
    for (size_t i = 0; i < rolled.views.size(); ++i)
      EXPECT_NEAR(rolled.views[i].mlre_px.value_or(-1), named.views[i].mlre_px.value_or(-1), 1e-6)
          << methodName(m) << " view " << i;
  }
}

TEST(Solvers, PpcPlaneErrorModelBeatsPaperWeighting) {
  // The per-view camera plane error model against the paper's per-point 1/p_i weighting, summed
  // over 10 seeds: better rotation (the tilts are no longer under-weighted) and translation
  // (measured on these 10 seeds: squared errors 0.23 x rotation, 0.64 x translation; 0.73 x and
  // 1.00 x with the earlier distance-free camera plane noise).
  SolverOptions model, paper;
  paper.ppc_plane_error_model = false;
  double rot_model = 0, rot_paper = 0, trans_model = 0, trans_paper = 0;
  for (unsigned seed = 1; seed <= 10; ++seed) {
    const auto scene = makeScene(seed);
    const auto a = calibrate(scene.views, Method::kPpc, model);
    const auto b = calibrate(scene.views, Method::kPpc, paper);
    ASSERT_TRUE(a.success && b.success);
    rot_model += std::pow(errors(a, scene.camera_T_lidar).rot_deg, 2);
    rot_paper += std::pow(errors(b, scene.camera_T_lidar).rot_deg, 2);
    trans_model += std::pow(errors(a, scene.camera_T_lidar).trans_m, 2);
    trans_paper += std::pow(errors(b, scene.camera_T_lidar).trans_m, 2);
    bool noted = false;
    for (const auto& n : a.notes) noted |= n.find("camera plane error") != std::string::npos;
    EXPECT_TRUE(noted);
  }
  EXPECT_LT(rot_model, rot_paper);
  EXPECT_LT(trans_model, trans_paper);
  std::printf(
      "PPC squared errors, plane error model / paper weighting: rotation %.2f, translation %.2f\n",
      rot_model / rot_paper, trans_model / trans_paper);
}

TEST(Solvers, MsgPairwiseRecoversGroundTruth) {
  // The target is 0.5 deg / 2 cm; with the offsets compared at the boards and the views
  // weighted by distance it holds with a factor of two to spare on every seed (camera planes
  // from PnP; seed 21 was 26 mm with the offsets compared at the sensor origins).
  SolverOptions options;
  double worst_rot = 0.0, worst_trans = 0.0;
  for (unsigned seed : {1u, 2u, 3u, 4u, 5u, 6u, 7u, 8u, 9u, 10u, 21u}) {
    const auto scene = makeScene(seed);
    const auto msg = calibrate(scene.views, Method::kMsgPair, options);
    ASSERT_TRUE(msg.success) << msg.reason;
    const Errors e = errors(msg, scene.camera_T_lidar);
    EXPECT_LT(e.rot_deg, 0.25) << "seed " << seed;
    EXPECT_LT(e.trans_m, 0.01) << "seed " << seed;
    worst_rot = std::max(worst_rot, e.rot_deg);
    worst_trans = std::max(worst_trans, e.trans_m);
    // Quality figures as for the other methods (edges are not used by MSG, only measured).
    EXPECT_TRUE(msg.mlre_px.has_value());
    EXPECT_GT(msg.line_rms_mm, 0.0);
    EXPECT_GT(msg.plane_rms_mm, 0.0);
    EXPECT_TRUE(msg.covariance.allFinite());
  }
  std::printf("MSG pairwise, worst over 11 seeds: %.3f deg, %.1f mm\n", worst_rot,
              1000.0 * worst_trans);
}

TEST(Solvers, PlaneToPlaneBetweenTwoLidars) {
  // LiDAR <-> LiDAR: the same board planes seen by two LiDARs, exact then noisy.
  std::mt19937 rng(11);
  const auto scene = makeScene(5);
  const Eigen::Isometry3d a_T_b = perturb(Eigen::Isometry3d::Identity(), 0.5, 0.5, rng);
  std::vector<PlaneCorrespondence> c;
  for (const View& v : scene.views) {
    PlaneCorrespondence pc;
    pc.in_b = v.lidar.plane;
    pc.in_a = v.lidar.plane.transformed(a_T_b);
    c.push_back(pc);
  }
  const auto sol = solvePlaneToPlane(c, SolverOptions());
  ASSERT_TRUE(sol.success) << sol.reason;
  // Exact planes: only numerical error.
  EXPECT_LT(rotationErrorDeg(sol.a_T_b, a_T_b), 1e-6);
  EXPECT_LT(translationErrorM(sol.a_T_b, a_T_b), 1e-6);
}

TEST(Solvers, PlaneToPlaneBetweenTwoCameras) {
  // Camera <-> camera: the true board planes seen by two cameras, each with the synthetic
  // camera-plane noise (0.2 deg normal, 3 mm offset).
  std::mt19937 rng(12);
  const auto scene = makeScene(6);
  const Eigen::Isometry3d a_T_b = perturb(Eigen::Isometry3d::Identity(), 0.3, 0.4, rng);
  std::normal_distribution<double> noise(0.0, 1.0);
  auto noisy = [&](const Plane& p) {
    Plane out = p;
    out.normal = (p.normal + Eigen::Vector3d(noise(rng), noise(rng), noise(rng)) * 0.2 * kRadPerDeg)
                     .normalized();
    out.offset += 0.003 * noise(rng);
    return out;
  };
  std::vector<PlaneCorrespondence> c;
  for (size_t i = 0; i < scene.views.size(); ++i) {
    const Plane in_a = Plane{Eigen::Vector3d::UnitZ(), 0.0}.transformed(scene.camera_T_board[i]);
    PlaneCorrespondence pc;
    pc.in_a = noisy(in_a);
    pc.in_b = noisy(in_a.transformed(a_T_b.inverse()));
    c.push_back(pc);
  }
  const auto sol = solvePlaneToPlane(c, SolverOptions());
  ASSERT_TRUE(sol.success) << sol.reason;
  // The MSG target (0.5 deg / 2 cm) with noise on both sides.
  EXPECT_LT(rotationErrorDeg(sol.a_T_b, a_T_b), 0.5);
  EXPECT_LT(translationErrorM(sol.a_T_b, a_T_b), 0.02);
  EXPECT_TRUE(sol.covariance.allFinite());
  EXPECT_GT(sol.normal_rms_deg, 0.0);
  // Coplanar normals (all board normals in one plane) are rejected with the reason.
  std::vector<PlaneCorrespondence> coplanar;
  for (int i = 0; i < 6; ++i) {
    PlaneCorrespondence pc;
    pc.in_a.normal = Eigen::Vector3d(std::cos(0.3 * i), 0.0, std::sin(0.3 * i) + 1.0).normalized();
    pc.in_a.offset = 3.0;
    pc.in_b = pc.in_a;
    coplanar.push_back(pc);
  }
  const auto bad = solvePlaneToPlane(coplanar, SolverOptions());
  EXPECT_FALSE(bad.success);
  EXPECT_NE(bad.reason.find("coplanar"), std::string::npos) << bad.reason;
}

TEST(Solvers, ClosedFormInitialiserIsClose) {
  // The initialiser only has to land in the basin of convergence; with 30 noisy views it is
  // already within about a degree and a few centimetres.
  const auto scene = makeScene(2);
  for (Method m : {Method::kPpc, Method::kPbpc, Method::kMsgPair}) {
    const auto guess = closedFormInitialGuess(scene.views, m, SolverOptions());
    ASSERT_TRUE(guess.ok()) << guess.error();
    EXPECT_LT(rotationErrorDeg(*guess, scene.camera_T_lidar), 1.0) << methodName(m);
    EXPECT_LT(translationErrorM(*guess, scene.camera_T_lidar), 0.05) << methodName(m);
  }
}

// Robustness: Ceres from 100 random starts (rotation N(0, 90 deg), translation N(0, 50 cm)).
TEST(Solvers, RandomInitialisationRobustness) {
  const auto scene = makeScene(21);
  RobustnessOptions robustness;
  robustness.trials = 100;
  SolverOptions options;
  for (Method m : {Method::kPpc, Method::kPbpc, Method::kMsgPair}) {
    // Convergence to the method's own minimum (the solve from the closed-form start) within
    // 0.5 deg / 2 cm; accuracy against the truth is the other tests' business (MSG pairwise is
    // 7.6 mm off the truth on this seed with camera planes from PnP; 26 mm before its offsets
    // were compared at the boards).
    const auto report = evaluateRandomInitialisation(scene.views, m, options, robustness);
    ASSERT_TRUE(report.success) << report.reason;
    if (m == Method::kMsgPair)
      EXPECT_GE(report.convergence_rate, 0.95) << methodName(m);
    else
      EXPECT_EQ(report.convergence_rate, 1.0) << methodName(m);
  }
}

TEST(Solvers, DegenerateInputGivesSpecificReasons) {
  SolverOptions options;
  const auto scene = makeScene(3);
  // No views.
  auto sol = calibrate({}, Method::kPbpc, options);
  EXPECT_FALSE(sol.success);
  EXPECT_NE(sol.reason.find("no views"), std::string::npos) << sol.reason;
  // Too few views.
  std::vector<View> two(scene.views.begin(), scene.views.begin() + 2);
  sol = calibrate(two, Method::kPpc, options);
  EXPECT_FALSE(sol.success);
  EXPECT_NE(sol.reason.find("needs >= 3"), std::string::npos) << sol.reason;
  std::vector<View> one(scene.views.begin(), scene.views.begin() + 1);
  sol = calibrate(one, Method::kPbpc, options);
  EXPECT_FALSE(sol.success);
  EXPECT_NE(sol.reason.find("needs >= 2"), std::string::npos) << sol.reason;
  // All normals parallel: the same board pose repeated.
  std::vector<View> same(5, scene.views[0]);
  for (Method m : {Method::kPpc, Method::kPbpc, Method::kMsgPair}) {
    sol = calibrate(same, m, options);
    EXPECT_FALSE(sol.success) << methodName(m);
    EXPECT_NE(sol.reason.find("parallel"), std::string::npos)
        << methodName(m) << ": " << sol.reason;
  }
  // NaN in a view: that view is skipped with a reason; with too few left, the solve fails.
  std::vector<View> nan_views(scene.views.begin(), scene.views.begin() + 3);
  nan_views[1].lidar.board_points[4].x() = std::numeric_limits<double>::quiet_NaN();
  sol = calibrate(nan_views, Method::kPpc, options);
  EXPECT_FALSE(sol.success);
  EXPECT_NE(sol.reason.find("not finite"), std::string::npos) << sol.reason;
  // Empty views.
  std::vector<View> empty(4);
  for (Method m : {Method::kPpc, Method::kPbpc, Method::kMsgPair}) {
    sol = calibrate(empty, m, options);
    EXPECT_FALSE(sol.success) << methodName(m);
    EXPECT_FALSE(sol.reason.empty()) << methodName(m);
  }
  // A NaN guess.
  Eigen::Isometry3d nan_guess = Eigen::Isometry3d::Identity();
  nan_guess(0, 3) = std::numeric_limits<double>::quiet_NaN();
  sol = calibrate(scene.views, Method::kPbpc, options, nan_guess);
  EXPECT_FALSE(sol.success);
  EXPECT_NE(sol.reason.find("guess"), std::string::npos);
}

TEST(Solvers, CovarianceShrinksWithMoreViewsAndMatchesSpread) {
  SolverOptions options;
  auto o = thirtyViewsAt2cmRangeNoise();
  o.num_views = 40;
  const auto scene = makeScene(9, o);
  std::vector<View> few(scene.views.begin(), scene.views.begin() + 8);
  const auto sol_few = calibrate(few, Method::kPbpc, options);
  const auto sol_all = calibrate(scene.views, Method::kPbpc, options);
  ASSERT_TRUE(sol_few.success) << sol_few.reason;
  ASSERT_TRUE(sol_all.success) << sol_all.reason;
  EXPECT_LT(sol_all.stddev.translation_m.norm(), sol_few.stddev.translation_m.norm());
  EXPECT_LT(sol_all.stddev.rotation_deg.norm(), sol_few.stddev.rotation_deg.norm());
  EXPECT_TRUE(sol_all.observability.well_conditioned) << sol_all.observability.weakest_description;
  EXPECT_TRUE(sol_all.covariance.allFinite());

  // Monte Carlo: the predicted 1 sigma (Ceres covariance, cluster-robust) matches the spread of
  // the estimates around the truth over 30 noisy draws: RMS error / RMS predicted sigma within a
  // factor of 1.5, for the rotation and the translation of every method.
  constexpr int kDraws = 30;
  constexpr double kFactor = 1.5;
  for (Method m : {Method::kPpc, Method::kPbpc, Method::kMsgPair}) {
    double err_t = 0, pred_t = 0, err_r = 0, pred_r = 0;
    for (unsigned seed = 30; seed < 30 + kDraws; ++seed) {
      const auto s = makeScene(seed);
      const auto sol = calibrate(s.views, m, options);
      ASSERT_TRUE(sol.success) << sol.reason;
      ASSERT_TRUE(sol.covariance.allFinite());
      err_t += std::pow(translationErrorM(sol.camera_T_lidar, s.camera_T_lidar), 2);
      pred_t += sol.covariance.block<3, 3>(3, 3).trace();
      err_r += std::pow(rotationErrorDeg(sol.camera_T_lidar, s.camera_T_lidar) * kRadPerDeg, 2);
      pred_r += sol.covariance.block<3, 3>(0, 0).trace();
    }
    const double ratio_t = std::sqrt(err_t / pred_t), ratio_r = std::sqrt(err_r / pred_r);
    EXPECT_GT(ratio_t, 1.0 / kFactor) << methodName(m);
    EXPECT_LT(ratio_t, kFactor) << methodName(m);
    EXPECT_GT(ratio_r, 1.0 / kFactor) << methodName(m);
    EXPECT_LT(ratio_r, kFactor) << methodName(m);
    std::printf(
        "%s: RMS error / RMS predicted sigma over %d draws: translation %.2f, rotation %.2f\n",
        methodName(m), kDraws, ratio_t, ratio_r);
  }
}

TEST(Solvers, PbpcSchedulesAgreeFromTheInitialiser) {
  const auto scene = makeScene(6);
  SolverOptions joint, sequential;
  joint.pbpc_schedule = PbpcSchedule::kJoint;
  sequential.pbpc_schedule = PbpcSchedule::kSequential;
  const auto a = calibrate(scene.views, Method::kPbpc, joint);
  const auto b = calibrate(scene.views, Method::kPbpc, sequential);
  ASSERT_TRUE(a.success && b.success);
  // Same final cost function, same start: the same minimum up to solver tolerance.
  EXPECT_LT(rotationErrorDeg(a.camera_T_lidar, b.camera_T_lidar), 1e-3);
  EXPECT_LT(translationErrorM(a.camera_T_lidar, b.camera_T_lidar), 1e-4);
}

TEST(Solvers, RobustLossesAllConverge) {
  // Every selectable loss reaches the truth; a few gross outliers (points 1 m off the board)
  // are down-weighted by the robust ones.
  auto scene = makeScene(8);
  for (int i = 0; i < 10; ++i)
    scene.views[i].lidar.board_points[0] += Eigen::Vector3d(1.0, 0.0, 0.0);
  for (RobustLoss loss : {RobustLoss::kHuber, RobustLoss::kCauchy, RobustLoss::kTukey}) {
    SolverOptions options;
    options.loss = loss;
    const auto sol = calibrate(scene.views, Method::kPbpc, options);
    ASSERT_TRUE(sol.success) << robustLossName(loss) << ": " << sol.reason;
    EXPECT_LT(errors(sol, scene.camera_T_lidar).rot_deg, 0.2) << robustLossName(loss);
    EXPECT_LT(errors(sol, scene.camera_T_lidar).trans_m, 0.01) << robustLossName(loss);
  }
}

TEST(Solvers, GuessIsAccepted) {
  const auto scene = makeScene(10);
  std::mt19937 rng(3);
  const Eigen::Isometry3d guess = perturb(scene.camera_T_lidar, 0.2, 0.2, rng);
  const auto sol = calibrate(scene.views, Method::kPbpc, SolverOptions(), guess);
  ASSERT_TRUE(sol.success) << sol.reason;
  EXPECT_FALSE(sol.used_closed_form_init);
  EXPECT_TRUE(sol.initial_guess.isApprox(guess));
  EXPECT_LT(errors(sol, scene.camera_T_lidar).trans_m, 0.01);
}

TEST(Solvers, WeakDirectionDetected) {
  // Boards all facing the camera (tilt <= 3 deg, near the optical axis): the normals barely
  // differ, so PPC's translation across the normal is weak.
  auto o = thirtyViewsAt2cmRangeNoise();
  o.max_tilt_deg = 3.0;
  o.max_off_axis_fraction = 0.1;
  const auto scene = makeScene(4, o);
  SolverOptions options;
  options.min_normal_spread_deg = 0.1;  // let it solve, then check it reports the weakness
  const auto sol = calibrate(scene.views, Method::kPpc, options);
  ASSERT_TRUE(sol.success) << sol.reason;
  EXPECT_FALSE(sol.observability.well_conditioned) << sol.observability.weakest_description;
  // Two directions are weak here: the rotation about the optical axis (the normals barely
  // differ) and the translation across it. Which one is weakest depends on the camera plane
  // noise (PnP planes: the rotation, 1.3 deg; distance-free noise: the translation, 20 mm).
  const Vector6d& v = sol.observability.weakest_direction;
  const bool rotation_about_z = std::abs(v(2)) > 0.7,
             translation_across = v.segment<2>(3).norm() > 0.7;
  EXPECT_TRUE(rotation_about_z || translation_across) << v.transpose();
  EXPECT_NE(sol.observability.weakest_description.find(rotation_about_z ? "rotation about camera z"
                                                                        : "translation"),
            std::string::npos)
      << sol.observability.weakest_description;
}

TEST(Solvers, BoardSizeMismatchIsAbsorbedByPlaneScale) {
  auto o = thirtyViewsAt2cmRangeNoise();
  o.declared_size_factor = 1.0 / 1.03;  // declared 3 % too small, as on the real OS1 data
  const auto scene = makeScene(13, o);
  SolverOptions with_scale, without_scale;
  without_scale.estimate_plane_scale = false;
  const auto a = calibrate(scene.views, Method::kPbpc, with_scale);
  const auto b = calibrate(scene.views, Method::kPbpc, without_scale);
  ASSERT_TRUE(a.success && b.success);
  EXPECT_NEAR(a.plane_scale, 1.03, 0.01);
  EXPECT_LT(errors(a, scene.camera_T_lidar).trans_m, 0.01);
  EXPECT_LT(errors(a, scene.camera_T_lidar).trans_m, errors(b, scene.camera_T_lidar).trans_m);
  bool noted = false;
  for (const auto& n : a.notes) noted |= n.find("scaled by") != std::string::npos;
  EXPECT_TRUE(noted);
}

TEST(Solvers, EdgeReassociationFixesSwappedLabels) {
  auto scene = makeScene(17);
  // Swap two LiDAR edge labels in a few views.
  for (int i : {2, 5, 11})
    std::swap(scene.views[i].lidar.edge_points[0], scene.views[i].lidar.edge_points[1]);
  const auto sol = calibrate(scene.views, Method::kPbpc, SolverOptions());
  ASSERT_TRUE(sol.success) << sol.reason;
  EXPECT_LT(errors(sol, scene.camera_T_lidar).rot_deg, 0.2);
  EXPECT_LT(errors(sol, scene.camera_T_lidar).trans_m, 0.01);
  EXPECT_EQ(sol.views[2].edges[0].lidar_edge, 1);
}

// The features' LiDAR edge points are per-scan-line extremes without beam bloom: half a column
// step inside the board on average. The real-LiDAR options do not shift them (a real beam's bloom
// may cancel the inset), so the result carries that bias; its 1 sigma must hold it. An OS1-64's
// 0.35 deg columns, 2 cm range noise, 30 views.
TEST(Solvers, EdgeSamplingBiasEntersTheOneSigma) {
  sim::SyntheticFeatureOptions o = thirtyViewsAt2cmRangeNoise();
  o.lidar_horizontal_resolution_deg = 0.35;
  int beyond_without = 0;
  for (unsigned seed = 1; seed <= 4; ++seed) {
    const auto scene = makeScene(seed, o);
    const CalibrationSolution sol = calibrate(scene.views, Method::kPbpc, realLidarSolverOptions());
    ASSERT_TRUE(sol.success) << sol.reason;
    EXPECT_GT(sol.edge_bias_covariance.trace(), 0.0) << "seed " << seed;
    const double with =
        worstSigmas(sol, scene.camera_T_lidar, sol.covariance + sol.edge_bias_covariance);
    const double without = worstSigmas(sol, scene.camera_T_lidar, sol.covariance);
    std::printf("seed %u: %.1f mm off, worst axis %.1f sigma (%.1f without the bias term)\n", seed,
                translationErrorM(sol.camera_T_lidar, scene.camera_T_lidar) * 1e3, with, without);
    EXPECT_LE(with, 3.0) << "seed " << seed;
    beyond_without += without > 3.0;
  }
  // The bias is real: the model covariance alone does not hold it.
  EXPECT_GE(beyond_without, 3);
  // Without a bias range nothing is added (the synthetic defaults, which shift by half a step).
  const auto scene = makeScene(1, o);
  EXPECT_EQ(calibrate(scene.views, Method::kPbpc, SolverOptions{}).edge_bias_covariance.trace(),
            0.0);
}

}  // namespace
}  // namespace board_calib
