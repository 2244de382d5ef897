// Consistency before solving and the verdict after it (issue 13): a good session is judged good
// and its reported 1 sigma covers its error; corrupted views are left out or the result refused;
// every fault of the sweep is failed or doubtful with a reason, never a silent success.
#include <board_calib/core/pipeline/pair_calibration.h>
#include <board_calib/core/transform.h>
#include "support/env_seeds.h"
#include "support/synthetic_views.h"

#include <gtest/gtest.h>
#include <Eigen/Eigenvalues>
#include <opencv2/calib3d.hpp>
#include <opencv2/core/eigen.hpp>

#include <cmath>
#include <cstdio>
#include <limits>
#include <random>
#include <regex>
#include <vector>

namespace board_calib {
namespace {

Target plainTarget() {
  Target t;
  t.type = TargetType::kPlain;
  t.width = t.height = 1.0;
  return t;
}

sim::SyntheticScene makeScene(unsigned seed, int views = 30, double range_noise_m = 0.02) {
  sim::SyntheticFeatureOptions o;
  o.num_views = views;
  o.lidar_range_noise_m = range_noise_m;
  std::mt19937 rng(seed);
  const Eigen::Isometry3d truth = sim::randomCameraTLidar(rng);
  auto scene = sim::generateSyntheticViews(o, truth, rng);
  EXPECT_TRUE(scene.ok()) << scene.error();
  return *scene;
}

PairCalibration run(const std::vector<View>& views, const std::string& method,
                    const std::optional<Eigen::Isometry3d>& guess = std::nullopt) {
  PairCalibrationOptions options;
  options.solver = SolverOptions{};  // the synthetic features' settings (edge shift on)
  return calibratePair(views, *parseMethods(method), plainTarget(), "camera", "lidar", options,
                       guess);
}

// Error in units of the reported 1 sigma, worst axis (rotation about the camera axes, translation).
double errorInSigmas(const PairCalibration& r, const Eigen::Isometry3d& truth) {
  const MethodRun* c = r.chosenRun();
  if (!c) return 0.0;
  const Eigen::AngleAxisd aa(c->solution.camera_T_lidar.linear() * truth.linear().transpose());
  const Eigen::Vector3d rot = aa.angle() * aa.axis() * kDegPerRad;
  const Eigen::Vector3d trans = c->solution.camera_T_lidar.translation() - truth.translation();
  double worst = 0;
  for (int i = 0; i < 3; ++i) {
    worst = std::max(worst, std::abs(rot(i)) / c->verdict.stddev.rotation_deg(i));
    worst = std::max(worst, std::abs(trans(i)) / c->verdict.stddev.translation_m(i));
  }
  return worst;
}

}  // namespace

TEST(Consistency, FindsTheConsensusAndTheCorruptedViews) {
  const auto scene = makeScene(3);
  std::vector<View> views = scene.views;
  // View 4: the LiDAR took a wall 1.5 m behind the board; view 9: the camera plane from another
  // region.
  for (auto& p : views[4].lidar.board_points) p += 1.5 * views[4].lidar.plane.normal;
  views[4].lidar.plane.offset += 1.5;
  views[9].camera.plane.normal =
      (Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitX()) * views[9].camera.plane.normal);
  const ConsistencyReport r = checkViewConsistency(views, plainTarget());
  ASSERT_TRUE(r.ok) << r.reason;
  EXPECT_TRUE(r.checkable);
  EXPECT_EQ(r.inconsistentIds(), (std::vector<int>{4, 9}));
  EXPECT_EQ(r.consistent_views, 28);
  // The consensus is a start, not the answer: within a degree and a few cm of the truth.
  EXPECT_LT(rotationErrorDeg(r.camera_T_lidar, scene.camera_T_lidar), 1.0);
  EXPECT_LT(translationErrorM(r.camera_T_lidar, scene.camera_T_lidar), 0.05);
  EXPECT_NE(r.views[4].reason.find("disagree"), std::string::npos) << r.views[4].reason;
}

TEST(Verdict, CleanSessionsAreGoodAndTheirSigmaCoversTheError) {
  for (unsigned seed = 1; seed <= 4; ++seed) {
    const auto scene = makeScene(seed);
    const PairCalibration r = run(scene.views, "all");
    ASSERT_FALSE(r.failed()) << r.reason;
    EXPECT_EQ(r.verdict, Verdict::kGood) << "seed " << seed << ": " << r.reason;
    ASSERT_NE(r.chosenRun(), nullptr);
    EXPECT_TRUE(r.chosenRun()->verdict.cross_validation.ran);
    // 3 sigma per axis: the acceptance rule of the issue for a reported success.
    EXPECT_LT(errorInSigmas(r, scene.camera_T_lidar), 3.0) << "seed " << seed;
    EXPECT_EQ(r.result.verdict, "good");
  }
}

// 20 % of the views corrupted three ways: the result stays accurate, or is refused with a reason.
TEST(Verdict, CorruptedViewsAreLeftOutOrTheResultRefused) {
  for (unsigned seed = 11; seed <= 14; ++seed) {
    auto scene = makeScene(seed);
    std::vector<View>& v = scene.views;
    std::mt19937 rng(seed);
    for (int k = 0; k < 6; ++k) {
      View& bad = v[static_cast<size_t>(5 * k + 1)];
      if (k % 3 == 0) {  // the LiDAR board is another object: a poster 1 m aside, turned 20 deg
        const Eigen::Isometry3d move =
            makeTransform(Eigen::AngleAxisd(0.35, Eigen::Vector3d::UnitZ()).toRotationMatrix(),
                          Eigen::Vector3d(0.3, 1.0, 0.2));
        for (auto& p : bad.lidar.board_points) p = move * p;
        for (auto& e : bad.lidar.edge_points)
          for (auto& p : e) p = move * p;
        bad.lidar.plane = bad.lidar.plane.transformed(move);
      } else if (k % 3 == 1) {  // the camera plane from the wrong region: another pose altogether
        bad.camera = v[static_cast<size_t>((5 * k + 13) % v.size())].camera;
      } else {  // moving board: the LiDAR saw it 0.3 s later, 25 cm and 8 deg further
        const Eigen::Isometry3d move =
            makeTransform(Eigen::AngleAxisd(0.14, Eigen::Vector3d::UnitY()).toRotationMatrix(),
                          Eigen::Vector3d(0.25, 0, 0));
        for (auto& p : bad.lidar.board_points) p = move * p;
        for (auto& e : bad.lidar.edge_points)
          for (auto& p : e) p = move * p;
        bad.lidar.plane = bad.lidar.plane.transformed(move);
      }
    }
    const PairCalibration r = run(v, "pbpc");
    if (r.failed()) {
      EXPECT_FALSE(r.reason.empty());
      continue;
    }
    const MethodRun* c = r.chosenRun();
    ASSERT_NE(c, nullptr);
    EXPECT_LT(rotationErrorDeg(c->solution.camera_T_lidar, scene.camera_T_lidar), 0.2)
        << "seed " << seed;
    EXPECT_LT(translationErrorM(c->solution.camera_T_lidar, scene.camera_T_lidar), 0.01)
        << "seed " << seed;
    EXPECT_LT(errorInSigmas(r, scene.camera_T_lidar), 3.0) << "seed " << seed;
    EXPECT_GE(r.consistency.inconsistentIds().size(), 5u) << "seed " << seed;
  }
}

namespace {

// Turns image side j about its first corner until its other end is `px` off; moves that corner
// and takes the camera plane from the corner PnP, as the plain detector gives them.
void tiltSide(int j, double px, CameraBoardFeatures* c) {
  const Eigen::Vector2d p0 = c->corners_px[(j + 3) % kNumEdges], d = c->corners_px[j] - p0;
  const Eigen::Vector2d dt = Eigen::Rotation2Dd(px / d.norm()) * d;
  Eigen::Vector2d n(-dt.y(), dt.x());
  n.normalize();
  if (n.dot(c->edge_lines[j].head<2>()) < 0) n = -n;  // keep the outward normal
  c->edge_lines[j] = Eigen::Vector3d(n.x(), n.y(), -n.dot(p0));
  const Eigen::Vector3d x = c->edge_lines[j].cross(c->edge_lines[(j + 1) % kNumEdges]);
  c->corners_px[j] = x.head<2>() / x.z();
  std::vector<cv::Point3d> object;
  std::vector<cv::Point2d> image;
  const auto outer = plainTarget().outerCorners();
  for (int i = 0; i < kNumEdges; ++i) {
    object.emplace_back(outer[i].x(), outer[i].y(), outer[i].z());
    image.emplace_back(c->corners_px[i].x(), c->corners_px[i].y());
  }
  cv::Mat K, rvec, tvec, R;
  cv::eigen2cv(c->K, K);
  ASSERT_TRUE(cv::solvePnP(object, image, K, cv::noArray(), rvec, tvec, false, cv::SOLVEPNP_IPPE));
  cv::Rodrigues(rvec, R);
  Eigen::Matrix3d board_R;
  Eigen::Vector3d board_t;
  cv::cv2eigen(R, board_R);
  cv::cv2eigen(tvec, board_t);
  Plane plane;
  plane.normal = board_R.col(2);
  plane.offset = plane.normal.dot(board_t);
  if (plane.normal.dot(c->plane.normal) < 0) {
    plane.normal = -plane.normal;
    plane.offset = -plane.offset;
  }
  c->plane = plane;
}

}  // namespace

// An image side fitted tilted (its edge fades along part of the side and clutter beside it pulls
// the line; docs/BENCHMARKS.md, "Session 9": 3 of 201 augmented real boards, 6-9 px at one end):
// nothing in one frame refuses it, so the session must absorb such views or say it cannot.
TEST(Verdict, ViewsWithATiltedImageSideAreAbsorbedOrTheResultRefused) {
  constexpr double kTiltPx = 8.0;  // at the far end of the side, the worst measured
  for (unsigned seed = 11; seed <= 14; ++seed) {
    auto scene = makeScene(seed);
    std::vector<View>& v = scene.views;
    for (size_t k = 3; k < v.size(); k += 5)  // 6 of 30 views, ten times the measured rate
      tiltSide(static_cast<int>(k / 5) % kNumEdges, kTiltPx, &v[k].camera);  // a side each time
    const PairCalibration r = run(v, "pbpc");
    std::printf("[tilted side] seed %u: %s %s\n", seed, verdictName(r.verdict), r.reason.c_str());
    // The consistency check before the solve names the tilted views (ids 3, 8, ..., 28).
    int named_tilted = 0;
    for (const int id : r.consistency.inconsistentIds()) named_tilted += id % 5 == 3;
    EXPECT_GE(named_tilted, 4) << "seed " << seed;
    if (r.failed()) {
      EXPECT_FALSE(r.reason.empty());
      continue;
    }
    const MethodRun* c = r.chosenRun();
    ASSERT_NE(c, nullptr);
    const double rot = rotationErrorDeg(c->solution.camera_T_lidar, scene.camera_T_lidar),
                 trans = translationErrorM(c->solution.camera_T_lidar, scene.camera_T_lidar);
    std::printf("[tilted side] seed %u: error %.3f deg %.1f mm, %.2f sigma\n", seed, rot,
                1e3 * trans, errorInSigmas(r, scene.camera_T_lidar));
    // The limits of the corrupted-views test above: a result given must stay right and be
    // covered by its own 1 sigma.
    EXPECT_LT(rot, 0.2) << "seed " << seed;
    EXPECT_LT(trans, 0.01) << "seed " << seed;
    EXPECT_LT(errorInSigmas(r, scene.camera_T_lidar), 3.0) << "seed " << seed;
  }
}

namespace {

// The fault sweep of issue 13: each case failed or doubtful with a reason, never good.
void faultSweep(unsigned seed) {
  SCOPED_TRACE("seed " + std::to_string(seed));
  const auto scene = makeScene(seed);
  const std::vector<View>& all = scene.views;
  struct Case {
    std::string name;
    std::vector<View> views;
    std::optional<Eigen::Isometry3d> guess;
    std::string method = "pbpc";
  };
  std::vector<Case> cases;
  Eigen::Isometry3d zero_quaternion = Eigen::Isometry3d::Identity();
  zero_quaternion.linear().setZero();
  Eigen::Isometry3d nan_guess = Eigen::Isometry3d::Identity();
  nan_guess.translation().x() = std::numeric_limits<double>::quiet_NaN();
  cases.push_back({"zero quaternion guess", all, zero_quaternion});
  cases.push_back({"NaN guess", all, nan_guess});
  for (int n = 1; n <= 3; ++n)
    cases.push_back({std::to_string(n) + " view(s)", {all.begin(), all.begin() + n}, {}});
  {
    std::vector<View> coplanar(8, all[0]);  // one board pose, eight times
    for (size_t i = 0; i < coplanar.size(); ++i) coplanar[i].id = static_cast<int>(i);
    cases.push_back({"coplanar views", coplanar, {}});
  }
  {
    std::vector<View> shuffled = all;  // camera and LiDAR features from different moments
    for (size_t i = 0; i < shuffled.size(); ++i)
      shuffled[i].camera = all[(i + 7) % all.size()].camera;
    cases.push_back({"shuffled pairing (infinite sync tolerance)", shuffled, {}});
  }
  {
    std::vector<View> swapped = all;  // the LiDAR features of another sensor mounted elsewhere
    const Eigen::Isometry3d other =
        makeTransform(Eigen::AngleAxisd(2.5, Eigen::Vector3d::UnitZ()).toRotationMatrix(),
                      Eigen::Vector3d(1.0, -2.0, 0.5));
    for (size_t i = 0; i < swapped.size(); i += 2) {
      for (auto& p : swapped[i].lidar.board_points) p = other * p;
      for (auto& e : swapped[i].lidar.edge_points)
        for (auto& p : e) p = other * p;
      swapped[i].lidar.plane = swapped[i].lidar.plane.transformed(other);
    }
    cases.push_back({"two LiDARs mixed", swapped, {}});
  }
  cases.push_back(
      {"far-off guess (180 deg)", all,
       makeTransform(Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitY()).toRotationMatrix(),
                     Eigen::Vector3d(3, 0, 0)) *
           scene.camera_T_lidar,
       "ppc"});
  int failed = 0, doubtful = 0, good_but_right = 0;
  for (const auto& c : cases) {
    const PairCalibration r = run(c.views, c.method, c.guess);
    std::printf("[fault sweep] %-45s %-8s %s\n", c.name.c_str(), verdictName(r.verdict),
                r.reason.c_str());
    EXPECT_FALSE(r.reason.empty()) << c.name;
    if (r.verdict == Verdict::kFailed)
      ++failed;
    else if (r.verdict == Verdict::kDoubtful)
      ++doubtful;
    else {
      // A good verdict is allowed only where the answer is right (a far guess Ceres recovers from).
      const MethodRun* run_ok = r.chosenRun();
      ASSERT_NE(run_ok, nullptr);
      EXPECT_LT(rotationErrorDeg(run_ok->solution.camera_T_lidar, scene.camera_T_lidar), 0.3)
          << c.name;
      EXPECT_LT(translationErrorM(run_ok->solution.camera_T_lidar, scene.camera_T_lidar), 0.02)
          << c.name;
      ++good_but_right;
    }
  }
  std::printf("[fault sweep] %zu cases: %d failed, %d doubtful, %d good and right\n", cases.size(),
              failed, doubtful, good_but_right);
  EXPECT_GE(failed + doubtful, static_cast<int>(cases.size()) - 1);
}

}  // namespace

TEST(Verdict, FaultSweepIsNeverASilentSuccess) {
  // Development aid: BOARD_CALIB_FAULT_SEEDS="1,2,3" sweeps other worlds.
  for (const unsigned seed : test_support::seedsFromEnv("BOARD_CALIB_FAULT_SEEDS", {21u}))
    faultSweep(seed);
}

// Residuals far beyond the noise model make the 1 sigma grow: biased camera planes (3 cm, every
// view a different way) must not come with a millimetre sigma.
TEST(Verdict, SigmaGrowsWhenResidualsExceedTheNoiseModel) {
  auto scene = makeScene(5);
  std::mt19937 rng(5);
  std::normal_distribution<double> offset(0.0, 0.03);
  for (auto& v : scene.views) v.camera.plane.offset += offset(rng);
  const PairCalibration r = run(scene.views, "ppc");
  ASSERT_NE(r.chosenRun(), nullptr) << r.reason;
  EXPECT_GT(r.chosenRun()->verdict.stddev_inflation, 1.5);
  EXPECT_LT(errorInSigmas(r, scene.camera_T_lidar), 3.0);
}

// PPC takes each camera plane's depth from the declared board size. Declared 1 % too large,
// every plane lies 1 % too far and the translation moves with it (measured before the check: a
// good verdict 41 mm off at 4 sigma on a simulated checkerboard session). The LiDAR measures the
// size: the result must name it and its 1 sigma cover the error. Declared right, nothing is
// named; declared 10 % off, it fails with a reason (the plane error model once divided by a zero
// variance there and Ceres reported "Residual and Jacobian evaluation failed").
// MSG pairwise puts the same camera planes against the LiDAR's and moved alike (42 mm off, with
// "add views" as the advice, before it had the check): the same holds.
TEST(Verdict, PpcAndMsgNameADeclaredBoardSizeTheLidarDisputes) {
  const std::regex named("declared ([0-9.]+) % too large");
  for (const std::string method : {"ppc", "msg"})
    for (unsigned seed = 31; seed <= 33; ++seed) {
      for (const double factor : {1.0, 1.01, 1.10}) {
        sim::SyntheticFeatureOptions o;
        o.declared_size_factor = factor;
        std::mt19937 rng(seed);
        const Eigen::Isometry3d truth = sim::randomCameraTLidar(rng);
        auto scene = sim::generateSyntheticViews(o, truth, rng);
        ASSERT_TRUE(scene.ok()) << scene.error();
        const PairCalibration r = run(scene->views, method);
        const std::string where = method + " seed " + std::to_string(seed) + " factor " +
                                  std::to_string(factor) + ": " + r.reason;
        EXPECT_EQ(r.reason.find("Ceres"), std::string::npos) << where;
        if (factor == 1.0) {
          // No false alarm (PPC alone may still be doubtful for its spread on some seeds).
          ASSERT_NE(r.chosenRun(), nullptr) << where;
          for (const auto& d : r.chosenRun()->verdict.details)
            EXPECT_EQ(d.find("declared"), std::string::npos) << where << ": " << d;
          EXPECT_LT(errorInSigmas(r, truth), 3.0) << where;
          continue;
        }
        EXPECT_NE(r.verdict, Verdict::kGood) << where;
        std::smatch m;
        ASSERT_TRUE(std::regex_search(r.reason, m, named)) << where;
        // The size the LiDAR measures: 1 sigma 0.1 % of the scale here (30 views, 2 cm range
        // noise).
        EXPECT_NEAR(std::stod(m[1]), (factor - 1.0) * 100.0, 0.35) << where;
        if (factor < 1.05) EXPECT_LT(errorInSigmas(r, truth), 3.0) << where;
      }
    }
}

// With every method (`all`), a depth scale PPC or MSG names holds for PBPC too: a focal length
// off moves all three alike, so they agree, and PBPC (which absorbs a wrong board size but not a
// wrong focal length) was chosen "good" 75 mm off (trust sweep 6, d21: focal length 2 % off).
// The data cannot tell the two causes apart, so no method is good while one names the scale.
TEST(Verdict, AScaleOneMethodNamesKeepsEveryMethodFromGood) {
  sim::SyntheticFeatureOptions o;
  o.declared_size_factor = 1.02;
  std::mt19937 rng(31);
  const Eigen::Isometry3d truth = sim::randomCameraTLidar(rng);
  auto scene = sim::generateSyntheticViews(o, truth, rng);
  ASSERT_TRUE(scene.ok()) << scene.error();
  const PairCalibration r = run(scene->views, "all");
  ASSERT_EQ(r.runs.size(), 3u) << r.reason;
  bool named = false;
  for (const auto& m : r.runs) named = named || !m.verdict.scale_finding.empty();
  ASSERT_TRUE(named) << r.reason;
  for (const auto& m : r.runs) {
    EXPECT_NE(m.verdict.verdict, Verdict::kGood)
        << methodName(m.solution.method) << ": " << m.verdict.reason;
    if (m.verdict.scale_finding.empty() && m.verdict.verdict == Verdict::kDoubtful) {
      EXPECT_NE(m.verdict.reason.find("a wrong focal length moves this result too"),
                std::string::npos)
          << m.verdict.reason;
    }
  }
  EXPECT_NE(r.verdict, Verdict::kGood) << r.reason;
}

// What the image lines become when the images still hold a radial distortion k1 that the
// camera_info does not undo: each side sampled, distorted, and fitted with a straight line; the
// camera plane from PnP on the corners they meet at.
void bendImageEdges(std::vector<View>* views, double k1) {
  for (View& v : *views) {
    CameraBoardFeatures& cam = v.camera;
    const double f = 0.5 * (cam.K(0, 0) + cam.K(1, 1));
    const Eigen::Vector2d c(cam.K(0, 2), cam.K(1, 2));
    const auto distort = [&](const Eigen::Vector2d& u) {
      const Eigen::Vector2d rho = (u - c) / f;
      return Eigen::Vector2d(u + f * k1 * rho.squaredNorm() * rho);
    };
    Eigen::Vector2d centre = Eigen::Vector2d::Zero();
    for (const auto& corner : cam.corners_px) centre += 0.25 * corner;
    std::array<Eigen::Vector3d, kNumEdges> lines;
    for (int j = 0; j < kNumEdges; ++j) {
      const Eigen::Vector2d a = cam.corners_px[static_cast<size_t>((j + 3) % 4)];
      const Eigen::Vector2d b = cam.corners_px[static_cast<size_t>(j)];
      std::vector<Eigen::Vector2d> pts;
      Eigen::Vector2d mean = Eigen::Vector2d::Zero();
      for (int i = 0; i <= 10; ++i) {
        pts.push_back(distort(a + (b - a) * (i / 10.0)));
        mean += pts.back() / 11.0;
      }
      Eigen::Matrix2d scatter = Eigen::Matrix2d::Zero();
      for (const auto& p : pts) scatter += (p - mean) * (p - mean).transpose();
      const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig(scatter);
      Eigen::Vector2d n = eig.eigenvectors().col(0);  // smallest: the line's normal
      if (n.dot(distort(centre) - mean) > 0) n = -n;  // outward: the interior gives < 0
      lines[static_cast<size_t>(j)] = Eigen::Vector3d(n.x(), n.y(), -n.dot(mean));
    }
    cam.edge_lines = lines;
    for (int j = 0; j < kNumEdges; ++j) {
      const Eigen::Vector3d p =
          lines[static_cast<size_t>(j)].cross(lines[static_cast<size_t>((j + 1) % 4)]);
      cam.corners_px[static_cast<size_t>(j)] = p.head<2>() / p.z();
    }
    // The camera plane: PnP on the bent corners, as the detector's would be.
    std::vector<cv::Point3d> object;
    std::vector<cv::Point2d> image;
    const auto outer = plainTarget().outerCorners();
    for (int i = 0; i < kNumEdges; ++i) {
      object.emplace_back(outer[i].x(), outer[i].y(), outer[i].z());
      image.emplace_back(cam.corners_px[i].x(), cam.corners_px[i].y());
    }
    cv::Mat K, rvec, tvec, R;
    cv::eigen2cv(cam.K, K);
    if (!cv::solvePnP(object, image, K, cv::noArray(), rvec, tvec, false, cv::SOLVEPNP_IPPE))
      continue;
    cv::Rodrigues(rvec, R);
    Eigen::Matrix3d board_R;
    Eigen::Vector3d board_t;
    cv::cv2eigen(R, board_R);
    cv::cv2eigen(tvec, board_t);
    Plane plane{board_R.col(2), board_R.col(2).dot(board_t)};
    if (plane.normal.dot(cam.plane.normal) < 0) {
      plane.normal = -plane.normal;
      plane.offset = -plane.offset;
    }
    cam.plane = plane;
  }
}

// A camera_info without the lens's distortion (or a rectified image with the raw camera_info)
// bends the board's image edges; PBPC fits them anyway and, seen on a simulated session with
// the plumb_bob coefficients left out, came out "good" 52 mm from the truth at 4.5 sigma. The
// edges' residuals keep the lens's radial pattern: it must be named. With the distortion right,
// nothing is named.
TEST(Verdict, PbpcNamesALensDistortionTheCameraInfoLeavesIn) {
  for (unsigned seed = 41; seed <= 43; ++seed) {
    for (const double k1 : {0.0, -0.08}) {
      sim::SyntheticScene scene = makeScene(seed, 20);
      bendImageEdges(&scene.views, k1);
      const PairCalibration r = run(scene.views, "pbpc");
      const std::string where =
          "seed " + std::to_string(seed) + " k1 " + std::to_string(k1) + ": " + r.reason;
      bool mentioned = r.reason.find("lens distortion") != std::string::npos;
      if (r.chosenRun())
        for (const auto& d : r.chosenRun()->verdict.details)
          mentioned |= d.find("lens distortion") != std::string::npos;
      if (k1 == 0.0) {
        ASSERT_NE(r.chosenRun(), nullptr) << where;
        EXPECT_FALSE(mentioned) << where;
        continue;
      }
      // Never good; with a result, the lens reported (heading the verdict, or in its details
      // when the result's 1 sigma already covers what it moves).
      EXPECT_NE(r.verdict, Verdict::kGood) << where;
      if (r.chosenRun()) {
        EXPECT_TRUE(mentioned) << where;
      }
      // LiDAR edges alone cannot tell the lens from edge returns off the board's edges
      // (blended returns gave k1 -0.03 in a simulated session whose camera_info was right):
      // wherever the finding is given, both causes are named.
      std::vector<std::string> texts{r.reason};
      if (r.chosenRun()) texts = r.chosenRun()->verdict.details;
      for (const std::string& t : texts) {
        if (t.find("lens distortion") == std::string::npos) continue;
        EXPECT_NE(t.find("the LiDAR's edge returns lie off the board's edges"), std::string::npos)
            << where;
      }
    }
  }
}

// Checkerboard corners as a detector reports them from images that still hold the radial
// distortion k1 (0.1 px noise), with the board pose PnP fits to them.
void addPattern(sim::SyntheticScene* scene, double k1, double w, double h, std::mt19937& rng) {
  std::normal_distribution<double> noise(0.0, 0.1);
  for (size_t i = 0; i < scene->views.size(); ++i) {
    CameraBoardFeatures& cam = scene->views[i].camera;
    const double f = 0.5 * (cam.K(0, 0) + cam.K(1, 1));
    const Eigen::Vector2d c(cam.K(0, 2), cam.K(1, 2));
    std::vector<cv::Point3d> object;
    std::vector<cv::Point2d> image;
    cam.pattern.clear();
    for (int row = 0; row < 5; ++row)
      for (int col = 0; col < 7; ++col) {
        const Eigen::Vector3d b(w * (0.15 + 0.7 * col / 6.0), h * (0.15 + 0.7 * row / 4.0), 0.0);
        const Eigen::Vector3d q = cam.K * (scene->camera_T_board[i] * b);
        Eigen::Vector2d u = q.head<2>() / q.z();
        const Eigen::Vector2d rho = (u - c) / f;
        u += f * k1 * rho.squaredNorm() * rho + Eigen::Vector2d(noise(rng), noise(rng));
        PatternObservation obs;
        obs.id = row * 7 + col;
        obs.board_point = b;
        obs.pixel = u;
        cam.pattern.push_back(obs);
        object.emplace_back(b.x(), b.y(), b.z());
        image.emplace_back(u.x(), u.y());
      }
    cv::Mat K, rvec, tvec, R;
    cv::eigen2cv(cam.K, K);
    ASSERT_TRUE(cv::solvePnP(object, image, K, cv::noArray(), rvec, tvec));
    cv::Rodrigues(rvec, R);
    Eigen::Matrix3d board_R;
    Eigen::Vector3d board_t;
    cv::cv2eigen(R, board_R);
    cv::cv2eigen(tvec, board_t);
    cam.camera_T_board.linear() = board_R;
    cam.camera_T_board.translation() = board_t;
  }
}

// The corners of a pattern board show the same bend without the LiDAR (k1 -0.113 +- 0.002, 79 %
// of the corners' residual on the simulated checkerboard session with its k1 -0.12 left out;
// the real checkerboard recording: 0.0005 +- 0.011, 0 %). Named for every method; nothing with
// the distortion right. Measured here: -0.130 to -0.132 +- 0.003 (62-75 %) for -0.12.
TEST(Verdict, PatternCornersNameALensDistortionTheCameraInfoLeavesIn) {
  for (unsigned seed = 51; seed <= 53; ++seed) {
    for (const double k1 : {0.0, -0.12}) {
      sim::SyntheticFeatureOptions o;
      o.num_views = 20;
      std::mt19937 rng(seed);
      const Eigen::Isometry3d truth = sim::randomCameraTLidar(rng);
      auto scene = sim::generateSyntheticViews(o, truth, rng);
      ASSERT_TRUE(scene.ok()) << scene.error();
      addPattern(&*scene, k1, o.board_width_m, o.board_height_m, rng);
      const PairCalibration r = run(scene->views, "ppc");
      ASSERT_NE(r.chosenRun(), nullptr) << r.reason;
      const std::string where =
          "seed " + std::to_string(seed) + " k1 " + std::to_string(k1) + ": " + r.reason;
      bool mentioned = false;
      for (const auto& d : r.chosenRun()->verdict.details)
        mentioned |= d.find("corners bend") != std::string::npos;
      EXPECT_EQ(mentioned, k1 != 0.0) << where;
      if (k1 != 0.0) EXPECT_NE(r.verdict, Verdict::kGood) << where;
    }
  }
}

// A LiDAR range offset moves every board plane along its view: PPC and MSG follow it with
// residuals as the noise predicts (3 cm on a simulated checkerboard session: both "good" 31 mm
// off at 5-24 sigma), while PBPC's edges hardly move. Asked alone, they are checked against
// PBPC on the same views: doubtful with the offset, nothing said without it.
TEST(Verdict, PlaneMethodsAskedAloneAreCheckedAgainstPbpc) {
  for (unsigned seed = 61; seed <= 63; ++seed) {
    for (const double delta : {0.0, 0.05}) {
      for (const std::string method : {"ppc", "msg"}) {
        sim::SyntheticScene scene = makeScene(seed, 20);
        for (View& v : scene.views) sim::lengthenRanges(&v.lidar, delta);
        const PairCalibration r = run(scene.views, method);
        ASSERT_NE(r.chosenRun(), nullptr) << r.reason;
        const std::string where = method + " seed " + std::to_string(seed) + " delta " +
                                  std::to_string(delta) + ": " + r.reason;
        bool checked = false;
        for (const auto& d : r.chosenRun()->verdict.details)
          checked |= d.find("pbpc differs") != std::string::npos;
        EXPECT_EQ(checked, delta != 0.0) << where;
        if (delta != 0.0) EXPECT_NE(r.verdict, Verdict::kGood) << where;
        EXPECT_EQ(r.runs.size(), 1u) << where;  // the check is not a run of its own
      }
    }
  }
}

// An uncertainty nobody could compute is not a zero one: without the solver's covariance and
// without a cross-validation (every re-solve fails) the result is refused, never good with 0 sigma.
TEST(Verdict, UnknownUncertaintyIsRefused) {
  const auto scene = makeScene(21, 12);
  const PairCalibration full = run(scene.views, "ppc");
  ASSERT_NE(full.chosenRun(), nullptr) << full.reason;
  const ConsistencyReport consistency = checkViewConsistency(scene.views, plainTarget());
  const auto no_resolve = [](const std::vector<View>&) { return CalibrationSolution{}; };
  const auto judged = [&](const Matrix6d& covariance) {
    CalibrationSolution sol = full.chosenRun()->solution;
    sol.covariance = covariance;
    return judgeSolution(sol, scene.views, plainTarget(), consistency, no_resolve);
  };
  const std::string unknown = "no uncertainty could be computed";
  const auto mentions = [&](const VerdictReport& r) {
    if (r.reason.find(unknown) != std::string::npos) return true;
    for (const auto& d : r.details)
      if (d.find(unknown) != std::string::npos) return true;
    return false;
  };
  for (const double value : {std::numeric_limits<double>::infinity(), 0.0}) {
    const VerdictReport r = judged(Matrix6d::Constant(value));
    EXPECT_EQ(r.verdict, Verdict::kFailed) << value;
    EXPECT_TRUE(mentions(r)) << value << ": " << r.reason;
  }
  // The solver's own covariance alone is an uncertainty: not refused for that reason.
  const VerdictReport known = judged(full.chosenRun()->solution.covariance);
  EXPECT_GT(known.stddev.translation_m.minCoeff(), 0.0);
  EXPECT_FALSE(mentions(known)) << known.reason;
}

// Few far views (4 at 6-10 m, 32 scan lines over 30 deg): the error a view shares across its
// points (the camera's board pose, the LiDAR's edge sampling at 3 cm per column) dominates, and
// four views cannot be cross-validated. Such a result is never good, and its 1 sigma, the noise
// model's alone, mostly covers the error: measured 24 of 28 seeds within 3 sigma on the worst of
// the 6 axes (a Gaussian would give 98 %), worst 6.7 sigma. This is why it stays doubtful.
// PPC on four views: its covariance (robust to a view's shared plane error) needs more views
// than the pose's 6 unknowns, and four cannot be cross-validated. The failure names the count,
// not the geometry ("the views do not determine the calibration" said before, wrongly).
TEST(Verdict, FourPpcViewsFailNamingTheCount) {
  sim::SyntheticFeatureOptions o;
  o.num_views = 4;
  std::mt19937 rng(7);
  const Eigen::Isometry3d truth = sim::randomCameraTLidar(rng);
  const auto scene = sim::generateSyntheticViews(o, truth, rng);
  ASSERT_TRUE(scene.ok()) << scene.error();
  const PairCalibration r = run(scene->views, "ppc");
  EXPECT_TRUE(r.failed());
  EXPECT_NE(r.reason.find("4 views are too few"), std::string::npos) << r.reason;
  EXPECT_EQ(r.reason.find("do not determine"), std::string::npos) << r.reason;
}

TEST(Verdict, FewFarViewsStayDoubtful) {
  int solved = 0, within3 = 0, good = 0;
  double worst = 0.0;
  for (unsigned seed = 100; seed < 130; ++seed) {
    sim::SyntheticFeatureOptions o;
    o.num_views = 4;
    o.min_distance_m = 6.0;
    o.max_distance_m = 10.0;
    o.lidar_rings = 32;
    o.lidar_vertical_fov_deg = 30.0;
    o.lidar_range_noise_m = 0.03;
    std::mt19937 rng(seed);
    const Eigen::Isometry3d truth = sim::randomCameraTLidar(rng);
    const auto scene = sim::generateSyntheticViews(o, truth, rng);
    if (!scene.ok()) {  // too few poses fit both fields of view for this seed
      std::printf("[few far] seed %u: %s\n", seed, scene.error().c_str());
      continue;
    }
    const PairCalibration r = run(scene->views, "pbpc");
    if (r.failed() || !r.chosenRun()) {
      std::printf("[few far] seed %u: failed: %s\n", seed, r.reason.c_str());
      continue;
    }
    ++solved;
    good += r.verdict == Verdict::kGood;
    const double e = errorInSigmas(r, truth);
    within3 += e < 3.0;
    worst = std::max(worst, e);
    const VerdictReport& v = r.chosenRun()->verdict;
    std::printf(
        "[few far] seed %u: %s, %.3f deg / %.1f mm, worst axis %.1f sigma (1 sigma %.3f deg / "
        "%.1f mm)\n",
        seed, verdictName(r.verdict),
        rotationErrorDeg(r.chosenRun()->solution.camera_T_lidar, truth),
        1e3 * translationErrorM(r.chosenRun()->solution.camera_T_lidar, truth), e,
        v.stddev.rotation_deg.maxCoeff(), 1e3 * v.stddev.translation_m.maxCoeff());
  }
  std::printf("[few far] %d solved, %d within 3 sigma, %d good, worst %.1f sigma\n", solved,
              within3, good, worst);
  ASSERT_GE(solved, 20);
  // Four views cannot be cross-validated: never good.
  EXPECT_EQ(good, 0);
  // The measured 86 %, less a seed's worth: a smaller model 1 sigma would show here first.
  EXPECT_GE(within3, 0.8 * solved);
}

}  // namespace board_calib
