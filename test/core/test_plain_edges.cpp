// A plain board's edge must be straight (issue 14): the sub-pixel edge fit refuses a side whose
// samples bend beyond a held board's bow and their own noise (a printed disc's tangent, a side
// that runs on along an occluder at an angle, a hand on a far side), and keeps straight and gently
// bowed edges.
// Synthetic edges rendered at 4x and area-averaged, with noise.
#include "../../src/core/image_detection/plain_internal.h"

#include "sim_test_helpers.h"

#include <gtest/gtest.h>
#include <opencv2/imgproc.hpp>

#include <cmath>
#include <functional>
#include <string>
#include <utility>
#include <vector>

namespace board_calib {
namespace {

using image_detection::CoarseEdge;
using image_detection::EdgeFit;
using image_detection::refineEdge;

constexpr int kWidth = 640, kHeight = 480, kSuper = 4;
constexpr double kNoiseSigma = 2.0;  // grey levels

CameraModel pinhole() {
  return sim::makeCamera(kWidth, kHeight, 600, DistortionModel::kPlumbBob, {0, 0, 0, 0, 0});
}

// A bright region bounded by `outline` (px) on a darker background, rendered at kSuper x and
// area-averaged, with Gaussian noise.
cv::Mat render(const std::vector<std::vector<cv::Point2d>>& outlines) {
  cv::Mat big(kHeight * kSuper, kWidth * kSuper, CV_8UC1, cv::Scalar(80));
  for (const auto& outline : outlines) {
    std::vector<cv::Point> pts;
    for (const auto& p : outline)
      pts.emplace_back(cvRound((p.x + 0.5) * kSuper - 0.5), cvRound((p.y + 0.5) * kSuper - 0.5));
    cv::fillPoly(big, std::vector<std::vector<cv::Point>>{pts}, cv::Scalar(170), cv::LINE_8);
  }
  cv::Mat small;
  cv::resize(big, small, cv::Size(kWidth, kHeight), 0, 0, cv::INTER_AREA);
  cv::Mat noise(small.size(), CV_16S), wide;
  cv::randn(noise, 0, kNoiseSigma);
  small.convertTo(wide, CV_16S);
  wide += noise;
  wide.convertTo(small, CV_8U);
  return small;
}

// The upper side of a region whose top runs from (x0, y) to (x1, y) with `bend(s)` px added
// downwards at s in [0, 1] along it; the region reaches 150 px below.
std::vector<cv::Point2d> regionUnder(double x0, double x1, double y,
                                     const std::function<double(double)>& bend) {
  std::vector<cv::Point2d> outline;
  constexpr int kSteps = 400;
  for (int i = 0; i <= kSteps; ++i) {
    const double s = static_cast<double>(i) / kSteps;
    outline.emplace_back(x0 + s * (x1 - x0), y + bend(s));
  }
  outline.emplace_back(x1, y + 150);
  outline.emplace_back(x0, y + 150);
  return outline;
}

EdgeFit fitTop(const cv::Mat& image, double x0, double x1, double y, double inside_y,
               const ImageBoardDetectorOptions& o = {}) {
  CoarseEdge coarse;
  coarse.a = {x0, y + 1.0};  // a coarse side is a pixel or so off
  coarse.b = {x1, y - 1.0};
  coarse.angle = -M_PI / 2;
  coarse.length = x1 - x0;
  return refineEdge(image, pinhole(), coarse, {0.5 * (x0 + x1), inside_y}, o, 5.0);
}

// The top side of a region under the outline y + bend(s), with noise of draw `seed`, fitted.
EdgeFit fitBentTop(double x0, double x1, double y, const std::function<double(double)>& bend,
                   int seed) {
  cv::setRNGSeed(seed);
  return fitTop(render({regionUnder(x0, x1, y, bend)}), x0, x1, y, y + 40);
}

// Each outline (a name, its bend) under `draws` noise draws from `seed`: the top side is a board
// side within `tolerance` px of the edge at height y at both ends.
using Outline = std::pair<std::string, std::function<double(double)>>;
void expectSidesOnEdge(double x0, double x1, double y, const std::vector<Outline>& outlines,
                       int draws, int seed, double tolerance) {
  for (const auto& [name, bend] : outlines)
    for (int draw = 0; draw < draws; ++draw) {
      const EdgeFit fit = fitBentTop(x0, x1, y, bend, seed++);
      EXPECT_TRUE(fit.valid) << name << ": " << fit.reason;
      if (!fit.valid) continue;
      for (const double x : {x0, x1})
        EXPECT_LT(std::abs(fit.line.head<2>().dot(Eigen::Vector2d(x, y)) + fit.line.z()), tolerance)
            << name << " at x " << x;
    }
}

TEST(PlainEdges, StraightAndGentlyBowedEdgesAreBoardEdges) {
  cv::setRNGSeed(1);
  for (const double span : {60.0, 400.0}) {
    const double x0 = 120, x1 = x0 + span, y = 200.3;
    // Straight.
    {
      const EdgeFit fit =
          fitTop(render({regionUnder(x0, x1, y, [](double) { return 0.0; })}), x0, x1, y, y + 40);
      EXPECT_TRUE(fit.valid) << span << ": " << fit.reason;
      EXPECT_LT(std::abs(fit.bow), 0.3) << span;
    }
    // A held board's bow: 0.5 % of the side (2 px on 400 px, the most measured on real boards).
    {
      const double sagitta = 0.005 * span;
      const EdgeFit fit = fitTop(
          render({regionUnder(x0, x1, y, [&](double s) { return 4 * sagitta * s * (1 - s); })}), x0,
          x1, y, y + 40);
      EXPECT_TRUE(fit.valid) << span << ": " << fit.reason;
    }
  }
}

TEST(PlainEdges, AFloppyBoardPassesWithAHigherBowLimit) {
  // A 200 px side bowed by 2 % of its length (4 px, still within the edge inlier band and RMS):
  // bent at the default limit, a board side when the user allows a floppy board's bow
  // (max_edge_bow_fraction 3 %).
  cv::setRNGSeed(5);
  const double x0 = 120, x1 = 320, y = 200.3, sagitta = 0.02 * (x1 - x0);
  const cv::Mat image =
      render({regionUnder(x0, x1, y, [&](double s) { return 4 * sagitta * s * (1 - s); })});
  const EdgeFit strict = fitTop(image, x0, x1, y + 0.5 * sagitta, y + 60);
  EXPECT_FALSE(strict.valid);
  EXPECT_NE(strict.reason.find("edge bent"), std::string::npos) << strict.reason;
  ImageBoardDetectorOptions floppy;
  floppy.max_edge_bow_fraction = 0.03;
  const EdgeFit lenient = fitTop(image, x0, x1, y + 0.5 * sagitta, y + 60, floppy);
  EXPECT_TRUE(lenient.valid) << lenient.reason;
}

TEST(PlainEdges, APrintedDiscIsNotABoard) {
  // The tangent of a 56 px disc, as the side of the square around it (a 4:3 board turned 41 deg
  // fits that square): measured on an augmented real frame, its four sides passed every other
  // edge test.
  cv::setRNGSeed(2);
  constexpr double kRadius = 28, cx = 300.4, cy = 240.2;
  std::vector<cv::Point2d> disc;
  for (int i = 0; i < 720; ++i)
    disc.emplace_back(cx + kRadius * std::cos(i * M_PI / 360),
                      cy + kRadius * std::sin(i * M_PI / 360));
  const EdgeFit fit = fitTop(render({disc}), cx - kRadius, cx + kRadius, cy - kRadius, cy);
  EXPECT_FALSE(fit.valid);
  EXPECT_NE(fit.reason.find("edge bent"), std::string::npos) << fit.reason;
}

TEST(PlainEdges, ASideRunningOnAlongAnOccluderIsBent) {
  // The last 40 % of a 90 px side follows an occluder of the board's colour leaving it at 8 deg
  // (a leg or an arm under a far board): a line through both is several px off at its end.
  cv::setRNGSeed(3);
  constexpr double x0 = 200, x1 = 290, y = 150.6;
  const double slope = std::tan(8 * M_PI / 180) * (x1 - x0);
  const EdgeFit fit = fitTop(
      render(
          {regionUnder(x0, x1, y, [&](double s) { return s < 0.6 ? 0.0 : -(s - 0.6) * slope; })}),
      x0, x1, y, y + 40);
  EXPECT_FALSE(fit.valid);
  EXPECT_NE(fit.reason.find("edge bent"), std::string::npos) << fit.reason;
}

TEST(PlainEdges, AHandOnAFarSideIsDroppedFromIt) {
  // A hand over a fifth of a 90 px side, standing 2.5 px out of it: within the inlier band, so
  // the line follows it (on an augmented real frame, a hand so took a far side 9.6 px off at its
  // end). In the middle, the side is bent; off the middle, the line tilts and passed every test
  // 1.76 px off at an end. Its stretch dropped, the rest of the side is straight and on the edge.
  // The noise is measured between neighbouring samples: from the parabola's residuals, the bump's
  // own misfit made it look like noise and the bent side passed.
  std::vector<Outline> hands;
  for (const double at : {0.5, 0.35, 0.65})
    hands.emplace_back("hand at " + std::to_string(at),
                       [at](double s) { return std::abs(s - at) < 0.1 ? -2.5 : 0.0; });
  // 2 grey levels of noise on a 90-level step over ~30 samples: a few hundredths of a pixel;
  // 0.3 px bounds it with margin.
  expectSidesOnEdge(200, 290, 150.6, hands, 2, 40, 0.3);
}

TEST(PlainEdges, AnOutlineAlongAFarSidesEndIsNotPartOfIt) {
  // The last fifth of a 60 px side (a far board's) is an occluder's outline 1.5-2.5 px outside the
  // edge (a leg or a hand beside the corner): within the configured 3 px inlier band, and at an
  // end, where no stretch is dropped. The line leaned on it 0.4-1.2 px off at its ends. The
  // band of a side's fine passes is the bow a held board may have over it (1.5 % of its ~45 px of
  // samples) plus three sigmas of their noise: the outline lies outside it, and the line on the
  // edge (measured 0.11 px). 0.3 px bounds ~20 samples with 2 grey levels of noise on a 90-level
  // step and the 1/4 px outline drawing.
  std::vector<Outline> outlines;
  for (const double out : {1.5, 2.0, 2.5})
    outlines.emplace_back("outline " + std::to_string(out) + " px out",
                          [out](double s) { return s > 0.8 ? -out : 0.0; });
  expectSidesOnEdge(200, 260, 150.6, outlines, 3, 70, 0.3);
}

TEST(PlainEdges, AnEdgeBesideTheImageBorderIsFitUpToIt) {
  // A side 6-8 px below the image's upper border: the first pass's profiles (coarse_search_px,
  // 10 px each way) leave the image at every position. They used to be skipped, so a side near
  // an image corner had "too few edge pixels"; the part past the border is now flat, and the
  // position counts where the narrow search (fine_search_px) lies inside.
  cv::setRNGSeed(5);
  constexpr double x0 = 100, x1 = 500, y = 6.3, drop = 1.5;
  const EdgeFit fit = fitTop(render({regionUnder(x0, x1, y, [](double s) { return drop * s; })}),
                             x0, x1, y, y + 40);
  ASSERT_TRUE(fit.valid) << fit.reason;
  // The outline is drawn at 1/4 px; 400 px of samples with 2 grey levels of noise on a 90-level
  // step place the line to a few hundredths of a pixel: 0.15 px bounds it with margin.
  for (const auto& p : {Eigen::Vector2d(x0, y), Eigen::Vector2d(x1, y + drop)})
    EXPECT_LT(std::abs(fit.line.head<2>().dot(p) + fit.line.z()), 0.15) << p.transpose();
}

TEST(PlainEdges, ASideProposedOffItsEdgeIsCoveredAroundItsOwnPeaksLine) {
  // A weak lines' side 6 px off its edge at one end and 2 px at the other (a long merged line the
  // lens' residual bent): the look along the proposed line finds the edge only where it lies
  // within fine_search_px (3 px), about 5/8 of the side; around the line the side's own peaks fit
  // (searched coarse_search_px wide) it finds it all along.
  cv::setRNGSeed(6);
  constexpr double x0 = 120, x1 = 520, y = 200.3;
  const cv::Mat image = render({regionUnder(x0, x1, y, [](double) { return 0.0; })});
  const Eigen::Vector2d a(x0, y + 6.0), b(x1, y - 2.0), inside(0.5 * (x0 + x1), y + 40);
  const ImageBoardDetectorOptions o;
  const double along = image_detection::edgeCoverage(image, pinhole(), a, b, inside, o, 5.0);
  const double refit = image_detection::edgeCoverage(image, pinhole(), a, b, inside, o, 5.0, true);
  EXPECT_LT(along, 0.75);  // short of the weak lines' bar (measured 0.66)
  EXPECT_GT(refit, 0.95);  // measured 1.0
}

TEST(PlainEdges, AFarBoardsShortSideIsAnEdgeWhereItShowsHalfItsLength) {
  // A 30 px side (a board ~80 px across, or a side the image cuts): after the corner exclusions
  // its edge spans ~20 px, under min_edge_length_px (24 px), which refused it ("visible edge too
  // short (18 px)" on augmented real frames). A side that short needs the share of its length
  // the coverage asks of every side. The same side with its edge along its first third only (the
  // rest is background: another object's corner) stays refused.
  cv::setRNGSeed(7);
  constexpr double x0 = 300, x1 = 330, y = 200.3;
  const EdgeFit fit =
      fitTop(render({regionUnder(x0, x1, y, [](double) { return 0.0; })}), x0, x1, y, y + 20);
  ASSERT_TRUE(fit.valid) << fit.reason;
  // ~10 samples with 2 grey levels of noise on a 90-level step: a few hundredths of a pixel;
  // 0.3 px bounds it with margin.
  for (const auto& p : {Eigen::Vector2d(x0, y), Eigen::Vector2d(x1, y)})
    EXPECT_LT(std::abs(fit.line.head<2>().dot(p) + fit.line.z()), 0.3) << p.transpose();
  const EdgeFit third =
      fitTop(render({regionUnder(x0, x0 + 10, y, [](double) { return 0.0; })}), x0, x1, y, y + 20);
  EXPECT_FALSE(third.valid);
}

// A board whose grain or stripes meet its side: the region under the top side from (x0, y) to
// (x1, y) is `step` grey levels above the background on average, with stripes of +-`amplitude`
// `period` px apart whose normal lies at `angle` from the side, rendered like render().
cv::Mat renderStriped(double x0, double x1, double y, double step, double amplitude, double period,
                      double angle) {
  cv::Mat big(kHeight * kSuper, kWidth * kSuper, CV_32FC1, cv::Scalar(80));
  const double c = std::cos(angle), s = std::sin(angle);
  for (int r = 0; r < big.rows; ++r)
    for (int k = 0; k < big.cols; ++k) {
      const double u = (k + 0.5) / kSuper - 0.5, v = (r + 0.5) / kSuper - 0.5;
      if (u < x0 || u > x1 || v < y || v > y + 150) continue;
      big.at<float>(r, k) =
          static_cast<float>(80 + step + amplitude * std::sin(2 * M_PI * (u * c + v * s) / period));
    }
  cv::Mat small;
  cv::resize(big, small, cv::Size(kWidth, kHeight), 0, 0, cv::INTER_AREA);
  cv::Mat noise(small.size(), CV_32F);
  cv::randn(noise, 0, kNoiseSigma);
  small += noise;
  small.convertTo(small, CV_8U);
  return small;
}

TEST(PlainEdges, StripesMeetingAFaintSideNeverPutItOff) {
  // A 100 px side 12 grey levels above the background, with stripes of +-18 levels 4-6 px apart
  // meeting it at 20-40 deg (the augmented frames' far, faint, wood-grained board), under 45 noise
  // draws. One profile at a time, a stripe's flank inside the board outshines the edge where
  // the stripe is dark: before the averaged look, 5 of the 45 sides passed every test 2.0-4.8 px
  // off. Now a side either agrees with its averaged look (measured within 1.47 px of the truth,
  // 21 of 45) or is refused; 2 px bounds the agreement (half the 3 px inlier band) plus noise.
  constexpr double x0 = 200, x1 = 300, y = 150.6;
  int valid = 0;
  for (const double period : {4.0, 5.0, 6.0})
    for (const double angle_deg : {110.0, 120.0, 130.0})
      for (int seed = 8; seed < 13; ++seed) {
        cv::setRNGSeed(seed);
        const cv::Mat image = renderStriped(x0, x1, y, 12, 18, period, angle_deg * M_PI / 180);
        const EdgeFit fit = fitTop(image, x0, x1, y, y + 40);
        if (!fit.valid) {
          EXPECT_FALSE(fit.reason.empty());
          continue;
        }
        ++valid;
        for (const auto& p : {Eigen::Vector2d(x0, y), Eigen::Vector2d(x1, y)})
          EXPECT_LT(std::abs(fit.line.head<2>().dot(p) + fit.line.z()), 2.0)
              << period << " px, " << angle_deg << " deg, seed " << seed << " at " << p.transpose();
      }
  EXPECT_GE(valid, 18);  // measured 21: the check refuses the stripes' victims, not every side
}

TEST(PlainEdges, AStripedSideRefusedAloneIsTheAveragedLooks) {
  // Sides the single profiles refuse ("two edges along the side", "not straight") while their
  // line lies near the edge: the averaged look passes, agrees, and is the side (measured 0.11,
  // 0.22 and 0.14 px from the truth; refused without it). 0.5 px bounds ~40 averaged samples on
  // a 12-level step under the stripes' residue.
  constexpr double x0 = 200, x1 = 300, y = 150.6;
  struct Stripes {
    double period, angle_deg;
    int seed;
  };
  for (const Stripes& st : {Stripes{5, 120, 8}, Stripes{5, 110, 8}, Stripes{6, 130, 11}}) {
    cv::setRNGSeed(st.seed);
    const cv::Mat image = renderStriped(x0, x1, y, 12, 18, st.period, st.angle_deg * M_PI / 180);
    const EdgeFit fit = fitTop(image, x0, x1, y, y + 40);
    EXPECT_TRUE(fit.valid) << st.period << " px, " << st.angle_deg << " deg: " << fit.reason;
    if (!fit.valid) continue;
    for (const auto& p : {Eigen::Vector2d(x0, y), Eigen::Vector2d(x1, y)})
      EXPECT_LT(std::abs(fit.line.head<2>().dot(p) + fit.line.z()), 0.5)
          << st.period << " px, " << st.angle_deg << " deg at " << p.transpose();
  }
}

}  // namespace
}  // namespace board_calib
