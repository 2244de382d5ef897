// Rig report folder (see rig_report.h).
#include <board_calib/core/pipeline/rig_report.h>

#include "rig_overlays.h"

#include <board_calib/core/file_io.h>
#include <board_calib/core/report/report.h>
#include <board_calib/core/rig/rig_summary.h>

#include <cmath>
#include <iomanip>
#include <sstream>

namespace board_calib {
namespace {

int sensorIndexOfFrame(const multi_sensor::MsgSolution& s, const std::string& frame) {
  for (size_t k = 0; k < s.sensors.size(); ++k)
    if (s.sensors[k].frame == frame) return static_cast<int>(k);
  return -1;
}

// Residuals of one view at camera_T_lidar, in the fields the pair report's figures read.
ViewResidual viewResidual(const View& v, const Eigen::Isometry3d& T) {
  ViewResidual vr;
  vr.view_id = v.id;
  vr.used = true;
  std::vector<double> r;
  for (const auto& p : v.lidar.board_points) {
    const double d = v.camera.plane.signedDistance(T * p);
    if (std::isfinite(d)) r.push_back(d);
  }
  vr.plane = residualStats(r);
  for (int e = 0; e < kNumEdges; ++e) {
    vr.edges[e].mlre_px = edgeLineReprojectionErrorPx(v, e, T);
    vr.edges[e].used = vr.edges[e].mlre_px.has_value();
    vr.edges[e].lidar_edge = e;
  }
  vr.mlre_px = viewLineReprojectionErrorPx(v, T);
  return vr;
}

CalibrationSolution evaluatePair(const std::vector<View>& views, const PairEntry& pair,
                                 const multi_sensor::PairEstimate* est,
                                 const multi_sensor::MsgSolution& s) {
  CalibrationSolution e;
  e.method = Method::kMsgPair;
  e.camera_T_lidar = pair.camera_T_lidar;
  e.final_cost = s.final_cost;
  e.solve_time_ms = s.solve_time_ms;
  if (views.empty()) {
    e.reason = "no board pose seen by both sensors";
    return e;
  }
  e.success = true;
  e.views_used = static_cast<int>(views.size());
  for (const auto& v : views) e.views.push_back(viewResidual(v, pair.camera_T_lidar));
  e.mlre_px = meanLineReprojectionErrorPx(views, pair.camera_T_lidar);
  if (const auto rms = planeRmsM(views, pair.camera_T_lidar)) e.plane_rms_mm = *rms * 1000.0;
  if (est && est->has_covariance) {
    e.covariance = est->covariance;
    e.stddev = est->stddev;
  }
  e.notes.push_back(
      "judged at the rig graph's camera_T_lidar (MSG-Cal over every sensor), not a pair solve");
  return e;
}

std::string pairTable(const std::vector<RigPairEvaluation>& pairs) {
  std::ostringstream md;
  md << std::fixed
     << "| camera <- LiDAR | shared poses | MLRE px | plane RMS mm | 1 sigma t mm (max) | "
     << "1 sigma r deg (max) | page |\n|---|---|---|---|---|---|---|\n";
  for (const auto& p : pairs) {
    const auto& e = p.evaluation;
    md << "| " << p.camera_frame << " <- " << p.lidar_frame << " | " << p.views.size() << " | ";
    if (e.mlre_px)
      md << std::setprecision(2) << *e.mlre_px;
    else
      md << "n/a";
    md << " | " << std::setprecision(1) << e.plane_rms_mm << " | "
       << 1000.0 * e.stddev.translation_m.maxCoeff() << " | " << std::setprecision(3)
       << e.stddev.rotation_deg.maxCoeff() << " | [" << p.folder << "](" << p.folder
       << "/report.md) |\n";
  }
  return md.str();
}

std::string graphDetails(const multi_sensor::MsgSolution& s) {
  std::ostringstream md;
  md << std::fixed;
  if (!s.rejected.empty()) {
    md << "\n## Rejected observations\n\n";
    for (const auto& r : s.rejected)
      md << "* pose " << r.pose_id << ", sensor `" << s.sensors[r.sensor].frame << "`: median "
         << std::setprecision(1) << r.median_whitened << " sigma\n";
  }
  md << "\n## Pairwise links\n\n| a | b | shared | used | rot diff to graph (deg) | trans diff "
        "(mm) | tree | note |\n"
     << "|---|---|---|---|---|---|---|---|\n";
  for (const auto& l : s.links)
    md << "| " << s.sensors[l.a].frame << " | " << s.sensors[l.b].frame << " | " << l.shared_views
       << " | " << l.views_used << " | " << std::setprecision(3) << l.graph_rotation_diff_deg
       << " | " << std::setprecision(1) << l.graph_translation_diff_mm << " | "
       << (l.in_spanning_tree ? "yes" : "") << " | " << (l.success ? "" : l.reason) << " |\n";
  return md.str();
}

// The pair's figures in the words of the pair report (no solver figures: the graph solved it).
std::string pairSummary(const RigPairEvaluation& p) {
  const CalibrationSolution& e = p.evaluation;
  std::ostringstream o;
  o << std::fixed;
  if (!e.success) {
    o << "no figures: " << e.reason << "\n";
    return o.str();
  }
  o << "camera_T_lidar                   " << poseLine(e.camera_T_lidar) << "\n";
  o << "board poses seen by both         " << e.views_used << "\n";
  if (e.mlre_px)
    o << "MLRE                             " << std::setprecision(2) << *e.mlre_px
      << " px  (mean distance of LiDAR edge points to the image edge lines)\n";
  else
    o << "MLRE                             n/a (no edge seen by both)\n";
  o << "plane RMS                        " << std::setprecision(1) << e.plane_rms_mm
    << " mm  (LiDAR board points to the camera's board plane; includes the LiDAR's range noise)\n";
  o << "1 sigma translation [mm]         " << std::setprecision(2)
    << 1e3 * e.stddev.translation_m.x() << " " << 1e3 * e.stddev.translation_m.y() << " "
    << 1e3 * e.stddev.translation_m.z() << "\n";
  o << "1 sigma rotation [deg]           " << std::setprecision(3) << e.stddev.rotation_deg.x()
    << " " << e.stddev.rotation_deg.y() << " " << e.stddev.rotation_deg.z() << "\n";
  for (const auto& n : e.notes) o << "note: " << n << "\n";
  return o.str();
}

std::string overlaysSection(const std::vector<RigOverlay>& overlays, const std::string& note) {
  std::ostringstream md;
  md << "\n## Overlays per camera\n\n";
  if (overlays.empty()) {
    md << (note.empty() ? "No kept camera image belongs to a board pose with a LiDAR." : note)
       << "\n";
    return md.str();
  }
  md << "Every LiDAR of a pose drawn on the camera's raw image at the graph's camera_T_lidar: its "
        "board points (one colour per LiDAR) and its edge points against the image edge lines "
        "(white to magenta by residual). Board points inside the image board: the share that "
        "lands inside the board's four image lines.\n\n"
     << rigOverlaysMarkdown(overlays, "", "", "");
  return md.str();
}

Status writePairPage(const std::string& dir, const RigPairEvaluation& p, const PlotOptions& plots,
                     const std::vector<RigOverlay>& overlays) {
  if (Status st = createFolder(dir, "report folder"); !st) return st;
  std::ostringstream md;
  md << "# " << p.camera_frame << " <- " << p.lidar_frame
     << " (MSG-Cal rig pair)\n\n[rig report](../report.md)\n\n";
  md << "```\n" << pairSummary(p) << "```\n\n";
  if (p.evaluation.success) {
    const auto figures = writeReportFigures(dir, p.views, {p.evaluation}, 0, plots);
    if (!figures) return Status::failure(figures.error());
    md << reportFiguresMarkdown(*figures, {}, plots);
    md << "## Per view\n\n" << perViewTable(p.evaluation);
  }
  md << "\n## Overlays\n\n" << rigOverlaysMarkdown(overlays, p.camera_frame, p.lidar_frame, "../");
  return writeFileAtomic(dir + "/report.md", md.str());
}

}  // namespace

std::vector<RigPairEvaluation> evaluateRigPairs(const multi_sensor::MsgProblem& problem,
                                                const multi_sensor::MsgSolution& solution,
                                                const ResultFile& result) {
  std::vector<RigPairEvaluation> out;
  for (size_t i = 0; i < result.pairs.size(); ++i) {
    const PairEntry& pair = result.pairs[i];
    RigPairEvaluation p;
    p.camera_frame = pair.camera_frame;
    p.lidar_frame = pair.lidar_frame;
    p.folder = pair.camera_frame + "__" + pair.lidar_frame;
    const int c = sensorIndexOfFrame(solution, pair.camera_frame);
    const int l = sensorIndexOfFrame(solution, pair.lidar_frame);
    p.views = multi_sensor::pairViews(problem, c, l);
    // msgResultFile keeps the solution's pair order.
    const multi_sensor::PairEstimate* est =
        i < solution.pairs.size() ? &solution.pairs[i] : nullptr;
    p.evaluation = evaluatePair(p.views, pair, est, solution);
    out.push_back(std::move(p));
  }
  return out;
}

Status writeRigReport(const std::string& dir, const RigConfig& rig,
                      const multi_sensor::MsgProblem& problem,
                      const multi_sensor::MsgSolution& solution, const ResultFile& result,
                      const RigReportInputs& inputs) {
  if (const std::string why = inputs.plots.validate(); !why.empty()) return Status::failure(why);
  if (Status st = createFolder(dir, "report folder"); !st) return st;
  const std::vector<RigPairEvaluation> pairs = evaluateRigPairs(problem, solution, result);
  const auto overlays = writeRigOverlays(dir, problem, solution, result, inputs.camera_frames);
  if (!overlays) return Status::failure("overlays: " + overlays.error());
  for (const auto& p : pairs)
    if (const Status st = writePairPage(dir + "/" + p.folder, p, inputs.plots, *overlays); !st)
      return st;

  std::ostringstream md;
  md << "# board_calib MSG-Cal report\n\n" << inputs.source << "\n\n";
  if (!inputs.verdict_text.empty()) md << "## Verdict\n\n```\n" << inputs.verdict_text << "```\n\n";
  md << "## Input\n\n";
  for (const auto& line : inputs.input_lines) md << "* " << line << "\n";
  md << "* " << problem.poses.size() << " board poses seen by two or more sensors\n\n";
  md << "## Result\n\n```\n"
     << rigSolutionSummary(rig, solution, result) << inputs.extra_result_text << "```\n\n";
  md << "## Camera <- LiDAR pairs\n\nEvery pair judged at the graph's pose on the board poses both "
        "sensors saw; "
        "each page has the pair report's figures (per-edge MLRE with outliers, pose coverage) and "
        "per-view "
        "residuals.\n\n"
     << pairTable(pairs);
  md << overlaysSection(*overlays, inputs.overlays_note);
  md << graphDetails(solution);
  if (const Status st = writeFileAtomic(dir + "/report.md", md.str()); !st) return st;
  return writeResultFile(dir + (inputs.failed ? "/result.failed.yaml" : "/result.yaml"), result);
}

}  // namespace board_calib
