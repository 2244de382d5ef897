// The calibrator's /diagnostics status as other programs read it (the rviz panel): hardware id
// and the keys of its key/value pairs, defined once for the writer and the readers.
#pragma once

namespace board_calib::calibrator_status {

constexpr const char* kHardwareId = "board_calib calibrator";
constexpr const char* kStatusName = "calibration session";  ///< suffix of the status name
constexpr const char* kServices = "services";  ///< namespace of the ~ services, e.g. /calibrator
constexpr const char* kViews = "views";        ///< number of kept views
constexpr const char* kViewIds = "view ids";   ///< kept view ids, space separated
constexpr const char* kLidarBoard = "lidar board";    ///< "found" or "not found: <reason>"
constexpr const char* kCameraBoard = "camera board";  ///< "found" or "not found: <reason>"
/// "still (n/N frames)", "moving (n/N frames)" or "no synchronised pair yet"
constexpr const char* kBoardMotion = "board motion";
constexpr const char* kLastEvent = "last event";
constexpr const char* kAdvicePrefix = "advice ";  ///< "advice 1", "advice 2", ...

}  // namespace board_calib::calibrator_status
