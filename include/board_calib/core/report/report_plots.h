// Figures of the offline report, drawn with OpenCV only (no plotting library): per-view,
// per-edge line re-projection errors (MATLAB's Lidar Camera Calibrator style, outliers
// highlighted), coverage of the board poses (distance x tilt, image-plane outlines) and the
// methods side by side. Plus the Markdown section that links them and every overlay image.
#pragma once

#include <board_calib/core/features.h>
#include <board_calib/core/solvers/solvers.h>

#include <opencv2/core.hpp>

#include <string>
#include <vector>

namespace board_calib {

struct PlotOptions {
  int width = 960;   ///< px, chart width
  int height = 420;  ///< px, chart height
  /// An edge whose MLRE exceeds this multiple of the median edge MLRE (of the same solution)
  /// is flagged as an outlier. Relative to the median, so it follows the data's own noise
  /// (pixel size, LiDAR spacing) instead of a pixel constant.
  double outlier_factor = 3.0;
  /// Bars are clipped at this multiple of the outlier threshold so one gross outlier does not
  /// flatten every other bar (its value is written on the clipped bar).
  double axis_clip_factor = 2.0;

  std::string validate() const;
};

/// One edge flagged by plotEdgeErrors.
struct EdgeOutlier {
  int view_id = 0;
  int edge = 0;  ///< image edge index (edgeName)
  double mlre_px = 0.0;
  double median_px = 0.0;  ///< median edge MLRE of the solution
};

/// Outlier edges of a solution: used edges with an MLRE above options.outlier_factor x the
/// median edge MLRE. Empty when fewer than 3 edges have an MLRE (no meaningful median).
std::vector<EdgeOutlier> findEdgeOutliers(const CalibrationSolution& solution,
                                          const PlotOptions& options);

/// Bar chart: for every view, one bar per edge (UL, UR, LR, LL) with its MLRE (px); the mean
/// MLRE and the outlier threshold as horizontal lines; outliers drawn red and labelled.
/// Fails when the solution has no edge MLRE at all (e.g. PPC on a board without edges).
Expected<cv::Mat> plotEdgeErrors(const CalibrationSolution& solution, const PlotOptions& options);

/// Two panels: left, each view's board distance from the camera (m) against its tilt (deg,
/// horizontal and vertical components of the board normal against the viewing ray: both
/// signs should appear); right, every view's board outline in the image (corners in
/// undistorted px), labelled by view id. Fails without a view with a camera board.
Expected<cv::Mat> plotPoseCoverage(const std::vector<View>& views, const PlotOptions& options);

/// Small multiples, one panel per figure (MLRE px, plane RMS mm, max 1 sigma translation mm,
/// max 1 sigma rotation deg), one bar per successful method; `chosen` (index into solutions,
/// or -1) is outlined. Fails when no solution succeeded.
Expected<cv::Mat> plotMethodComparison(const std::vector<CalibrationSolution>& solutions,
                                       int chosen, const PlotOptions& options);

/// What writeReportFigures wrote (file names relative to the report folder).
struct ReportFigures {
  std::string edge_errors;  ///< empty when not drawn
  std::string pose_coverage;
  std::string method_comparison;
  std::vector<std::string> skipped;  ///< "figure: reason" for each figure not drawn
  std::vector<EdgeOutlier> outliers;
};

/// Writes the figures as PNGs into `dir` (edge_errors.png for the chosen solution,
/// pose_coverage.png, methods.png when there is more than one solution). Fails only when a
/// file cannot be written; a figure without data is listed in `skipped` with the reason.
Expected<ReportFigures> writeReportFigures(const std::string& dir, const std::vector<View>& views,
                                           const std::vector<CalibrationSolution>& solutions,
                                           int chosen, const PlotOptions& options = PlotOptions{});

/// The Markdown section linking the figures, listing the outlier edges, and linking every
/// overlay image (names relative to the report folder).
std::string reportFiguresMarkdown(const ReportFigures& figures,
                                  const std::vector<std::string>& overlay_files,
                                  const PlotOptions& options = PlotOptions{});

/// The report folder's overlay images (`overlay_*.jpg` / `.png`), sorted by the number in
/// the name (view id).
std::vector<std::string> listOverlayFiles(const std::string& dir);

/// writeReportFigures, then appends reportFiguresMarkdown (with listOverlayFiles) to
/// `dir`/report.md. Returns what was written.
Expected<ReportFigures> appendReportFigures(const std::string& dir, const std::vector<View>& views,
                                            const std::vector<CalibrationSolution>& solutions,
                                            int chosen, const PlotOptions& options = PlotOptions{});

}  // namespace board_calib
