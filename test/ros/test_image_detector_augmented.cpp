// Plain board detector on augmented REAL frames (issue 14): the frames of basler_os1_plain and
// rs16_plain with the board recoloured, its contrast lowered, printed marks or wood grain added,
// the background changed, the frame shrunk to a 5-15 m equivalent (board 80-250 px), legs and a
// hand over the lower part of the board, and combinations; the reference lines are carried
// through every geometric change. Each case must find four edges within 1 px of the reference;
// the frames with the board blanked out must give "not found".
// References: basler_os1_plain, the independent lines of ../shared/tools/mlre (never used by the
// detector); rs16_plain, the detector's lines found inside corners picked by eye on the clean
// frame (no independent lines exist; its README measured them straight to 0.2-0.4 px).
// Frames and augmentations: augmented_frames.h.
// Set BOARD_CALIB_DEBUG_DIR to write the debug images and the augmented frames there.
#include "augmented_frames.h"

#include <board_calib/core/image_detection/image_board_detector.h>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdlib>
#include <ctime>
#include <filesystem>
#include <optional>
#include <random>
#include <string>
#include <vector>

namespace board_calib {
namespace {

using augmented::Case;
using augmented::Frame;
using namespace augmented;  // the Op names of the case table

const std::vector<Case>& kCases = augmentedCases();
constexpr unsigned kDefaultSeed = 14;  // the augmentation draw the floors are measured on

void writeDebug(const std::string& name, const cv::Mat& image, const CameraModel& camera,
                const ImageDetection& det) {
  const char* dir = std::getenv("BOARD_CALIB_DEBUG_DIR");
  if (!dir) return;
  std::filesystem::create_directories(dir);
  cv::imwrite(std::string(dir) + "/" + name + ".png", drawImageDetection(image, camera, det));
  cv::imwrite(std::string(dir) + "/" + name + "_raw.png", image);
}

// Each reference segment's ends measured on the found line of the same name (a wrong board or a
// wrong name is far off); prints the edges over 1 px.
struct EdgeScore {
  int edges = 0, within = 0;
  double worst = 0;
};

// Development aid (BOARD_CALIB_AUG_RESIDUALS set): an edge's inliers in order along its
// reference side, each as "position:residual from the reference/residual from the fitted line"
// (undistorted px): where a hand or a leg pulled the line, and how far.
void printResiduals(const Frame& f, const ImageDetection& det, int j) {
  const CameraModel camera = f.camera();
  const Eigen::Vector3d& ref = f.lines[j];
  const Eigen::Vector3d& fit = det.features.edge_lines[j];
  const Eigen::Vector2d dir(-ref.y(), ref.x());
  std::vector<std::array<double, 3>> rows;
  for (const auto& raw : det.details.edge_points_raw[j]) {
    const Eigen::Vector2d u = camera.undistortPixel(raw);
    rows.push_back({dir.dot(u), ref.head<2>().dot(u) + ref.z(), fit.head<2>().dot(u) + fit.z()});
  }
  std::sort(rows.begin(), rows.end());
  std::printf("    reference side from %.0f to %.0f; inliers:", dir.dot(f.segments[j][0]),
              dir.dot(f.segments[j][1]));
  for (const auto& r : rows) std::printf(" %.0f:%.2f/%.2f", r[0], r[1], r[2]);
  std::printf("\n");
}

EdgeScore scoreEdges(const Frame& f, const ImageDetection& det, const std::string& case_name) {
  const CameraBoardFeatures& fe = det.features;
  EdgeScore s;
  for (int j = 0; j < kNumEdges; ++j) {
    const double dist = edgeErrorPx(f, fe, j);
    const double along = f.lines[j].head<2>().dot(fe.edge_lines[j].head<2>());
    ++s.edges;
    s.within += dist <= 1.0;
    s.worst = std::max(s.worst, dist);
    if (dist > 1.0)
      std::printf(
          "  edge %-10s %s %s: %.2f px (normals' cosine %.3f, bow %.1f +- %.1f px over %.0f)\n",
          f.name.c_str(), case_name.c_str(), edgeName(j), dist, along, det.details.edge_bow_px[j],
          det.details.edge_bow_sigma_px[j], det.details.edge_span_px[j]);
    // Development aid: a side named otherwise (1000) next to the found lines under any name,
    // which tells a quarter-turn naming of the board from another object.
    if (dist >= 1e3 && std::getenv("BOARD_CALIB_AUG_DIAG")) {
      std::printf("    found lines under any name:");
      for (int k = 0; k < kNumEdges; ++k)
        std::printf(" %s %.2f px", edgeName(k), segmentDistancePx(f, j, fe.edge_lines[k]));
      std::printf("\n");
    }
    if (dist > 1.0 && dist < 1e3 && std::getenv("BOARD_CALIB_AUG_RESIDUALS"))
      printResiduals(f, det, j);
  }
  return s;
}

// Per reference side: the share of its visible length whose grey-level step across the line
// (largest 1 px difference within 2 px of it) reaches the detector's weakest edge gradient (its
// minEdgeGradient at the defaults), and that step's median: a side without it cannot be found by
// its edge, a miss with it is the detector's.
void printSideSteps(const Frame& f, const ImageDetection& d) {
  const CameraModel camera = f.camera();
  const ImageBoardDetectorOptions defaults;
  const double min_gradient = std::max(defaults.min_edge_contrast,
                                       defaults.edge_snr * std::sqrt(2.0) * d.details.noise_sigma);
  cv::Mat grey;
  if (f.image.channels() == 3)
    cv::cvtColor(f.image, grey, cv::COLOR_BGR2GRAY);
  else
    grey = f.image.clone();
  grey.convertTo(grey, CV_32F);
  auto at = [&](const Eigen::Vector2d& u) {
    const Eigen::Vector2d r = camera.distortPixel(u);
    cv::Mat patch;
    cv::getRectSubPix(grey, cv::Size(1, 1), cv::Point2f(float(r.x()), float(r.y())), patch);
    return patch.at<float>(0, 0);
  };
  std::string steps;
  for (int j = 0; j < kNumEdges; ++j) {
    const Eigen::Vector2d a = f.segments[j][0], b = f.segments[j][1];
    const Eigen::Vector2d n = f.lines[j].head<2>();
    const int samples = std::max(2, static_cast<int>((b - a).norm()));
    std::vector<double> step;
    int strong = 0;
    for (int k = 0; k < samples; ++k) {
      const Eigen::Vector2d p = a + (b - a) * (k + 0.5) / samples;
      double best = 0;
      for (double o = -2.0; o <= 2.0; o += 0.5)
        best = std::max(best, double(std::abs(at(p + (o + 0.5) * n) - at(p + (o - 0.5) * n))));
      step.push_back(best);
      strong += best >= min_gradient;
    }
    std::nth_element(step.begin(), step.begin() + step.size() / 2, step.end());
    steps += cv::format(" %s %.0f%% (%.1f)", edgeName(j), 100.0 * strong / samples,
                        step[step.size() / 2]);
  }
  std::printf("    step >= %.1f along:%s\n", min_gradient, steps.c_str());
}

// Development aid (BOARD_CALIB_AUG_DIAG set): for a miss, per reference side the merged lines
// along it (rank among the kept lines, length) and the segments on it; every hypothesis
// tried whose corners lie within `kNearPx` of the reference corners and why it was rejected, or
// the nearest one (a region that failed before its corners were fitted records none).
void printNearHypotheses(const Frame& f, const ImageDetection& d) {
  if (!std::getenv("BOARD_CALIB_AUG_DIAG")) return;
  constexpr double kNearPx = 20.0;
  const auto& tried = d.details.hypotheses_px;
  double nearest = 1e18;
  size_t nearest_k = tried.size();
  for (size_t k = 0; k < tried.size(); ++k) {
    double worst = 0;
    for (const auto& c : tried[k]) {
      double best = 1e18;
      for (const auto& r : f.corners) best = std::min(best, (c - r).norm());
      worst = std::max(worst, best);
    }
    if (worst <= kNearPx)
      std::printf("    near (%.0f px): %s\n", worst, d.details.hypothesis_reasons[k].c_str());
    if (worst < nearest) {
      nearest = worst;
      nearest_k = k;
    }
  }
  // Per reference side: the merged lines along it (rank, support) and the segments on it, both
  // ends within kAlongPx of the reference line.
  constexpr double kAlongPx = 4.0;
  const CameraModel camera = f.camera();
  for (int j = 0; j < kNumEdges; ++j) {
    const Eigen::Vector3d& ref = f.lines[j];
    auto off = [&](const Eigen::Vector2d& p) { return std::abs(ref.head<2>().dot(p) + ref.z()); };
    const double side = (f.segments[j][1] - f.segments[j][0]).norm();
    std::string ranks;
    for (size_t k = 0; k < d.details.lines_px.size(); ++k) {
      const auto& l = d.details.lines_px[k];
      if (off(l[0]) > kAlongPx || off(l[1]) > kAlongPx) continue;
      ranks += " #" + std::to_string(k) + "(" +
               std::to_string(static_cast<int>((l[1] - l[0]).norm())) + ")";
    }
    double on = 0;
    int count = 0;
    for (const auto& s : d.details.segments_raw) {
      const Eigen::Vector2d a = camera.undistortPixel(s[0]), b = camera.undistortPixel(s[1]);
      if (off(a) > kAlongPx || off(b) > kAlongPx) continue;
      on += (b - a).norm();
      ++count;
    }
    std::printf("    side %s %.0f px: %d segments %.0f px; lines%s\n", edgeName(j), side, count, on,
                ranks.empty() ? " none" : ranks.c_str());
  }
  printSideSteps(f, d);
  std::printf("    %zu tried, %d lines, %d quads; nearest %.0f px%s%s\n", tried.size(),
              d.details.straight_lines, d.details.line_quads, nearest,
              nearest_k < tried.size() ? ": " : "",
              nearest_k < tried.size() ? d.details.hypothesis_reasons[nearest_k].c_str() : "");
}

// CPU time of this thread (ms): the detector is single-threaded, and on a shared machine its CPU
// time varies far less than its wall time.
double threadCpuMs() {
  timespec t{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
  return t.tv_sec * 1e3 + t.tv_nsec * 1e-6;
}

struct CaseTally {
  int frames = 0, found = 0, basler_found = 0, rs16_found = 0;
  EdgeScore all, basler;
  double sum_ms = 0, max_ms = 0, sum_cpu_ms = 0;
  std::vector<double> basler_cpu_ms, rs16_cpu_ms;  // per frame
  PlainStageTimes basler_stages, rs16_stages;      // sums over the frames
};

// "mean / median / max" of per-frame CPU times.
std::string cpuSummary(std::vector<double> ms) {
  if (ms.empty()) return "-";
  std::sort(ms.begin(), ms.end());
  double sum = 0;
  for (const double m : ms) sum += m;
  char text[64];
  std::snprintf(text, sizeof(text), "%.1f / %.1f / %.1f ms", sum / ms.size(), ms[ms.size() / 2],
                ms.back());
  return text;
}

// One case over every recorded frame: detections, their timing and their lines.
CaseTally runCase(const std::vector<Frame>& frames, const Case& c, size_t index,
                  std::mt19937& rng) {
  CaseTally t;
  for (size_t i = 0; i < frames.size(); ++i) {
    const Frame f = augment(frames[i], c, static_cast<int>(i), rng);
    const bool basler = f.name.rfind("basler", 0) == 0;
    const CameraModel camera = f.camera();
    auto det = ImageBoardDetector::create(f.target, ImageBoardDetectorOptions{});
    EXPECT_TRUE(det.ok());
    if (!det.ok()) return t;
    const double cpu_start = threadCpuMs();
    const ImageDetection d = det->detect(f.image, camera);
    const double cpu_ms = threadCpuMs() - cpu_start;
    t.sum_cpu_ms += cpu_ms;
    (basler ? t.basler_cpu_ms : t.rs16_cpu_ms).push_back(cpu_ms);
    (basler ? t.basler_stages : t.rs16_stages) += d.details.stage_times;
    ++t.frames;
    t.sum_ms += d.details.time_ms;
    t.max_ms = std::max(t.max_ms, d.details.time_ms);
    writeDebug("aug_" + std::to_string(index) + "_" + f.name, f.image, camera, d);
    const CameraBoardFeatures& fe = d.features;
    if (!fe.found || !fe.allEdgesValid()) {
      std::printf("  miss %-10s %s: %s\n", f.name.c_str(), c.name.c_str(), fe.reason.c_str());
      printNearHypotheses(f, d);
      EXPECT_FALSE(fe.reason.empty());
      continue;
    }
    ++t.found;
    (basler ? t.basler_found : t.rs16_found) += 1;
    const EdgeScore s = scoreEdges(f, d, c.name);
    t.all.edges += s.edges;
    t.all.within += s.within;
    t.all.worst = std::max(t.all.worst, s.worst);
    if (basler) {
      t.basler.edges += s.edges;
      t.basler.within += s.within;
    }
  }
  return t;
}

TEST(ImageDetectorAugmented, PlainBoardRealFrames) {
  if (!std::filesystem::exists(BOARD_CALIB_SHARED_DIR)) GTEST_SKIP() << "../shared absent";
  const std::vector<Frame>& frames = recordedFrames();
  ASSERT_GE(frames.size(), 16u + kRs16WithReference);
  // Development aid: BOARD_CALIB_AUG_SEED draws other augmentations (the floors below hold for
  // the default 14 only).
  const char* seed = std::getenv("BOARD_CALIB_AUG_SEED");
  std::mt19937 rng(seed ? static_cast<unsigned>(std::atoi(seed)) : kDefaultSeed);
  CaseTally total;
  std::printf("%-40s %8s %8s %8s %12s %10s %9s %8s %8s\n", "case", "found", "basler", "rs16",
              "edges<=1px", "worst px", "mean ms", "max ms", "cpu ms");
  // Development aid: BOARD_CALIB_AUG_CASES="0,3" runs only those cases (all when unset).
  const char* only = std::getenv("BOARD_CALIB_AUG_CASES");
  auto selected = [only](size_t k) {
    if (!only) return true;
    const std::string list = std::string(",") + only + ",";
    return list.find("," + std::to_string(k) + ",") != std::string::npos;
  };
  for (size_t k = 0; k < kCases.size(); ++k) {
    if (!selected(k)) continue;
    const Case& c = kCases[k];
    const CaseTally t = runCase(frames, c, k, rng);
    std::printf("%-40s %4d/%-3d %5d/16 %6d/%-2zu %6d/%-5d %10.2f %9.1f %8.1f %8.1f\n",
                c.name.c_str(), t.found, t.frames, t.basler_found, t.rs16_found, frames.size() - 16,
                t.all.within, t.all.edges, t.all.worst, t.sum_ms / std::max(1, t.frames), t.max_ms,
                t.sum_cpu_ms / std::max(1, t.frames));
    total.frames += t.frames;
    total.found += t.found;
    total.all.edges += t.all.edges;
    total.all.within += t.all.within;
    total.all.worst = std::max(total.all.worst, t.all.worst);
    total.basler.edges += t.basler.edges;
    total.basler.within += t.basler.within;
    total.basler_found += t.basler_found;
    total.rs16_found += t.rs16_found;
    total.basler_cpu_ms.insert(total.basler_cpu_ms.end(), t.basler_cpu_ms.begin(),
                               t.basler_cpu_ms.end());
    total.rs16_cpu_ms.insert(total.rs16_cpu_ms.end(), t.rs16_cpu_ms.begin(), t.rs16_cpu_ms.end());
    total.basler_stages += t.basler_stages;
    total.rs16_stages += t.rs16_stages;
    EXPECT_GE(t.basler_found, c.basler_floor) << c.name;
    // rs16_plain (wide-angle lens, a floor and ceiling full of long lines, hands on the sides):
    // the clean frames are the floor (5 of the 5 with a reference); the augmented ones are
    // reported (0-3 of 5 for the photometric cases, 0-1 far or occluded), below the target.
    if (c.ops.empty()) {
      EXPECT_GE(t.rs16_found, 5) << c.name;
    }
    // The recoloured board alone: its colour part finds it in the office (2 of 5 before the
    // single frame's colour parts).
    if (c.ops == std::vector<augmented::Op>{kColour}) {
      EXPECT_GE(t.rs16_found, 5) << c.name;
    }
  }
  std::printf(
      "all cases: four edges in %d/%d frames (%.1f %%), %d/%d edges within 1 px (worst %.2f px); "
      "basler_os1_plain %d/%d edges within 1 px\n",
      total.found, total.frames, 100.0 * total.found / std::max(1, total.frames), total.all.within,
      total.all.edges, total.all.worst, total.basler.within, total.basler.edges);
  std::printf("basler_os1_plain %d frames found, CPU per frame %s; rs16_plain %d found, %s\n",
              total.basler_found, cpuSummary(total.basler_cpu_ms).c_str(), total.rs16_found,
              cpuSummary(total.rs16_cpu_ms).c_str());
  // Where the time goes (CPU time of the detecting thread, per stage).
  for (const bool basler : {true, false}) {
    const auto& cpu = basler ? total.basler_cpu_ms : total.rs16_cpu_ms;
    if (cpu.empty()) continue;
    std::printf(
        "%s stages, mean ms per frame: %s\n", basler ? "basler_os1_plain" : "rs16_plain",
        (basler ? total.basler_stages : total.rs16_stages).scaled(1.0 / cpu.size()).text().c_str());
  }
  // Lines within 1 px of the independent reference: measured 669 of 676 basler edges (the rest
  // are shifted lines in the far, occluded and recoloured cases).
  EXPECT_GE(total.basler.within, 0.97 * total.basler.edges);
  // No found board is another quadrilateral or has a bent side: its worst edge measured 2.08 px
  // (6.15 px, legs along basler3's side, before the rival-line test), a wrong board's 100 px or
  // more, or named otherwise
  // (1000); a side a hand pulled, 9.6 px (another draw, before the straightness test).
  EXPECT_LT(total.all.worst, 8.0);
  // Over every case (the whole table, when no case is selected): measured 49 of 60 rs16_plain
  // frames and 233 of 252 in all. The search is deterministic, so a lost frame is a regression.
  // Session 29: 39 and 215 before edge profiles cut by the image border, the second look at a
  // weak side around its own peaks' line and the faint-line search's weak quadrilaterals (one
  // frame each). Session 31: 41 and 218 before a short side's span rule (basler0 far, 3 frames)
  // and the line search at twice the width (4). Session 32: 45 and 225 before the stable
  // regions' quadrilaterals (two far rs16 boards in the office). Session 35: 48 and 229 since a
  // hand's stretch is dropped from a side it bent (a far rs16 board). Session 36: 47 and 228, the
  // far rs16_3 board no longer found: its side a hand held passed 3.44 px off; its fine passes
  // now leave the hand out and its two looks disagree. Session 40: 46 and 227, the far rs16_1
  // board no longer found: its upper left side rests on two stretches 4 px apart, a side refused
  // since draws 22 and 24 kept such sides 9.44 and 5.17 px off (OtherDrawsGiveNoWrongBoard).
  // Session 44: 230, three far basler boards under grain, searched no wider than their lines'
  // error (quadSearchPx). Session 45: 47 and 231, the far rs16_3 board whose top side's line
  // took in a ceiling segment 450 px on: a line crosses a corner only within the other line's
  // extent (crossesAt). Session 46: 48 and 232, the far rs16_1 board whose two upper sides
  // ranked past the 200 lines kept: past the first lines, those ending at a corner come first
  // (rankLinesEndingAtCorners). Session 47: 49 and 233, the far rs16_2 board under legs and
  // hands, whose lower right side shows 69 % of its edge: only quadrilaterals that could be the
  // declared board take the weak lines' few places, and with its lines ending at three corners
  // one side need only show min_side_coverage (rankWeakQuads). Each session's figures, and what
  // each change gained or cost, are in docs/BENCHMARKS.md.
  if (!only && !seed) {
    EXPECT_GE(total.rs16_found, 49);
    EXPECT_GE(total.found, 233);
  }
}

// Other draws of the same augmentations: no found board is another object or has a side off the
// board's. Before the edge straightness test, draw 2 took a printed disc for the board (its
// tangents bowed 13 % of their span) and draw 4 a far board's side running on along a leg of its
// colour (bowed 8 %), both with sides 1000 px "off" (other orientation); draw 3 kept a far side
// a hand pulled 9.6 px off at its end. Since the far rs16 board is moved through the lens
// (session 27), draw 4 found a far rs16 board whose side, pulled onto the hand holding it, ran
// 9.23 px off at its end and draw 2 one 5.52 px off beside a leg, both seen on less than half of
// the side between their corners; now such a board does not settle the search and the board
// refitted at its place wins. 208, 210 and 209 of 252 found, worst edges 1.70, 3.59 and 2.44 px.
// Draw 5 (session 35): dropping a hand's stretch from a far rs16 side left the side leaning on the
// leg below it, and the 4:3 board was named a quarter turn round (sides 1000 px "off"); the rest
// of a side must now be free of such a stretch. Draws 15 and 17 (session 37): a far rs16 board's
// colour part, its own outline searched as the board, passed with its lower right side on a hand
// and a leg (5 and 11 px off), and the 4:3 board then fitted best a quarter turn round. Draws 22
// and 24 (session 40): a far rs16 side rested on two offset stretches, a hand's outline 4.5 px
// outside the edge at one end and the edge at the other, and ran 9.44 and 5.17 px off at its end;
// a side whose line moves when fitted on its longest stretch alone is now refused.
TEST(ImageDetectorAugmented, OtherDrawsGiveNoWrongBoard) {
  if (!std::filesystem::exists(BOARD_CALIB_SHARED_DIR)) GTEST_SKIP() << "../shared absent";
  const std::vector<Frame>& frames = recordedFrames();
  ASSERT_GE(frames.size(), 16u + kRs16WithReference);
  for (const unsigned seed : {2u, 3u, 4u, 5u, 15u, 17u, 22u, 24u}) {
    std::mt19937 rng(seed);
    int found = 0, frames_run = 0;
    double worst = 0;
    for (size_t k = 0; k < kCases.size(); ++k) {
      const CaseTally t = runCase(frames, kCases[k], k, rng);
      found += t.found;
      frames_run += t.frames;
      worst = std::max(worst, t.all.worst);
    }
    std::printf("draw %u: four edges in %d/%d frames, worst edge %.2f px\n", seed, found,
                frames_run, worst);
    // The right board's sides measured up to 3.59 px (draw 3: a far, faint, wood-grained side
    // bowed 2.3 px); a side beside the board, 5.52 px and more; a bent side or another object's
    // is further.
    EXPECT_LT(worst, 5.0) << "draw " << seed;
  }
}

// One frame of a draw as the whole table's generator makes it (the augmentations of the cases
// before it replayed, no detection), or nullopt when `name` is not among the recorded frames.
std::optional<Frame> replayedFrame(const std::vector<Frame>& frames, unsigned seed,
                                   size_t case_index, const std::string& name) {
  std::mt19937 rng(seed);
  for (size_t k = 0; k < case_index; ++k)
    for (size_t i = 0; i < frames.size(); ++i)
      augment(frames[i], kCases[k], static_cast<int>(i), rng);
  for (size_t i = 0; i < frames.size(); ++i) {
    Frame f = augment(frames[i], kCases[case_index], static_cast<int>(i), rng);
    if (f.name == name) return f;
  }
  return std::nullopt;
}

// The board of a replayed frame, detected alone; its sides' errors against the reference (px).
std::array<double, kNumEdges> replayedBoardErrors(unsigned seed, size_t case_index,
                                                  augmented::Op op, const std::string& name,
                                                  const std::string& debug_name) {
  std::array<double, kNumEdges> errors;
  errors.fill(1e9);
  const std::vector<Frame>& frames = recordedFrames();
  EXPECT_GE(frames.size(), 16u + kRs16WithReference);
  EXPECT_EQ(kCases[case_index].ops, std::vector<augmented::Op>{op});
  const std::optional<Frame> f = replayedFrame(frames, seed, case_index, name);
  if (!f) {
    ADD_FAILURE() << name << " is not among the recorded frames";
    return errors;
  }
  auto det = ImageBoardDetector::create(f->target, ImageBoardDetectorOptions{});
  if (!det.ok()) {
    ADD_FAILURE() << "detector not created";
    return errors;
  }
  const ImageDetection d = det->detect(f->image, f->camera());
  writeDebug(debug_name + "_" + f->name, f->image, f->camera(), d);
  EXPECT_TRUE(d.features.found && d.features.allEdgesValid()) << d.features.reason;
  if (!d.features.found || !d.features.allEdgesValid()) return errors;
  for (int j = 0; j < kNumEdges; ++j) {
    errors[j] = edgeErrorPx(*f, d.features, j);
    std::printf("  edge %s: %.2f px\n", edgeName(j), errors[j]);
  }
  return errors;
}

// Fresh draw 23, wood grain, rs16_1: a wall-and-floor rectangle of the office around the board
// passed the board checks (corners fitting 0.8 x 0.6 m at 4.39 px by a steep turn) beside the
// board itself (0.99 px), and won on its longer outline: all four sides 1000 px "off". Outlines
// that cross cannot both be the board; the better fit is kept.
TEST(ImageDetectorAugmented, ASceneRectangleCrossingTheBoardLosesToIt) {
  if (!std::filesystem::exists(BOARD_CALIB_SHARED_DIR)) GTEST_SKIP() << "../shared absent";
  const auto errors = replayedBoardErrors(23, 5, kWood, "rs16_1", "crossing");
  // The board's sides: within 1 px but for a grain-bowed one (2.67 px measured); the scene
  // rectangle's lie hundreds of px away.
  for (int j = 0; j < kNumEdges; ++j) EXPECT_LT(errors[j], 4.0) << edgeName(j);
}

// Draw 32, far, rs16_3: the board's bottom side was merged with a collinear scene segment ~870 px
// to its left, so its line crossed the board's corner and no quadrilateral ended there; the board
// was taken with the floor line below it as its bottom side (corners fitting at 1.34 px, that
// side 41 px off). A line now crosses a corner only within the other line's extent.
TEST(ImageDetectorAugmented, ABoardSideMergedWithADistantSceneSegmentKeepsItsCorners) {
  if (!std::filesystem::exists(BOARD_CALIB_SHARED_DIR)) GTEST_SKIP() << "../shared absent";
  const auto errors = replayedBoardErrors(32, 6, kFar, "rs16_3", "merged_side");
  // The board's sides lie within 1 px of the reference (measured up to 0.26 px); the floor line
  // is 20-48 px below the bottom side.
  for (int j = 0; j < kNumEdges; ++j) EXPECT_LT(errors[j], 1.0) << edgeName(j);
}

// Default draw, far + background + print + occluders, rs16_1: once more far lines were ranked,
// a ceiling beam's light face in the wide-angle corner passed for a board 14.7 m away, its
// sides 170 and 47 px. Its long sides run on past 3 of their 4 corner ends, but the short
// sides' ends were too short a stretch to test, and with fewer than six ends tested no
// quadrilateral was judged. A short side's ends are now tested over as many samples as an edge
// needs (continuationStretchPx).
TEST(ImageDetectorAugmented, ABeamsFaceWhoseLongSidesRunOnIsNotAFarBoard) {
  if (!std::filesystem::exists(BOARD_CALIB_SHARED_DIR)) GTEST_SKIP() << "../shared absent";
  const std::vector<Frame>& frames = recordedFrames();
  ASSERT_GE(frames.size(), 16u + kRs16WithReference);
  constexpr size_t kCase = 11;
  ASSERT_EQ(kCases[kCase].ops, (std::vector<augmented::Op>{kBackground, kPrint, kOcclude, kFar}));
  const std::optional<Frame> f = replayedFrame(frames, kDefaultSeed, kCase, "rs16_1");
  ASSERT_TRUE(f.has_value());
  auto det = ImageBoardDetector::create(f->target, ImageBoardDetectorOptions{});
  ASSERT_TRUE(det.ok()) << det.error();
  const ImageDetection d = det->detect(f->image, f->camera());
  writeDebug("beam_face_" + f->name, f->image, f->camera(), d);
  // Not found (the board's own sides are too faint here), or found with the board's sides.
  for (int j = 0; j < kNumEdges && d.features.found; ++j)
    EXPECT_LT(edgeErrorPx(*f, d.features, j), 1.0) << edgeName(j) << ": another object's side";
}

// The far cases alone, each from a fresh draw (its own generator at the default seed: other
// placements, occluders and textures than in the whole table). Before the first pass's rival-line
// test, the far case alone kept an rs16 side 10.8 px off at its end: a hand and the board's edge
// along it, the fit settled between them and stayed within the bow limit. (The other cases from
// fresh draws are not asserted yet: wood grain alone takes a scene rectangle of the rs16 office
// for the board, docs/BENCHMARKS.md, session 25.)
TEST(ImageDetectorAugmented, FarCasesFromAFreshDrawGiveNoWrongBoard) {
  if (!std::filesystem::exists(BOARD_CALIB_SHARED_DIR)) GTEST_SKIP() << "../shared absent";
  const std::vector<Frame>& frames = recordedFrames();
  ASSERT_GE(frames.size(), 16u + kRs16WithReference);
  int found = 0, frames_run = 0;
  double worst = 0;
  for (size_t k = 0; k < kCases.size(); ++k) {
    const auto& ops = kCases[k].ops;
    if (std::find(ops.begin(), ops.end(), kFar) == ops.end()) continue;
    std::mt19937 rng(kDefaultSeed);
    const CaseTally t = runCase(frames, kCases[k], k, rng);
    found += t.found;
    frames_run += t.frames;
    worst = std::max(worst, t.all.worst);
  }
  std::printf("far cases from a fresh draw: four edges in %d/%d frames, worst edge %.2f px\n",
              found, frames_run, worst);
  EXPECT_LT(worst, 8.0);
}

// No wrong board: the blanked frames (board inpainted from its surroundings) give "not found".
TEST(ImageDetectorAugmented, BlankedFramesGiveNoBoard) {
  if (!std::filesystem::exists(BOARD_CALIB_SHARED_DIR)) GTEST_SKIP() << "../shared absent";
  const std::vector<Frame>& frames = recordedFrames();
  ASSERT_GE(frames.size(), 16u + kRs16WithReference);
  std::mt19937 rng(14);
  int wrong = 0;
  for (const Frame& clean : frames) {
    Frame f = clean;
    f.image = clean.image.clone();
    blankBoard(&f, rng);
    const CameraModel camera = f.camera();
    auto det = ImageBoardDetector::create(f.target, ImageBoardDetectorOptions{});
    ASSERT_TRUE(det.ok());
    const ImageDetection d = det->detect(f.image, camera);
    writeDebug("blank_" + f.name, f.image, camera, d);
    if (!d.features.found) {
      EXPECT_FALSE(d.features.reason.empty());
    }
    wrong += d.features.found;
    std::printf("  blank %-10s: %s\n", f.name.c_str(), d.features.reason.c_str());
  }
  std::printf("blanked: %d wrong boards in %zu frames\n", wrong, frames.size());
  // Issue target: none, met. The glass-wall rectangles of the rs16_plain office that fit a
  // 0.8 x 0.6 m board (4 of 21 before) are rejected because their sides run on past 3-5 of their
  // 8 corner ends; three basler rectangles sit at 20.0-20.1 m, just past the distance limit.
  EXPECT_EQ(wrong, 0);
}

}  // namespace
}  // namespace board_calib
