// The report folder of a pair calibration run, written the same way offline (calibrate_bag
// --report) and live (the calibrator on ~calibrate): report.md with the verdict first, the
// result, the methods side by side, the findings, the views and their residuals, coverage
// advice and the figures; the result file (`result.failed.yaml` for a failed run), the session,
// launch and URDF snippets (not for a failed run) and, where the raw frames are at hand, an
// overlay image per view.
#pragma once

#include <board_calib/core/camera_model.h>
#include <board_calib/core/lidar_detection/lidar_cloud.h>
#include <board_calib/core/pipeline/pair_calibration.h>
#include <board_calib/core/session/session.h>

#include <opencv2/core.hpp>

#include <map>
#include <string>

namespace board_calib {

struct PairReportInputs {
  std::string source;       ///< where the views came from, one line (bags, "live session")
  std::string detection;    ///< optional line on the detectors' hit rates
  std::string child_frame;  ///< TF child of the snippets; empty: the camera frame
  const std::map<int, cv::Mat>* view_images = nullptr;     ///< raw image per view id (optional)
  const std::map<int, LidarCloud>* view_clouds = nullptr;  ///< raw cloud per view id (optional)
  const CameraModel* camera = nullptr;                     ///< needed for the overlays
};

/// Writes the report folder `dir` (created when missing). Fails with the first file that could
/// not be written; every file is written atomically.
Status writePairReport(const std::string& dir, const PairCalibration& run,
                       const PairSession& session, const PairReportInputs& inputs);

}  // namespace board_calib
