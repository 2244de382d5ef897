// Plain board detector's second chance on augmented REAL frames (issue 14 item 3b): with a prior
// extrinsic, the image is searched again inside the board it projects (detectNear). Frames,
// references and augmentations: augmented_frames.h (as in test_image_detector_augmented).
#include "augmented_frames.h"

#include <board_calib/core/image_detection/image_board_detector.h>

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <random>

namespace board_calib {
namespace {

using augmented::Case;
using augmented::Frame;
using namespace augmented;

const std::vector<Case>& kCases = augmentedCases();

// A prior extrinsic's projection of the board: the reference corners shifted together by up to
// kPriorShiftPx and each by up to kPriorJitterPx more (a previous solve off by ~0.25 deg at
// f 2814 px, or LiDAR edges a sample spacing off), searched with a tolerance that covers both.
constexpr double kPriorShiftPx = 12.0, kPriorJitterPx = 4.0, kPriorTolerancePx = 25.0;

ExpectedBoard priorProjection(const Frame& f, std::mt19937& rng) {
  std::uniform_real_distribution<double> shift(-kPriorShiftPx, kPriorShiftPx),
      jitter(-kPriorJitterPx, kPriorJitterPx);
  const Eigen::Vector2d common(shift(rng), shift(rng));
  ExpectedBoard e;
  for (int j = 0; j < kNumEdges; ++j)
    e.corners_px[j] = f.corners[j] + common + Eigen::Vector2d(jitter(rng), jitter(rng));
  e.tolerance_px = kPriorTolerancePx;
  return e;
}

// Reference edges with a found line within 1 px at both ends of the visible segment (any name).
int edgesWithin1px(const Frame& f, const CameraBoardFeatures& fe) {
  int within = 0;
  for (int j = 0; j < kNumEdges; ++j) {
    double best = 1e18;
    for (int k = 0; k < kNumEdges; ++k)
      best = std::min(best, segmentDistancePx(f, j, fe.edge_lines[k]));
    within += best <= 1.0;
  }
  return within;
}

// Issue 14 item 3b: when the LiDAR found the board and a prior extrinsic exists, the image is
// searched again inside the projected board with the same checks: it must keep every board the
// whole-image search found, recover some it missed, and never accept a board that is not there.
TEST(ImageDetectorAugmented, SecondChanceInsideTheProjectedBoard) {
  if (!std::filesystem::exists(BOARD_CALIB_SHARED_DIR)) GTEST_SKIP() << "../shared absent";
  const std::vector<Frame>& frames = recordedFrames();
  ASSERT_GE(frames.size(), 16u + kRs16WithReference);
  std::mt19937 rng(3);
  int all_on_board = 0, all_second = 0, all_frames = 0, all_edges = 0, all_within = 0;
  // clean, legs and hand, colour + print + occluders, far + colour + occluders
  for (const size_t k : {size_t{0}, size_t{7}, size_t{8}, size_t{10}}) {
    int on_board = 0, second_found = 0, edges = 0, within = 0;
    for (size_t i = 0; i < frames.size(); ++i) {
      const Frame f = augment(frames[i], kCases[k], static_cast<int>(i), rng);
      const CameraModel camera = f.camera();
      auto det = ImageBoardDetector::create(f.target, ImageBoardDetectorOptions{});
      ASSERT_TRUE(det.ok());
      const ImageDetection whole = det->detect(f.image, camera);
      const ImageDetection second = det->detectNear(f.image, camera, priorProjection(f, rng));
      // The whole-image board counts when it is the reference board (all four lines to 1 px).
      const bool whole_on_board = whole.features.found && whole.features.allEdgesValid() &&
                                  edgesWithin1px(f, whole.features) == kNumEdges;
      on_board += whole_on_board;
      if (!second.features.found || !second.features.allEdgesValid()) {
        EXPECT_FALSE(second.features.reason.empty());
        if (whole_on_board)
          std::printf("  lost %-10s %s: %s\n", f.name.c_str(), kCases[k].name.c_str(),
                      second.features.reason.c_str());
        continue;
      }
      ++second_found;
      edges += kNumEdges;
      within += edgesWithin1px(f, second.features);
    }
    std::printf(
        "%-40s whole image on the board %2d/%zu, second chance %2d/%zu, its edges within 1 px "
        "%d/%d\n",
        kCases[k].name.c_str(), on_board, frames.size(), second_found, frames.size(), within,
        edges);
    all_on_board += on_board;
    all_second += second_found;
    all_frames += static_cast<int>(frames.size());
    all_edges += edges;
    all_within += within;
  }
  std::printf(
      "four edges: whole image on the board %d/%d, second chance %d/%d, edges within 1 px %d/%d\n",
      all_on_board, all_frames, all_second, all_frames, all_within, all_edges);
  // The second chance keeps every board the whole image found on the reference (measured 71 of
  // 84 against 64: where the whole image took another rectangle, or a board with a line off) ...
  EXPECT_GE(all_second, all_on_board);
  // ... and its lines are as good as the whole-image search's (measured 277 of 284 within
  // 1 px; the rest are sides bent by an occluder at a corner, also seen without the prior).
  EXPECT_GE(all_within, 0.95 * all_edges);

  // Blanked boards: the projected region holds no board, so nothing may be accepted there.
  int wrong = 0;
  for (const Frame& clean : frames) {
    Frame f = clean;
    f.image = clean.image.clone();
    blankBoard(&f, rng);
    const CameraModel camera = f.camera();
    auto det = ImageBoardDetector::create(f.target, ImageBoardDetectorOptions{});
    const ImageDetection d = det->detectNear(f.image, camera, priorProjection(f, rng));
    if (d.features.found)
      std::printf("  WRONG %s: a board near the blanked one\n", f.name.c_str());
    else
      EXPECT_FALSE(d.features.reason.empty());
    wrong += d.features.found;
  }
  std::printf("blanked, searched near the projected board: %d wrong boards in %zu frames\n", wrong,
              frames.size());
  EXPECT_EQ(wrong, 0);
}

}  // namespace
}  // namespace board_calib
