// Stateful camera board detector (issue 14, 3a), the image counterpart of LidarBoardTracker: the
// board is what moves between views; a quadrilateral that passes every board check at one place
// of the image over static_after_s (a window bay, a door, a poster) is the static scene, and later
// frames look past it.
#pragma once

#include <board_calib/core/common/static_memory.h>
#include <board_calib/core/image_detection/image_board_detector.h>

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
  void reset();
  int numPlaces() const { return static_cast<int>(places_.size()); }
  int numStaticPlaces() const;
  int numStaticLines() const;
  /// The static places and lines as the detector's exclusions (for debugging and tests).
  StaticScene staticScene() const;
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
  void rememberLines(const ImageDetection& detection, double stamp, int image_width);
  void remember(const ImageDetection& detection, double stamp);
  ImageBoardDetector detector_;
  StaticMemoryOptions memory_;
  std::vector<Place> places_;
  std::vector<LinePlace> lines_;
  long frames_ = 0;
  double last_stamp_ = -1e300;
};

}  // namespace board_calib
