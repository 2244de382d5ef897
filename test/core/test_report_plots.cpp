// Report figures: PNGs written at the requested size, an edge with a wrong image line flagged
// and drawn as an outlier, the Markdown section links figures and overlays.
#include <board_calib/core/report/report_plots.h>
#include "support/synthetic_views.h"

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <random>

#include <unistd.h>

namespace board_calib {
namespace {

namespace fs = std::filesystem;

constexpr int kBadView = 4;  // index of the view whose image line is moved
constexpr int kBadEdge = kUpperRight;
constexpr double kLineShiftPx = 40.0;  // a gross error, as a hand or a wrong line gives

struct Fixture {
  std::vector<View> views;
  std::vector<CalibrationSolution> solutions;  // ppc, pbpc
};

// 12 synthetic views (0.3 px line noise: edge MLREs of a few tenths of a px); optionally one
// image line moved outward by kLineShiftPx.
Fixture makeFixture(bool corrupt) {
  sim::SyntheticFeatureOptions o;
  o.num_views = 12;
  std::mt19937 rng(11);
  const Eigen::Isometry3d truth = sim::randomCameraTLidar(rng);
  auto scene = sim::generateSyntheticViews(o, truth, rng);
  EXPECT_TRUE(scene.ok()) << scene.error();
  Fixture f;
  f.views = scene->views;
  if (corrupt)
    f.views[kBadView].camera.edge_lines[kBadEdge].z() -=
        kLineShiftPx;  // (a, b) unit: moves it 40 px
  SolverOptions solver;
  for (Method m : {Method::kPpc, Method::kPbpc})
    f.solutions.push_back(calibrate(f.views, m, solver));
  for (const auto& s : f.solutions) EXPECT_TRUE(s.success) << s.reason;
  return f;
}

std::string tempDir(const std::string& name) {
  const fs::path dir =
      fs::temp_directory_path() / ("board_calib_plots_" + name + "_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir.string();
}

// Pixels of the outlier colour (BGR 30, 30, 220) in the bar area (below the legend and title).
int outlierPixels(const cv::Mat& img) {
  int n = 0;
  for (int y = 50; y < img.rows; ++y)
    for (int x = 0; x < img.cols; ++x) {
      const cv::Vec3b p = img.at<cv::Vec3b>(y, x);
      if (p[0] == 30 && p[1] == 30 && p[2] == 220) ++n;
    }
  return n;
}

TEST(ReportPlots, FlagsTheCorruptedEdgeOnly) {
  const Fixture f = makeFixture(true);
  const CalibrationSolution& pbpc = f.solutions[1];
  const auto outliers = findEdgeOutliers(pbpc, PlotOptions{});
  ASSERT_EQ(outliers.size(), 1u);
  EXPECT_EQ(outliers[0].view_id, f.views[kBadView].id);
  EXPECT_EQ(outliers[0].edge, kBadEdge);
  // The robust solve ignores the bad line, so the edge keeps most of the 40 px shift.
  EXPECT_GT(outliers[0].mlre_px, 0.5 * kLineShiftPx);
  // Clean data: 0.3 px line noise gives edge MLREs within a small factor of each other.
  EXPECT_TRUE(findEdgeOutliers(makeFixture(false).solutions[1], PlotOptions{}).empty());
}

TEST(ReportPlots, WritesFiguresAtTheRequestedSizeAndHighlightsTheOutlier) {
  const Fixture bad = makeFixture(true), good = makeFixture(false);
  PlotOptions o;
  o.width = 800;
  o.height = 360;
  const std::string dir_bad = tempDir("bad"), dir_good = tempDir("good");
  auto fb = writeReportFigures(dir_bad, bad.views, bad.solutions, 1, o);
  auto fg = writeReportFigures(dir_good, good.views, good.solutions, 1, o);
  ASSERT_TRUE(fb.ok()) << fb.error();
  ASSERT_TRUE(fg.ok()) << fg.error();
  EXPECT_TRUE(fb->skipped.empty());
  for (const std::string& name : {fb->edge_errors, fb->pose_coverage, fb->method_comparison}) {
    ASSERT_FALSE(name.empty());
    const cv::Mat img = cv::imread(dir_bad + "/" + name);
    ASSERT_FALSE(img.empty()) << name;
    EXPECT_EQ(img.cols, o.width) << name;
    EXPECT_EQ(img.rows, o.height) << name;
    EXPECT_GT(cv::countNonZero(img.reshape(1) != 255), 1000) << name << " is blank";
  }
  // The outlier bar is filled red: at least a bar's width times 100 px more red than the
  // clean chart (which only has the red threshold dashes and the legend swatch).
  const int red_bad = outlierPixels(cv::imread(dir_bad + "/" + fb->edge_errors));
  const int red_good = outlierPixels(cv::imread(dir_good + "/" + fg->edge_errors));
  EXPECT_GT(red_bad - red_good, 4 * 100) << red_bad << " vs " << red_good;
  fs::remove_all(dir_bad);
  fs::remove_all(dir_good);
}

TEST(ReportPlots, MarkdownLinksFiguresOutliersAndEveryOverlay) {
  const Fixture f = makeFixture(true);
  const std::string dir = tempDir("md");
  for (const char* name :
       {"overlay_view_10.jpg", "overlay_view_2.jpg", "overlay_view_1.jpg", "notes.txt"})
    std::ofstream(dir + "/" + name) << "x";
  { std::ofstream(dir + "/report.md") << "# board_calib report\n"; }
  auto figures = appendReportFigures(dir, f.views, f.solutions, 1);
  ASSERT_TRUE(figures.ok()) << figures.error();
  EXPECT_EQ(listOverlayFiles(dir),
            (std::vector<std::string>{"overlay_view_1.jpg", "overlay_view_2.jpg",
                                      "overlay_view_10.jpg"}));
  std::ifstream in(dir + "/report.md");
  const std::string md((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_EQ(md.rfind("# board_calib report", 0), 0u);  // appended, not overwritten
  for (const char* s : {"](edge_errors.png)", "](pose_coverage.png)", "](methods.png)",
                        "(overlay_view_1.jpg)", "(overlay_view_2.jpg)", "(overlay_view_10.jpg)"})
    EXPECT_NE(md.find(s), std::string::npos) << s;
  const std::string flagged = "view " + std::to_string(f.views[kBadView].id) + ", edge UR";
  EXPECT_NE(md.find(flagged), std::string::npos) << md;
  fs::remove_all(dir);
}

TEST(ReportPlots, NoDataGivesReasonsNotFiles) {
  CalibrationSolution empty;
  EXPECT_FALSE(plotEdgeErrors(empty, PlotOptions{}).ok());
  EXPECT_FALSE(plotPoseCoverage({}, PlotOptions{}).ok());
  EXPECT_FALSE(plotMethodComparison({empty}, -1, PlotOptions{}).ok());
  PlotOptions bad;
  bad.outlier_factor = 1.0;
  EXPECT_NE(bad.validate(), "");
  const std::string dir = tempDir("empty");
  auto f = writeReportFigures(dir, {}, {empty}, -1);
  ASSERT_TRUE(f.ok()) << f.error();
  EXPECT_EQ(f->skipped.size(), 2u);  // edge errors (no reported solution) and coverage (no views)
  EXPECT_TRUE(f->edge_errors.empty());
  EXPECT_TRUE(f->pose_coverage.empty());
  fs::remove_all(dir);
}

}  // namespace
}  // namespace board_calib
