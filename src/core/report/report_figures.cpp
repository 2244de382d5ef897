// The report's figure files and the Markdown section that links them and the overlays (see
// report_plots.h); the charts themselves are drawn in plots.cpp.
#include <board_calib/core/common/format.h>
#include <board_calib/core/report/report_plots.h>

#include <opencv2/imgcodecs.hpp>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <sstream>

namespace board_calib {

Expected<ReportFigures> writeReportFigures(const std::string& dir, const std::vector<View>& views,
                                           const std::vector<CalibrationSolution>& solutions,
                                           int chosen, const PlotOptions& o) {
  if (auto why = o.validate(); !why.empty())
    return Expected<ReportFigures>::failure("plot options: " + why);
  ReportFigures f;
  const auto save = [&](const std::string& name, const Expected<cv::Mat>& img,
                        std::string* written) -> Status {
    if (!img) {
      f.skipped.push_back(name + ": " + img.error());
      return Status::success();
    }
    const std::string path = dir + "/" + name;
    try {
      if (!cv::imwrite(path, *img)) return Status::failure("cannot write " + path);
    } catch (const cv::Exception& e) {
      return Status::failure("cannot write " + path + ": " + e.what());
    }
    *written = name;
    return Status::success();
  };
  if (chosen >= 0 && chosen < static_cast<int>(solutions.size())) {
    if (Status st = save("edge_errors.png", plotEdgeErrors(solutions[chosen], o), &f.edge_errors);
        !st)
      return Expected<ReportFigures>::failure(st.reason);
    f.outliers = findEdgeOutliers(solutions[chosen], o);
  } else {
    f.skipped.push_back("edge_errors.png: no reported solution");
  }
  if (Status st = save("pose_coverage.png", plotPoseCoverage(views, o), &f.pose_coverage); !st)
    return Expected<ReportFigures>::failure(st.reason);
  if (solutions.size() > 1) {
    if (Status st =
            save("methods.png", plotMethodComparison(solutions, chosen, o), &f.method_comparison);
        !st)
      return Expected<ReportFigures>::failure(st.reason);
  }
  return f;
}

std::string reportFiguresMarkdown(const ReportFigures& f, const std::vector<std::string>& overlays,
                                  const PlotOptions& o) {
  std::ostringstream md;
  md << "## Figures\n\n";
  if (!f.edge_errors.empty()) {
    md << "Line re-projection error (MLRE) of every edge of every view, as MATLAB's Lidar Camera "
          "Calibrator "
          "shows it; `*` marks a view not used in the solve.\n\n![Per-edge MLRE]("
       << f.edge_errors << ")\n\n";
    if (f.outliers.empty()) {
      md << "No outlier edge (none above " << formatFixed(o.outlier_factor, 0)
         << " x the median edge MLRE).\n\n";
    } else {
      md << "**Outlier edges** (MLRE above " << formatFixed(o.outlier_factor, 0)
         << " x the median edge MLRE of " << formatFixed(f.outliers.front().median_px, 2)
         << " px): check these views' overlays (a hand on the edge, a wrong image line, a bent "
            "board) and drop "
            "them (`--load-session` after editing, or the calibrator's `~drop_view`) if they are "
            "wrong:\n\n";
      for (const auto& q : f.outliers)
        md << "* view " << q.view_id << ", edge " << edgeName(q.edge) << ": "
           << formatFixed(q.mlre_px, 1) << " px\n";
      md << "\n";
    }
  }
  if (!f.pose_coverage.empty())
    md << "Board poses: distance and tilt (tilts of both signs about both axes constrain the "
          "rotation and the "
          "translation along the optical axis), and where the board was in the image.\n\n![Pose "
          "coverage]("
       << f.pose_coverage << ")\n\n";
  if (!f.method_comparison.empty())
    md << "The methods side by side (the reported one outlined).\n\n![Methods side by side]("
       << f.method_comparison << ")\n\n";
  for (const auto& s : f.skipped) md << "* not drawn: " << s << "\n";
  if (!f.skipped.empty()) md << "\n";
  if (!overlays.empty()) {
    md << "## Overlays\n\nEvery view with the reported result: LiDAR points coloured by depth, the "
          "detected "
          "image edges and the projected LiDAR edge points coloured by their distance to them.\n\n";
    constexpr size_t kColumns = 4;
    md << "|";
    for (size_t c = 0; c < kColumns; ++c) md << " |";
    md << "\n|";
    for (size_t c = 0; c < kColumns; ++c) md << "---|";
    md << "\n";
    for (size_t i = 0; i < overlays.size(); i += kColumns) {
      md << "|";
      for (size_t c = 0; c < kColumns; ++c) {
        if (i + c < overlays.size())
          md << " [![" << overlays[i + c] << "](" << overlays[i + c] << ")](" << overlays[i + c]
             << ")";
        md << " |";
      }
      md << "\n";
    }
    md << "\n";
  }
  return md.str();
}

std::vector<std::string> listOverlayFiles(const std::string& dir) {
  namespace fs = std::filesystem;
  std::vector<std::pair<long, std::string>> found;
  std::error_code ec;
  for (const auto& entry : fs::directory_iterator(dir, ec)) {
    const std::string name = entry.path().filename().string();
    const std::string ext = entry.path().extension().string();
    if (name.rfind("overlay_", 0) != 0 || (ext != ".jpg" && ext != ".png")) continue;
    const std::string stem = entry.path().stem().string();
    const size_t digits = stem.find_last_not_of("0123456789");
    const long number = digits + 1 < stem.size() ? std::stol(stem.substr(digits + 1)) : -1;
    found.emplace_back(number, name);
  }
  std::sort(found.begin(), found.end());
  std::vector<std::string> names;
  for (auto& [n, name] : found) names.push_back(std::move(name));
  return names;
}

Expected<ReportFigures> appendReportFigures(const std::string& dir, const std::vector<View>& views,
                                            const std::vector<CalibrationSolution>& solutions,
                                            int chosen, const PlotOptions& o) {
  auto f = writeReportFigures(dir, views, solutions, chosen, o);
  if (!f) return f;
  std::ofstream md(dir + "/report.md", std::ios::app);
  if (!md) return Expected<ReportFigures>::failure("cannot append to " + dir + "/report.md");
  md << "\n" << reportFiguresMarkdown(*f, listOverlayFiles(dir), o);
  if (!md) return Expected<ReportFigures>::failure("cannot append to " + dir + "/report.md");
  return f;
}
}  // namespace board_calib
