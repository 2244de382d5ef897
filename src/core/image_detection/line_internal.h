// Private to the line stage of the plain detector: LSD segments merged into long straight lines
// (line_segments.cpp), from which line_hypotheses.cpp forms quadrilaterals.
#pragma once

#include "detection_internal.h"

#include <array>
#include <utility>
#include <vector>

namespace board_calib {
namespace image_detection {

inline double cross2(const Eigen::Vector2d& a, const Eigen::Vector2d& b) {
  return a.x() * b.y() - a.y() * b.x();
}

inline double angleBetweenLines(const Eigen::Vector2d& d1, const Eigen::Vector2d& d2) {
  return std::acos(std::min(1.0, std::abs(d1.dot(d2))));
}

/// One LSD segment, undistorted full-resolution px.
struct Member {
  Eigen::Vector2d a, b;
  double length;
};

/// Segments merged into one straight line.
struct MergedLine {
  Eigen::Vector2d point, dir;  ///< undistorted px, unit direction
  std::vector<Member> members;
  std::vector<std::pair<double, double>> intervals;  ///< union of member projections along dir
  double support = 0, t_min = 0, t_max = 0;

  double offset(const Eigen::Vector2d& p) const { return cross2(dir, p - point); }
  /// px between the ends of its support.
  double extent() const { return t_max - t_min; }
  double along(const Eigen::Vector2d& p) const { return dir.dot(p - point); }

  /// Length-weighted total least squares through the member segments (each sampled at its ends
  /// and middle), then the union of their projections.
  void refit();

  /// Support inside [lo, hi] along the line.
  double supportWithin(double lo, double hi) const {
    double s = 0;
    for (const auto& iv : intervals)
      s += std::max(0.0, std::min(hi, iv.second) - std::max(lo, iv.first));
    return s;
  }

  std::array<Eigen::Vector2d, 2> ends() const { return {point + t_min * dir, point + t_max * dir}; }

  Eigen::Vector3d homogeneous() const {
    const Eigen::Vector2d n(-dir.y(), dir.x());
    return {n.x(), n.y(), -n.dot(point)};
  }
};

/// Reorders the lines past the first `first` (most supported first): those with an end where
/// another line meets them at a real angle and ends too (an L corner, as a board's sides make)
/// come before the others, each group keeping its order (line_hypotheses.cpp).
void rankLinesEndingAtCorners(std::vector<MergedLine>* lines, size_t first, double end_sigma);

/// Line segments of an 8-bit grey image (x1, y1, x2, y2; pixel centres at integers): the LSD
/// algorithm as OpenCV's LSD_REFINE_NONE, faster (line_segment_detector.cpp). `quantization`:
/// LSD's q, the bound of the error on a gradient component (grey levels; 2 is LSD's for raw 8-bit
/// images); gradients below q / sin(22.5 deg) have no direction.
std::vector<cv::Vec4f> lineSegments(const cv::Mat& gray, double quantization = kLsdRawQuantization);

/// The merged lines of an image, most supported first.
struct LineSet {
  std::vector<MergedLine> lines;
  double end_sigma_px = 0;  ///< full-resolution px: endpoint noise of a segment at the LSD scale
};

/// LSD on the image downscaled to options.line_detection_width_px, segments merged into lines
/// with enough support, at most max_lines (evidence: the raw segments and their count).
/// `quantization`: LSD's q (lineSegments).
LineSet detectLines(const cv::Mat& gray, const CameraModel& camera,
                    const ImageBoardDetectorOptions& options, LineEvidence* evidence, int max_lines,
                    double quantization = kLsdRawQuantization);

}  // namespace image_detection
}  // namespace board_calib
