// Real plain-board frames with reference lines (basler_os1_plain: the independent lines of
// ../shared/tools/mlre; rs16_plain: the detector's lines inside hand-picked corners) and the
// augmentations of issue 14 (board colour, contrast, print, wood grain, background, far, legs and
// hands, blanked board); the reference lines follow every geometric change.
#pragma once

#include <board_calib/core/camera_model.h>
#include <board_calib/core/features.h>
#include <board_calib/core/target.h>

#include <opencv2/core.hpp>

#include <array>
#include <random>
#include <string>
#include <vector>

namespace board_calib {
namespace augmented {

// One frame with its camera and reference board edges (undistorted px of that camera).
struct Frame {
  std::string name;
  cv::Mat image;
  CameraIntrinsics intrinsics;
  std::array<Eigen::Vector3d, kNumEdges> lines;                    // reference lines
  std::array<std::array<Eigen::Vector2d, 2>, kNumEdges> segments;  // visible reference segments
  std::array<Eigen::Vector2d, kNumEdges> corners;                  // corner j = line j x line j+1
  Target target;

  CameraModel camera() const { return *CameraModel::create(intrinsics); }
};

// rs16_plain frames with a reference: the detector's lines found inside the picked corners
// (detectNear, the same sub-pixel edges as the whole-image search), segments = extent of its edge
// pixels. Frames 4, 5 and 7 get none: both hands hide 80-85 % of a side, which no search accepts
// (they were scored against another rectangle of the office before).
constexpr size_t kRs16WithReference = 5;

/// The 16 basler_os1_plain frames, then the rs16_plain frames with a reference (read once).
const std::vector<Frame>& recordedFrames();

/// Inpaints the board from its surroundings (a frame without the board).
void blankBoard(Frame* f, std::mt19937& rng);

enum Op { kColour, kLowContrast, kBackground, kPrint, kWood, kFar, kOcclude };

struct Case {
  std::string name;
  std::vector<Op> ops;
  int basler_floor;  // basler_os1_plain frames (of 16) with four edges: the test's floor
};

/// Largest distance (px) of reference segment `ref`'s ends from `line` (a u + b v + c = 0, with
/// (a, b) a unit normal).
double segmentDistancePx(const Frame& f, int ref, const Eigen::Vector3d& line);

/// How far found edge `j` (line j of `found`) is from reference edge j: its segment distance, or
/// 1000 px when the line's normal is not the reference's (another object, or a board named round).
double edgeErrorPx(const Frame& f, const CameraBoardFeatures& found, int j);

/// The cases of the augmented tests, with their basler floors.
const std::vector<Case>& augmentedCases();

/// The frame with the case's augmentations (index picks colours, sizes; rng the random parts).
Frame augment(const Frame& clean, const Case& c, int index, std::mt19937& rng);

}  // namespace augmented
}  // namespace board_calib
