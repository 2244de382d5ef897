// Rig report overlays (see rig_overlays.h).
#include "rig_overlays.h"

#include <board_calib/core/common/format.h>
#include <board_calib/core/file_io.h>
#include <board_calib/core/projection/view_overlay.h>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <array>
#include <cctype>
#include <sstream>

namespace board_calib {
namespace {

constexpr int kOverlayJpegQuality = 85;
constexpr double kLegendScale = 0.9;
constexpr int kLegendThickness = 2;
constexpr int kLegendMarginPx = 12;
constexpr int kLegendLinePx = 30;
// One flat colour per LiDAR (BGR), so two LiDARs' board points can be told apart on one image.
const std::array<cv::Vec3b, 4> kLidarColours{
    {{0, 165, 255}, {255, 0, 255}, {0, 255, 255}, {255, 128, 0}}};

std::string fileSafe(const std::string& name) {
  std::string out = name;
  for (char& ch : out)
    if (!std::isalnum(static_cast<unsigned char>(ch)) && ch != '-' && ch != '_') ch = '_';
  return out;
}

const PairEntry* pairOf(const ResultFile& result, const std::string& camera,
                        const std::string& lidar) {
  for (const auto& p : result.pairs)
    if (p.camera_frame == camera && p.lidar_frame == lidar) return &p;
  return nullptr;
}

std::string percent(const std::optional<double>& share) {
  return share ? formatFixed(100.0 * *share, 1) + " %" : "n/a";
}

std::string pixels(const std::optional<double>& px) {
  return px ? formatFixed(*px, 2) + " px" : "n/a";
}

// Every LiDAR of `pose` drawn on one camera image; the legend names each in its colour.
Expected<RigOverlay> drawPose(const multi_sensor::BoardPoseObservation& pose, int camera,
                              const RigFrame& frame, const multi_sensor::MsgSolution& solution,
                              const ResultFile& result, cv::Mat* canvas) {
  auto model = CameraModel::create(frame.intrinsics);
  if (!model) return Expected<RigOverlay>::failure("camera model: " + model.error());
  RigOverlay overlay;
  overlay.camera_frame = solution.sensors[static_cast<size_t>(camera)].frame;
  overlay.pose_id = pose.id;
  View view;
  view.id = pose.id;
  view.camera = pose.cameras.at(camera);
  size_t colour = 0;
  for (const auto& [sensor, lidar] : pose.lidars) {
    const std::string& lidar_frame = solution.sensors[static_cast<size_t>(sensor)].frame;
    const PairEntry* pair = pairOf(result, overlay.camera_frame, lidar_frame);
    if (!pair || !lidar.found) continue;
    view.lidar = lidar;
    ViewOverlayStyle style;
    style.points.color_mode = ColorMode::kFlat;
    style.points.flat_color = kLidarColours[colour % kLidarColours.size()];
    style.edges.annotate = false;  // one legend line per LiDAR below instead
    std::optional<EdgeCheck> check;
    if (Status st =
            drawViewOverlay(view, nullptr, *model, pair->camera_T_lidar, style, canvas, &check);
        !st)
      return Expected<RigOverlay>::failure(st.reason);
    RigOverlayLidar l{lidar_frame,
                      boardPointsInsideImageBoard(lidar, view.camera, pair->camera_T_lidar),
                      check ? std::optional<double>(check->mlre_px) : std::nullopt};
    const std::string legend =
        lidar_frame + ": board points inside " + percent(l.inside) + ", MLRE " + pixels(l.mlre_px);
    const cv::Vec3b& c = style.points.flat_color;
    const cv::Point at(kLegendMarginPx,
                       kLegendMarginPx + kLegendLinePx * static_cast<int>(colour + 1));
    // A dark outline keeps the line readable on any background.
    cv::putText(*canvas, legend, at, cv::FONT_HERSHEY_SIMPLEX, kLegendScale, cv::Scalar(0, 0, 0),
                kLegendThickness + 3);
    cv::putText(*canvas, legend, at, cv::FONT_HERSHEY_SIMPLEX, kLegendScale,
                cv::Scalar(c[0], c[1], c[2]), kLegendThickness);
    overlay.lidars.push_back(std::move(l));
    ++colour;
  }
  return overlay;
}

}  // namespace

Expected<std::vector<RigOverlay>> writeRigOverlays(const std::string& dir,
                                                   const multi_sensor::MsgProblem& problem,
                                                   const multi_sensor::MsgSolution& solution,
                                                   const ResultFile& result,
                                                   const std::vector<RigCameraFrames>& frames) {
  using Out = Expected<std::vector<RigOverlay>>;
  std::vector<RigOverlay> out;
  for (const auto& camera : frames) {
    if (camera.sensor < 0 || camera.sensor >= static_cast<int>(solution.sensors.size())) continue;
    for (const auto& pose : problem.poses) {
      const auto seen = pose.cameras.find(camera.sensor);
      if (seen == pose.cameras.end() || pose.lidars.empty()) continue;
      const auto frame = camera.images.find(seen->second.stamp);
      if (frame == camera.images.end() || frame->second.image.empty()) continue;
      cv::Mat canvas = frame->second.image.clone();
      auto overlay = drawPose(pose, camera.sensor, frame->second, solution, result, &canvas);
      if (!overlay) return Out::failure(overlay.error());
      if (overlay->lidars.empty()) continue;
      overlay->file = "overlays/" + fileSafe(overlay->camera_frame) + "_pose_" +
                      std::to_string(pose.id) + ".jpg";
      if (Status st = createFolder(dir + "/overlays", "overlay folder"); !st)
        return Out::failure(st.reason);
      const std::string path = dir + "/" + overlay->file;
      if (!cv::imwrite(path, canvas, {cv::IMWRITE_JPEG_QUALITY, kOverlayJpegQuality}))
        return Out::failure("cannot write '" + path + "'");
      out.push_back(std::move(*overlay));
    }
  }
  return out;
}

std::string rigOverlaysMarkdown(const std::vector<RigOverlay>& overlays,
                                const std::string& camera_frame, const std::string& lidar_frame,
                                const std::string& prefix) {
  std::ostringstream md;
  md << "| camera | pose | LiDAR | board points inside the image board | MLRE | overlay |\n"
     << "|---|---|---|---|---|---|\n";
  for (const auto& o : overlays) {
    if (!camera_frame.empty() && o.camera_frame != camera_frame) continue;
    for (const auto& l : o.lidars) {
      if (!lidar_frame.empty() && l.frame != lidar_frame) continue;
      md << "| " << o.camera_frame << " | " << o.pose_id << " | " << l.frame << " | "
         << percent(l.inside) << " | " << pixels(l.mlre_px) << " | [" << o.file << "](" << prefix
         << o.file << ") |\n";
    }
  }
  return md.str();
}

}  // namespace board_calib
