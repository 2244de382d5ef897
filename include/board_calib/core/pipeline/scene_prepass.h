// Offline pre-pass of the static scene (issue 14): live, the image memory knows the static scene
// only after static_after_s, so the first holds of a session meet the facade alone. Offline the
// whole recording is at hand: its line stage on frames spread over the recording tells, by the
// same rule as live (PlaceSightings), which straight lines stay put, before the first frame is
// searched for the board (PipelineOptions::image_known_scene).
#pragma once

#include <board_calib/core/image_detection/image_board_tracker.h>

#include <optional>
#include <string>

namespace board_calib {

struct ScenePrepassOptions {
  /// Frames per static_after_s: the pre-pass takes one image every static_after_s / this (1.5 s
  /// by default), so a static line's 6 s are seen in 4-5 frames and a board held for a normal
  /// hold (1.5-3 s) in 1-2. 0: no pre-pass.
  int frames_per_static = 4;
  /// Also the board-like rectangles (the whole detection, not only its line stage): a static
  /// rectangle found by its region (a poster) is not a quadrilateral of lines, so static lines
  /// alone do not keep it from being taken for the board.
  bool rectangles = true;
  std::string validate() const;
};

/// Fed the images of a whole recording in time order; keeps one every
/// static_after_s / frames_per_static and remembers its board-like rectangles and merged lines.
class ScenePrepass {
 public:
  static Expected<ScenePrepass> create(const Target& target,
                                       const ImageBoardDetectorOptions& detector,
                                       const StaticMemoryOptions& memory,
                                       const ScenePrepassOptions& options = {});
  /// Whether the image at `stamp` (s) would be used (the caller may skip decoding the others).
  bool wants(double stamp) const;
  /// The image at `stamp`; false when not used (not wanted, or bad intrinsics).
  bool add(const cv::Mat& image, const CameraIntrinsics& intrinsics, double stamp);
  /// The rectangles and lines static over the recording (seen over static_after_s in
  /// min_seen_fraction of the pre-pass frames since their first sighting, counted to the last
  /// frame).
  StaticScene scene() const { return tracker_.staticScene(); }
  /// Images used since the start (or since the stamps went back: a second recording).
  long frames() const { return tracker_.frames(); }

 private:
  ScenePrepass(ImageBoardTracker tracker, double period_s, bool rectangles)
      : tracker_(std::move(tracker)), period_s_(period_s), rectangles_(rectangles) {}
  ImageBoardTracker tracker_;
  double period_s_ = 0.0;
  bool rectangles_ = true;
  double last_stamp_ = -1e300;
  std::optional<CameraIntrinsics> intrinsics_;
  std::optional<CameraModel> camera_;
};

}  // namespace board_calib
