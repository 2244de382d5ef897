// Checkerboard (PPC-Cal): OpenCV corner detection (fast check on a downscaled image first),
// cornerSubPix at full resolution, a consistent orientation, PnP, outer edges from the pose.
#include "detection_internal.h"

#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include <cmath>

namespace board_calib {
namespace image_detection {
namespace {

constexpr int kSubPixIterations = 40;
constexpr double kSubPixEpsilon = 0.001;  // px
constexpr double kSubPixWindowFraction =
    0.4;  // of the smallest corner spacing: the window must stay in one square

// Reorders OpenCV's corners so that they match Target::checkerboardCorners(): right-handed in the
// image (board x right, y down seen from the printed face) and board x as close to image +u as
// possible (the pattern's 180° symmetry, and 90° for square patterns, cannot be told otherwise).
std::vector<cv::Point2f> orient(const std::vector<cv::Point2f>& c, int cols, int rows) {
  auto at = [&](const std::vector<cv::Point2f>& v, int col, int row) {
    return v[row * cols + col];
  };
  std::vector<cv::Point2f> v = c;
  const cv::Point2f x_axis = at(v, cols - 1, 0) - at(v, 0, 0);
  const cv::Point2f y_axis = at(v, 0, rows - 1) - at(v, 0, 0);
  if (x_axis.x * y_axis.y - x_axis.y * y_axis.x < 0) {  // mirrored: flip every row
    for (int r = 0; r < rows; ++r)
      for (int k = 0; k < cols; ++k) v[r * cols + k] = c[r * cols + (cols - 1 - k)];
  }
  std::vector<std::vector<cv::Point2f>> options{v, std::vector<cv::Point2f>(v.rbegin(), v.rend())};
  if (cols == rows) {  // 90° rotations map a square pattern onto itself
    for (int turn = 0; turn < 2; ++turn) {
      const auto& src = options[turn];
      std::vector<cv::Point2f> rot(src.size());
      for (int r = 0; r < rows; ++r)
        for (int k = 0; k < cols; ++k) rot[r * cols + k] = src[k * cols + (cols - 1 - r)];
      options.push_back(rot);
    }
  }
  size_t best = 0;
  double best_u = -1e18;
  for (size_t i = 0; i < options.size(); ++i) {
    const cv::Point2f x = at(options[i], cols - 1, 0) - at(options[i], 0, 0);
    const double u = x.x / std::max(1e-6, std::hypot(double(x.x), double(x.y)));
    if (u > best_u) {
      best_u = u;
      best = i;
    }
  }
  return options[best];
}

}  // namespace

void detectCheckerboard(const cv::Mat& gray, const CameraModel& camera, const Target& target,
                        const ImageBoardDetectorOptions& o, ImageDetection* out) {
  CameraBoardFeatures& f = out->features;
  ImageDetectionDetails& d = out->details;
  const int cols = target.checkerboard.cols, rows = target.checkerboard.rows;
  const cv::Size pattern(cols, rows);
  const int flags =
      cv::CALIB_CB_ADAPTIVE_THRESH | cv::CALIB_CB_NORMALIZE_IMAGE | cv::CALIB_CB_FAST_CHECK;
  std::vector<cv::Point2f> corners;
  bool found = false;
  if (gray.cols > o.fast_check_width_px) {
    const double scale = static_cast<double>(gray.cols) / o.fast_check_width_px;
    cv::Mat small;
    cv::resize(gray, small,
               cv::Size(o.fast_check_width_px, static_cast<int>(std::lround(gray.rows / scale))), 0,
               0, cv::INTER_AREA);
    const double sx = static_cast<double>(gray.cols) / small.cols,
                 sy = static_cast<double>(gray.rows) / small.rows;
    found = cv::findChessboardCorners(small, pattern, corners, flags);
    if (found)
      for (auto& p : corners)
        p = cv::Point2f(float((p.x + 0.5) * sx - 0.5), float((p.y + 0.5) * sy - 0.5));
  }
  // Small boards vanish in the downscaled image: fall back to full resolution (still fast-checked).
  if (!found) found = cv::findChessboardCorners(gray, pattern, corners, flags);
  if (!found || corners.size() != static_cast<size_t>(cols * rows)) {
    f.reason = cv::format("board not found: no %dx%d checkerboard", cols, rows);
    return;
  }
  corners = orient(corners, cols, rows);
  double min_spacing = 1e18;
  for (int r = 0; r < rows; ++r)
    for (int k = 0; k < cols; ++k) {
      const cv::Point2f p = corners[r * cols + k];
      if (k + 1 < cols)
        min_spacing = std::min<double>(min_spacing, cv::norm(corners[r * cols + k + 1] - p));
      if (r + 1 < rows)
        min_spacing = std::min<double>(min_spacing, cv::norm(corners[(r + 1) * cols + k] - p));
    }
  const int win = std::max(
      2, std::min(o.subpix_window_px, static_cast<int>(kSubPixWindowFraction * min_spacing)));
  cv::cornerSubPix(gray, corners, cv::Size(win, win), cv::Size(-1, -1),
                   cv::TermCriteria(cv::TermCriteria::EPS + cv::TermCriteria::COUNT,
                                    kSubPixIterations, kSubPixEpsilon));
  const Points3 board = target.checkerboardCorners();
  Points2 undist;
  for (size_t i = 0; i < corners.size(); ++i) {
    const Eigen::Vector2d raw(corners[i].x, corners[i].y);
    d.pattern_raw.push_back(raw);
    undist.push_back(camera.undistortPixel(raw));
  }
  const double size_px = std::max((undist[cols - 1] - undist[0]).norm(),
                                  (undist[(rows - 1) * cols] - undist[0]).norm());
  if (size_px < o.min_board_size_px) {
    f.reason = cv::format("board too small: pattern spans %.0f px", size_px);
    return;
  }
  const PoseFit pose = fitPose(board, undist, f.K, o.pixel_sigma_px);
  if (!pose.ok) {
    f.reason = pose.reason;
    return;
  }
  for (size_t i = 0; i < undist.size(); ++i)
    f.pattern.push_back({static_cast<int>(i), board[i], undist[i]});
  f.camera_T_board = pose.camera_T_board;
  f.plane = planeFromPose(pose.camera_T_board);
  f.reprojection_rms_px = pose.rms_px;
  d.pattern_errors_px = pose.errors_px;
  d.pose_covariance = pose.covariance;
  outerEdgesFromPose(target, &f);
  if (pose.rms_px > o.max_reprojection_rms_px) {
    f.reason = cv::format("checkerboard corners do not fit the pattern (rms %.2f px)", pose.rms_px);
    return;
  }
  f.found = true;
}

}  // namespace image_detection
}  // namespace board_calib
