#include <board_calib/core/file_io.h>
#include <board_calib/core/pipeline/pair_report.h>
#include <board_calib/core/projection/view_overlay.h>
#include <board_calib/core/report/report.h>
#include <board_calib/core/report/report_plots.h>

#include <opencv2/imgcodecs.hpp>

#include <sstream>

namespace board_calib {
namespace {

constexpr int kOverlayJpegQuality = 85;

std::string reportMarkdown(const PairCalibration& run, const PairSession& session,
                           const PairReportInputs& in,
                           const std::vector<CalibrationSolution>& solutions) {
  const ResultFile& result = run.result;
  std::ostringstream md;
  md << "# board_calib report\n\n"
     << in.source << "\n\ncamera frame `" << result.camera_frame << "`, LiDAR frame `"
     << result.lidar_frame << "`, " << session.views().size() << " views\n\n";
  if (!in.detection.empty()) md << in.detection << "\n\n";
  md << "## Verdict: " << verdictName(run.verdict) << "\n\n```\n"
     << verdictSummary(run) << "```\n\n";
  md << "## Result\n\n```\n";
  std::vector<PoseStddev> judged;
  for (const auto& r : run.runs) {
    md << solutionSummary(r.solution, &r.verdict.stddev);
    judged.push_back(r.verdict.stddev);
  }
  md << "```\n\n";
  if (solutions.size() > 1)
    md << "## Methods side by side\n\n" << comparisonTable(solutions, &judged) << "\n";
  if (!result.notes.empty()) {
    md << "## Findings\n\n";
    for (const auto& n : result.notes) md << "* " << n << "\n";
    md << "\n";
  }
  md << "## Views\n\n";
  for (const auto& sv : session.views()) md << "* view " << sv.view.id << ": " << sv.why << "\n";
  const CalibrationSolution& shown = run.shownRun().solution;
  md << "\n## Per-view residuals (" << methodName(shown.method) << ")\n\n"
     << perViewTable(shown) << "\n";
  const CoverageReport cov = session.coverage();
  md << "## Coverage\n\ntilt span " << cov.tilt_span_deg << " deg, range " << cov.range_min_m << "-"
     << cov.range_max_m << " m, image coverage " << cov.image_coverage * 100 << " %\n\n";
  for (const auto& a : cov.advice) md << "* " << a << "\n";
  return md.str();
}

}  // namespace

Status writePairReport(const std::string& dir, const PairCalibration& run,
                       const PairSession& session, const PairReportInputs& in) {
  if (run.runs.empty())
    return Status::failure("nothing to report: no method was run (" + run.reason + ")");
  if (Status st = createFolder(dir, "report folder"); !st) return st;
  std::vector<CalibrationSolution> solutions;
  for (const auto& r : run.runs) solutions.push_back(r.solution);
  const ResultFile& result = run.result;
  const std::string child = in.child_frame.empty() ? result.camera_frame : in.child_frame;

  if (Status st = writeFileAtomic(dir + "/report.md", reportMarkdown(run, session, in, solutions));
      !st)
    return st;
  if (Status st =
          writeResultFile(dir + (run.failed() ? "/result.failed.yaml" : "/result.yaml"), result);
      !st)
    return st;
  if (!run.failed()) {  // no ready-to-use snippet of a failed calibration
    if (Status st = writeFileAtomic(dir + "/static_transform.launch",
                                    staticTransformLaunchSnippet(result, child));
        !st)
      return st;
    if (Status st = writeFileAtomic(dir + "/urdf_joint.xml", urdfJointSnippet(result, child)); !st)
      return st;
  }
  if (Status st = session.save(dir + "/session.yaml"); !st) return st;

  // Overlays: the projected cloud and the projected-edges check of every view with its frames.
  const CalibrationSolution& shown = run.shownRun().solution;
  if (in.camera && in.view_images && in.view_clouds) {
    for (const auto& sv : session.views()) {
      const auto img = in.view_images->find(sv.view.id);
      const auto cloud = in.view_clouds->find(sv.view.id);
      if (img == in.view_images->end() || cloud == in.view_clouds->end()) continue;
      cv::Mat canvas = img->second.clone();
      // A view that cannot be drawn keeps its raw image: the report still shows the frame.
      (void)drawViewOverlay(sv.view, &cloud->second, *in.camera, shown.camera_T_lidar,
                            ViewOverlayStyle{}, &canvas);
      const std::string path = dir + "/overlay_view_" + std::to_string(sv.view.id) + ".jpg";
      if (!cv::imwrite(path, canvas, {cv::IMWRITE_JPEG_QUALITY, kOverlayJpegQuality}))
        return Status::failure("cannot write '" + path + "'");
    }
  }
  // Figures (per-edge errors, pose coverage, methods) and links to every overlay.
  if (auto figures = appendReportFigures(dir, run.used_views, solutions, run.chosen); !figures)
    return Status::failure("report figures: " + figures.error());
  return Status::success();
}

}  // namespace board_calib
