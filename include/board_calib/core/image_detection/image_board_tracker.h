// Stateful camera board detector (issue 14, 3a), the image counterpart of LidarBoardTracker: the
// board is what moves between views; a quadrilateral that passes every board check at one place
// of the image over static_after_s (a window bay, a door, a poster) is the static scene, and later
// frames look past it.
#pragma once

#include <board_calib/core/common/static_memory.h>
#include <board_calib/core/image_detection/image_board_detector.h>

#include <deque>
#include <vector>

namespace board_calib {

/// One per camera (not thread-safe). Images must come in time order; a stamp going back resets
/// the memory. Only plain boards are affected (a pattern board is unambiguous).
class ImageBoardTracker {
 public:
  static Expected<ImageBoardTracker> create(const Target& target,
                                            const ImageBoardDetectorOptions& detector,
                                            const StaticMemoryOptions& memory = {});

  /// Detects the board in a raw image taken at `stamp` (s): board-like quadrilaterals at static
  /// places are passed as exclusions. Every board-like quadrilateral of the frame is remembered;
  /// when this frame's board is at a place that is static from now on, the frame is searched
  /// again without it.
  ImageDetection detect(const cv::Mat& image, const CameraModel& camera, double stamp);
  /// Offline pre-pass: `image` (stamp in s, time order) searched alone, without exclusions,
  /// its board-like quadrilaterals (with `rectangles`) and every merged straight line remembered;
  /// the frame's board is not returned. A tracker fed so over a whole recording knows its static
  /// scene by the same rule as live (staticScene()), to be given to the main pass's tracker.
  void learnScene(const cv::Mat& image, const CameraModel& camera, double stamp, bool rectangles);
  /// The static scene known before the first frame (an offline pre-pass over the whole
  /// recording): excluded from every frame besides what this tracker learns. Kept by reset().
  void setKnownScene(StaticScene scene) { known_ = std::move(scene); }
  /// Forgets what was learnt (not the known scene).
  void reset();
  int numPlaces() const { return static_cast<int>(places_.size()); }
  /// Frames seen (detect() or learnScene()) since the last reset or stamp going back.
  long frames() const { return frames_; }
  int numStaticPlaces() const;
  int numStaticLines() const;
  /// The static places and lines as the detector's exclusions (learnt, then the known scene).
  StaticScene staticScene() const;
  /// Remembered straight lines, static or not (the memory's size, with numPlaces()).
  int numRememberedLines() const { return static_cast<int>(lines_.size()); }
  /// ms the last detect() spent on the memory itself (static scene, remembering, forgetting),
  /// besides the detector's search.
  double memoryMs() const { return memory_ms_; }
  /// New detector options (e.g. reconfigured); the memory is kept. Returns why they are refused
  /// (then the previous ones stay), empty on success.
  std::string setDetectorOptions(const ImageBoardDetectorOptions& options);
  /// The wrapped detector (a second chance near a projected board uses it directly).
  ImageBoardDetector& detector() { return detector_; }
  const StaticMemoryOptions& memory() const { return memory_; }

 private:
  ImageBoardTracker(ImageBoardDetector detector, const StaticMemoryOptions& memory)
      : detector_(std::move(detector)), memory_(memory) {}
  struct Place {
    std::array<Eigen::Vector2d, kNumEdges> corners_px{};  ///< undistorted px, first sighting
    double tolerance_px = 0.0;
    PlaceSightings sightings;
  };
  struct LinePlace {
    std::array<Eigen::Vector2d, 2> ends_px{};  ///< undistorted px, first sighting
    PlaceSightings sightings;
  };
  int match(const std::array<Eigen::Vector2d, kNumEdges>& corners) const;
  void rememberLines(const std::vector<std::array<Eigen::Vector2d, 2>>& lines, double stamp,
                     int image_width);
  void startFrame(double stamp);
  void forget(double stamp);
  void remember(const ImageDetection& detection, double stamp);
  void learnBackground(const cv::Mat& image, double stamp);
  ImageBoardDetector detector_;
  StaticMemoryOptions memory_;
  std::vector<Place> places_;
  std::vector<LinePlace> lines_;
  StaticScene known_;
  long frames_ = 0;
  double memory_ms_ = 0.0;
  double last_stamp_ = -1e300;
  // Downscaled bgr frames, one per background period, and their median (StaticScene::background).
  std::deque<cv::Mat> background_frames_;
  std::deque<double> background_stamps_;
  cv::Size background_source_;  // full-size image the frames were taken from
  double background_last_s_ = -1e300;
  cv::Mat background_;
};

}  // namespace board_calib
