// The reference paper's "projected edges" check: LiDAR edge points projected with an
// extrinsic, scored by their perpendicular distance to the image edge lines (MLRE).
#include <board_calib/core/common/edge_association.h>
#include <board_calib/core/projection/projection.h>

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <sstream>

namespace board_calib {

namespace {

constexpr double kTextScale = 1.2;
constexpr int kTextThickness = 2;
constexpr int kTextMarginPx = 12;
constexpr int kTextBaselinePx = 30;  // cap height of the font at kTextScale

double lineDistancePx(const Eigen::Vector3d& line, const Eigen::Vector2d& u) {
  return std::abs(line.x() * u.x() + line.y() * u.y() + line.z()) / std::hypot(line.x(), line.y());
}

}  // namespace

std::string EdgeCheckOptions::validate() const {
  std::ostringstream why;
  if (!(residual_scale_px > 0.0))
    why << "residual_scale_px must be > 0";
  else if (point_radius_px < 0 || point_radius_px > 50)
    why << "point_radius_px must be in [0, 50]";
  else if (line_style.thickness_px < 1)
    why << "line_style.thickness_px must be >= 1";
  else if (!(line_style.sample_step_px > 0.0))
    why << "line_style.sample_step_px must be > 0";
  return why.str();
}

Expected<EdgeCheck> checkProjectedEdges(const LidarBoardFeatures& lidar,
                                        const CameraBoardFeatures& image, const CameraModel& camera,
                                        const Eigen::Isometry3d& camera_T_lidar,
                                        const EdgeCheckOptions& options) {
  const std::string why = options.validate();
  if (!why.empty()) return Expected<EdgeCheck>::failure("edge check options: " + why);
  if (!lidar.found) return Expected<EdgeCheck>::failure("no LiDAR board (" + lidar.reason + ")");
  if (!image.found) return Expected<EdgeCheck>::failure("no image board (" + image.reason + ")");

  // Undistorted pixels of every LiDAR edge point in front of the camera (the scored set
  // includes points off the image: the image lines extend there).
  std::array<Points2, kNumEdges> undistorted;
  std::array<std::vector<Eigen::Vector3d>, kNumEdges> in_camera;
  int lidar_edges = 0;
  for (int j = 0; j < kNumEdges; ++j) {
    if (!lidar.edge_valid[j]) continue;
    ++lidar_edges;
    for (const Eigen::Vector3d& p : lidar.edge_points[j]) {
      const Eigen::Vector3d pc = camera_T_lidar * p;
      Eigen::Vector2d u;
      if (!camera.projectUndistorted(pc, &u)) continue;
      undistorted[j].push_back(u);
      in_camera[j].push_back(pc);
    }
  }
  if (lidar_edges == 0) return Expected<EdgeCheck>::failure("the LiDAR board has no valid edge");
  if (std::none_of(image.edge_valid.begin(), image.edge_valid.end(), [](bool v) { return v; }))
    return Expected<EdgeCheck>::failure("the image board has no valid edge line");

  // LiDAR edge j -> image line: the association the solvers use (core/common/edge_association.h),
  // so the overlay scores the pairs the solver fitted.
  std::array<int, kNumEdges> assignment{{0, 1, 2, 3}};
  if (options.reassociate) {
    const EdgeAssociation a = associateEdges(camera.K(), image, lidar, camera_T_lidar);
    for (int k = 0; k < kNumEdges; ++k) assignment[a.lidar_edge[k]] = k;
  }

  EdgeCheck check;
  double sum = 0;
  for (int j = 0; j < kNumEdges; ++j) {
    check.mean_residual_px[j] = std::numeric_limits<double>::quiet_NaN();
    const int k = assignment[j];
    if (undistorted[j].empty() || !image.edge_valid[k]) continue;
    check.image_edge[j] = k;
    double edge_sum = 0;
    for (size_t n = 0; n < undistorted[j].size(); ++n) {
      EdgePointCheck pc;
      pc.residual_px = lineDistancePx(image.edge_lines[k], undistorted[j][n]);
      edge_sum += pc.residual_px;
      // Drawn only where the camera sees it; scored regardless.
      if (camera.isVisible(in_camera[j][n])) {
        camera.project(in_camera[j][n], &pc.pixel);
        check.points[j].push_back(pc);
      }
      ++check.num_points;
    }
    check.mean_residual_px[j] = edge_sum / undistorted[j].size();
    sum += edge_sum;
  }
  if (check.num_points == 0)
    return Expected<EdgeCheck>::failure(
        "no LiDAR edge point projects in front of the camera with this extrinsic");
  check.mlre_px = sum / check.num_points;
  return check;
}

Status drawEdgeCheck(const CameraBoardFeatures& image, const EdgeCheck& check,
                     const CameraModel& camera, const EdgeCheckOptions& options,
                     cv::Mat* bgr_image) {
  const std::string why = options.validate();
  if (!why.empty()) return Status::failure("edge check options: " + why);
  if (bgr_image == nullptr || bgr_image->empty()) return Status::failure("image is empty");
  if (bgr_image->type() == CV_8UC1) cv::cvtColor(*bgr_image, *bgr_image, cv::COLOR_GRAY2BGR);
  if (bgr_image->type() != CV_8UC3) return Status::failure("image must be 8-bit mono or bgr");

  for (int k = 0; k < kNumEdges; ++k)
    if (image.edge_valid[k])
      drawUndistortedLine(image.edge_lines[k], camera, options.line_style, bgr_image);

  for (int j = 0; j < kNumEdges; ++j) {
    for (const EdgePointCheck& p : check.points[j]) {
      // White at 0 px to magenta at residual_scale_px and beyond, ringed in black: neither hue
      // is in the depth/intensity colour map (jet) of the cloud drawn underneath.
      const double s = std::clamp(p.residual_px / options.residual_scale_px, 0.0, 1.0);
      const cv::Scalar color(255, 255.0 * (1.0 - s), 255);
      const int radius = std::max(options.point_radius_px, 1);
      const cv::Point2d centre(p.pixel.x(), p.pixel.y());
      cv::circle(*bgr_image, centre, radius + 1, cv::Scalar(0, 0, 0), cv::FILLED, cv::LINE_AA);
      cv::circle(*bgr_image, centre, radius, color, cv::FILLED, cv::LINE_AA);
    }
  }

  if (options.annotate) {
    std::ostringstream text;
    text.setf(std::ios::fixed);
    text.precision(2);
    text << "MLRE " << check.mlre_px << " px (" << check.num_points << " pts)";
    const cv::Point origin(kTextMarginPx, kTextMarginPx + kTextBaselinePx);
    // Dark outline keeps the text readable on bright boards.
    cv::putText(*bgr_image, text.str(), origin, cv::FONT_HERSHEY_SIMPLEX, kTextScale,
                cv::Scalar(0, 0, 0), kTextThickness + 3, cv::LINE_AA);
    cv::putText(*bgr_image, text.str(), origin, cv::FONT_HERSHEY_SIMPLEX, kTextScale,
                cv::Scalar(255, 255, 255), kTextThickness, cv::LINE_AA);
  }
  return Status::success();
}

}  // namespace board_calib
