#include <board_calib/core/common/format.h>
#include <board_calib/core/common/statistics.h>
#include <board_calib/core/report/report_plots.h>
#include <board_calib/core/transform.h>

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <sstream>

namespace board_calib {
namespace {

constexpr int kFont = cv::FONT_HERSHEY_SIMPLEX;
constexpr double kFontScale = 0.45;
constexpr int kMarginLeft = 60, kMarginRight = 20, kMarginTop = 46, kMarginBottom = 44;  // px

const cv::Scalar kWhite(255, 255, 255), kBlack(0, 0, 0), kGrid(225, 225, 225),
    kGreyText(90, 90, 90);
const cv::Scalar kOutlier(30, 30, 220);  // BGR red
// Fewer edges than this give no median to judge an outlier by.
constexpr size_t kMinEdgesForMedian = 3;
// Per-edge colours (BGR), colour-blind friendly (Okabe-Ito): UL blue, UR bluish green, LR orange,
// LL purple.
const cv::Scalar kEdgeColour[kNumEdges] = {
    {178, 114, 0}, {115, 158, 0}, {0, 159, 230}, {167, 121, 204}};

/// 1, 2 or 5 times a power of ten, about range / 5.
double niceStep(double range) {
  if (!(range > 0)) return 1.0;
  const double raw = range / 5.0;
  const double p = std::pow(10.0, std::floor(std::log10(raw)));
  for (double m : {1.0, 2.0, 5.0})
    if (raw <= m * p) return m * p;
  return 10.0 * p;
}

void text(cv::Mat* img, const std::string& s, cv::Point at, const cv::Scalar& colour = kBlack,
          double scale = kFontScale, int thickness = 1) {
  cv::putText(*img, s, at, kFont, scale, colour, thickness, cv::LINE_AA);
}

int textWidth(const std::string& s, double scale = kFontScale) {
  int baseline = 0;
  return cv::getTextSize(s, kFont, scale, 1, &baseline).width;
}

void dashedHLine(cv::Mat* img, int x0, int x1, int y, const cv::Scalar& colour) {
  constexpr int kDash = 8;
  for (int x = x0; x < x1; x += 2 * kDash)
    cv::line(*img, {x, y}, {std::min(x + kDash, x1), y}, colour, 1, cv::LINE_AA);
}

/// A data rectangle inside an image with linear axes.
struct Axes {
  cv::Rect area;
  double x0 = 0, x1 = 1, y0 = 0, y1 = 1;

  int px(double x) const {
    return area.x + static_cast<int>(std::lround((x - x0) / (x1 - x0) * area.width));
  }
  int py(double y) const {
    return area.y + area.height - static_cast<int>(std::lround((y - y0) / (y1 - y0) * area.height));
  }

  /// Grid and labels on y (and on x when `x_ticks`), axis titles, a frame.
  void draw(cv::Mat* img, const std::string& x_title, const std::string& y_title,
            bool x_ticks) const {
    const double ys = niceStep(y1 - y0);
    for (double y = std::ceil(y0 / ys) * ys; y <= y1 + 1e-9; y += ys) {
      cv::line(*img, {area.x, py(y)}, {area.x + area.width, py(y)}, kGrid, 1);
      const std::string label = formatFixed(y, ys < 1 ? (ys < 0.1 ? 2 : 1) : 0);
      text(img, label, {area.x - 6 - textWidth(label), py(y) + 4}, kGreyText);
    }
    if (x_ticks) {
      const double xs = niceStep(x1 - x0);
      for (double x = std::ceil(x0 / xs) * xs; x <= x1 + 1e-9; x += xs) {
        cv::line(*img, {px(x), area.y}, {px(x), area.y + area.height}, kGrid, 1);
        const std::string label = formatFixed(x, xs < 1 ? 1 : 0);
        text(img, label, {px(x) - textWidth(label) / 2, area.y + area.height + 16}, kGreyText);
      }
    }
    cv::rectangle(*img, area, kGreyText, 1);
    text(img, x_title,
         {area.x + area.width / 2 - textWidth(x_title) / 2, area.y + area.height + 36});
    text(img, y_title, {area.x, area.y - 8});
  }
};

void title(cv::Mat* img, const std::string& s) { text(img, s, {kMarginLeft, 20}, kBlack, 0.55, 1); }

void legendEntry(cv::Mat* img, int* x, int y, const cv::Scalar& colour, const std::string& label) {
  cv::rectangle(*img, cv::Rect(*x, y - 10, 12, 12), colour, cv::FILLED);
  text(img, label, {*x + 16, y});
  *x += 16 + textWidth(label) + 14;
}

struct PoseSample {
  int view_id = 0;
  double distance_m = 0;
  double tilt_h_deg = 0, tilt_v_deg = 0;
};

/// Board centre distance and tilt from the camera features: the ray through the mean of the
/// corners (undistorted px) meets the camera board plane.
std::optional<PoseSample> poseSample(const View& v) {
  const CameraBoardFeatures& c = v.camera;
  if (!c.found || !c.plane.normal.allFinite()) return std::nullopt;
  Eigen::Vector2d mean = Eigen::Vector2d::Zero();
  for (const auto& p : c.corners_px) {
    if (!p.allFinite()) return std::nullopt;
    mean += p / kNumEdges;
  }
  const Eigen::Vector3d ray = c.K.inverse() * Eigen::Vector3d(mean.x(), mean.y(), 1.0);
  const double denom = c.plane.normal.dot(ray);
  if (!(std::abs(denom) > 1e-9)) return std::nullopt;
  const Eigen::Vector3d centre = ray * (c.plane.offset / denom);
  if (!(centre.z() > 0)) return std::nullopt;
  const Eigen::Vector3d& n = c.plane.normal;
  PoseSample s;
  s.view_id = v.id;
  s.distance_m = centre.norm();
  s.tilt_h_deg = (std::atan2(n.x(), n.z()) - std::atan2(centre.x(), centre.z())) * kDegPerRad;
  s.tilt_v_deg = (std::atan2(n.y(), n.z()) - std::atan2(centre.y(), centre.z())) * kDegPerRad;
  return s;
}

}  // namespace

std::string PlotOptions::validate() const {
  if (width < 320 || height < 240) return "plot size must be at least 320 x 240 px";
  if (!(outlier_factor > 1.0)) return "outlier_factor must be > 1";
  if (!(axis_clip_factor >= 1.0)) return "axis_clip_factor must be >= 1";
  return "";
}

std::vector<EdgeOutlier> findEdgeOutliers(const CalibrationSolution& s, const PlotOptions& o) {
  std::vector<double> all;
  for (const auto& v : s.views)
    for (const auto& e : v.edges)
      if (e.used && e.mlre_px) all.push_back(*e.mlre_px);
  std::vector<EdgeOutlier> out;
  if (all.size() < kMinEdgesForMedian) return out;
  const double med = medianOf(all);
  for (const auto& v : s.views)
    for (int j = 0; j < kNumEdges; ++j) {
      const auto& e = v.edges[j];
      if (e.used && e.mlre_px && *e.mlre_px > o.outlier_factor * med)
        out.push_back({v.view_id, j, *e.mlre_px, med});
    }
  return out;
}

namespace {

// One edge's bar: outliers in red with their value, a clipped bar with a broken top, an edge
// not used in the solve outlined.
void drawEdgeBar(double value, bool used, bool outlier, int x, int bar, const cv::Scalar& colour,
                 const Axes& ax, cv::Mat* out) {
  cv::Mat& img = *out;
  const bool clipped = value > ax.y1;
  const int y = ax.py(std::min(value, ax.y1));
  const cv::Rect r(x, y, std::max(1, bar - 1), ax.area.y + ax.area.height - y);
  cv::rectangle(img, r, outlier ? kOutlier : colour, cv::FILLED);
  if (!used) cv::rectangle(img, r, kGreyText, 1);  // drawn but not part of the solve
  if (clipped) {                                   // a broken top: two white slashes
    cv::line(img, {x, y + 8}, {x + bar - 1, y + 4}, kWhite, 2);
    cv::line(img, {x, y + 14}, {x + bar - 1, y + 10}, kWhite, 2);
  }
  if (outlier) {  // value on top; beside the break of a clipped bar
    const std::string label = formatFixed(value, value < 10 ? 1 : 0);
    const cv::Point at = clipped ? cv::Point(x + bar + 2, y + 14)
                                 : cv::Point(x + bar / 2 - textWidth(label, 0.4) / 2, y - 4);
    text(&img, label, at, kOutlier, 0.4);
  }
}

}  // namespace

Expected<cv::Mat> plotEdgeErrors(const CalibrationSolution& s, const PlotOptions& o) {
  if (auto why = o.validate(); !why.empty()) return Expected<cv::Mat>::failure(why);
  std::vector<const ViewResidual*> views;
  double vmax = 0;
  std::vector<double> all;
  for (const auto& v : s.views) {
    bool any = false;
    for (const auto& e : v.edges)
      if (e.mlre_px) {
        any = true;
        vmax = std::max(vmax, *e.mlre_px);
        if (e.used) all.push_back(*e.mlre_px);
      }
    if (any) views.push_back(&v);
  }
  if (views.empty())
    return Expected<cv::Mat>::failure("no edge has an MLRE (" + std::string(methodName(s.method)) +
                                      ")");
  const std::vector<EdgeOutlier> outliers = findEdgeOutliers(s, o);
  const double threshold =
      all.size() >= kMinEdgesForMedian ? o.outlier_factor * medianOf(all) : 0.0;
  const double top = threshold > 0 ? std::min(vmax, o.axis_clip_factor * threshold) : vmax;

  cv::Mat img(o.height, o.width, CV_8UC3, kWhite);
  Axes ax;
  ax.area = cv::Rect(kMarginLeft, kMarginTop, o.width - kMarginLeft - kMarginRight,
                     o.height - kMarginTop - kMarginBottom);
  ax.x0 = 0;
  ax.x1 = static_cast<double>(views.size());
  ax.y0 = 0;
  ax.y1 = std::max(1e-3, top * 1.1);
  ax.draw(&img, "", "MLRE px", false);
  text(&img, "view", {8, ax.area.y + ax.area.height + 16}, kGreyText);
  title(&img,
        std::string("Line re-projection error per view and edge (") + methodName(s.method) + ")");

  const double slot = static_cast<double>(ax.area.width) / views.size();
  const int bar = std::max(1, static_cast<int>(slot * 0.8 / kNumEdges));
  for (size_t i = 0; i < views.size(); ++i) {
    const ViewResidual& v = *views[i];
    const int x_slot = ax.area.x + static_cast<int>(i * slot + 0.1 * slot);
    for (int j = 0; j < kNumEdges; ++j) {
      const auto& e = v.edges[j];
      if (!e.mlre_px) continue;
      const bool outlier = std::any_of(outliers.begin(), outliers.end(), [&](const EdgeOutlier& q) {
        return q.view_id == v.view_id && q.edge == j;
      });
      drawEdgeBar(*e.mlre_px, e.used, outlier, x_slot + j * bar, bar, kEdgeColour[j], ax, &img);
    }
    const std::string id = std::to_string(v.view_id) + (v.used ? "" : "*");
    text(&img, id,
         {x_slot + static_cast<int>(0.4 * slot) - textWidth(id) / 2,
          ax.area.y + ax.area.height + 16},
         kGreyText);
  }
  if (s.mlre_px && *s.mlre_px <= ax.y1)
    dashedHLine(&img, ax.area.x, ax.area.x + ax.area.width, ax.py(*s.mlre_px), kBlack);
  if (threshold > 0 && threshold <= ax.y1)
    dashedHLine(&img, ax.area.x, ax.area.x + ax.area.width, ax.py(threshold), kOutlier);

  int lx = o.width - kMarginRight - 470;
  for (int j = 0; j < kNumEdges; ++j) legendEntry(&img, &lx, 38, kEdgeColour[j], edgeName(j));
  legendEntry(&img, &lx, 38, kOutlier, "outlier");
  std::string foot = "black dashes: mean MLRE";
  if (s.mlre_px) foot += " " + formatFixed(*s.mlre_px, 2) + " px";
  if (threshold > 0)
    foot += ";  red dashes: " + formatFixed(o.outlier_factor, 0) +
            " x median edge = " + formatFixed(threshold, 1) + " px";
  text(&img, foot, {o.width - kMarginRight - textWidth(foot, 0.4), o.height - 8}, kGreyText, 0.4);
  return img;
}

namespace {

// Left half: board distance against tilt, both tilt components.
void drawDistanceTilt(const std::vector<PoseSample>& samples, const PlotOptions& o, cv::Mat* out) {
  cv::Mat& img = *out;
  const int half = o.width / 2;
  Axes ax;
  ax.area = cv::Rect(kMarginLeft, kMarginTop, half - kMarginLeft - kMarginRight,
                     o.height - kMarginTop - kMarginBottom);
  double dmin = samples[0].distance_m, dmax = dmin, tmax = 10.0;
  for (const auto& s : samples) {
    dmin = std::min(dmin, s.distance_m);
    dmax = std::max(dmax, s.distance_m);
    tmax = std::max({tmax, std::abs(s.tilt_h_deg), std::abs(s.tilt_v_deg)});
  }
  const double pad = std::max(0.25, 0.1 * (dmax - dmin));
  ax.x0 = std::max(0.0, dmin - pad);
  ax.x1 = dmax + pad;
  ax.y0 = -tmax * 1.1;
  ax.y1 = tmax * 1.1;
  ax.draw(&img, "board distance from the camera (m)", "tilt deg", true);
  cv::line(img, {ax.area.x, ax.py(0)}, {ax.area.x + ax.area.width, ax.py(0)}, kGreyText, 1);
  for (const auto& s : samples) {
    cv::circle(img, {ax.px(s.distance_m), ax.py(s.tilt_h_deg)}, 5, kEdgeColour[0], cv::FILLED,
               cv::LINE_AA);
    const cv::Point pv(ax.px(s.distance_m), ax.py(s.tilt_v_deg));
    cv::rectangle(img, cv::Rect(pv.x - 4, pv.y - 4, 9, 9), kEdgeColour[2], cv::FILLED);
  }
  int lx = ax.area.x + 80;
  legendEntry(&img, &lx, ax.area.y - 8, kEdgeColour[0], "about vertical axis");
  legendEntry(&img, &lx, ax.area.y - 8, kEdgeColour[2], "about horizontal axis");
}

// Right half: every board outline in the image, scaled to fit (corners may lie outside it).
void drawImageOutlines(const std::vector<View>& views, int image_w, int image_h,
                       const PlotOptions& o, cv::Mat* out) {
  cv::Mat& img = *out;
  const int half = o.width / 2;
  double u0 = 0, v0 = 0, u1 = image_w, v1 = image_h;
  for (const auto& v : views)
    if (v.camera.found)
      for (const auto& p : v.camera.corners_px)
        if (p.allFinite()) {
          u0 = std::min(u0, p.x());
          v0 = std::min(v0, p.y());
          u1 = std::max(u1, p.x());
          v1 = std::max(v1, p.y());
        }
  const cv::Rect panel(half + 20, kMarginTop, half - 40, o.height - kMarginTop - kMarginBottom);
  const double scale =
      std::min(panel.width / std::max(1.0, u1 - u0), panel.height / std::max(1.0, v1 - v0));
  const auto toPanel = [&](double u, double v) {
    return cv::Point(panel.x + static_cast<int>((u - u0) * scale),
                     panel.y + static_cast<int>((v - v0) * scale));
  };
  if (image_w > 0 && image_h > 0) {
    cv::rectangle(img, cv::Rect(toPanel(0, 0), toPanel(image_w, image_h)), kGreyText, 2);
    text(&img,
         "grey frame: the " + std::to_string(image_w) + " x " + std::to_string(image_h) +
             " px image",
         {panel.x, panel.y + panel.height + 30}, kGreyText);
  }
  int k = 0;
  for (const auto& v : views) {
    if (!v.camera.found) continue;
    std::vector<cv::Point> poly;
    for (const auto& p : v.camera.corners_px)
      if (p.allFinite()) poly.push_back(toPanel(p.x(), p.y()));
    if (poly.size() != kNumEdges) continue;
    const cv::Scalar colour = kEdgeColour[k++ % kNumEdges];
    cv::polylines(img, poly, true, colour, 1, cv::LINE_AA);
    cv::Point centre(0, 0);
    for (const auto& p : poly) centre += p;
    centre = cv::Point(centre.x / kNumEdges, centre.y / kNumEdges);
    const std::string id = std::to_string(v.id);
    text(&img, id, centre - cv::Point(textWidth(id, 0.4) / 2, -4), colour, 0.4);
  }
}

}  // namespace

Expected<cv::Mat> plotPoseCoverage(const std::vector<View>& views, const PlotOptions& o) {
  if (auto why = o.validate(); !why.empty()) return Expected<cv::Mat>::failure(why);
  std::vector<PoseSample> samples;
  int image_w = 0, image_h = 0;
  for (const auto& v : views) {
    if (auto s = poseSample(v)) samples.push_back(*s);
    image_w = std::max(image_w, v.camera.image_width);
    image_h = std::max(image_h, v.camera.image_height);
  }
  if (samples.empty()) return Expected<cv::Mat>::failure("no view has a camera board with corners");

  cv::Mat img(o.height, o.width, CV_8UC3, kWhite);
  title(&img, "Board poses: distance x tilt (left), outlines in the image (right)");
  drawDistanceTilt(samples, o, &img);
  drawImageOutlines(views, image_w, image_h, o, &img);
  return img;
}

Expected<cv::Mat> plotMethodComparison(const std::vector<CalibrationSolution>& solutions,
                                       int chosen, const PlotOptions& o) {
  if (auto why = o.validate(); !why.empty()) return Expected<cv::Mat>::failure(why);
  std::vector<int> ok;
  for (int i = 0; i < static_cast<int>(solutions.size()); ++i)
    if (solutions[i].success) ok.push_back(i);
  if (ok.empty()) return Expected<cv::Mat>::failure("no method succeeded");

  struct Metric {
    std::string name;
    std::vector<std::optional<double>> values;
  };
  std::vector<Metric> metrics = {{"MLRE px", {}},
                                 {"plane RMS mm", {}},
                                 {"1 sigma t mm (max)", {}},
                                 {"1 sigma r deg (max)", {}}};
  for (int i : ok) {
    const auto& s = solutions[i];
    metrics[0].values.push_back(s.mlre_px);
    metrics[1].values.push_back(s.plane_rms_mm);
    const double st = s.stddev.translation_m.maxCoeff() * 1e3,
                 sr = s.stddev.rotation_deg.maxCoeff();
    metrics[2].values.push_back(std::isfinite(st) ? std::optional<double>(st) : std::nullopt);
    metrics[3].values.push_back(std::isfinite(sr) ? std::optional<double>(sr) : std::nullopt);
  }

  cv::Mat img(o.height, o.width, CV_8UC3, kWhite);
  title(&img, "Methods side by side (outlined: reported)");
  const int panel_w = (o.width - 20) / static_cast<int>(metrics.size());
  for (size_t m = 0; m < metrics.size(); ++m) {
    double vmax = 0;
    for (const auto& v : metrics[m].values)
      if (v) vmax = std::max(vmax, *v);
    Axes ax;
    ax.area = cv::Rect(static_cast<int>(m) * panel_w + kMarginLeft, kMarginTop + 10,
                       panel_w - kMarginLeft - 10, o.height - kMarginTop - 10 - kMarginBottom);
    ax.x0 = 0;
    ax.x1 = static_cast<double>(ok.size());
    ax.y0 = 0;
    ax.y1 = vmax > 0 ? vmax * 1.2 : 1.0;
    ax.draw(&img, "", metrics[m].name, false);
    const double slot = static_cast<double>(ax.area.width) / ok.size();
    for (size_t i = 0; i < ok.size(); ++i) {
      const int x = ax.area.x + static_cast<int>((i + 0.2) * slot);
      const int w = std::max(2, static_cast<int>(0.6 * slot));
      const std::string name = methodName(solutions[ok[i]].method);
      text(&img, name, {x + w / 2 - textWidth(name) / 2, ax.area.y + ax.area.height + 16},
           kGreyText);
      const auto& v = metrics[m].values[i];
      if (!v) {
        text(&img, "-", {x + w / 2 - 3, ax.area.y + ax.area.height - 6}, kGreyText);
        continue;
      }
      const int y = ax.py(*v);
      const cv::Rect r(x, y, w, ax.area.y + ax.area.height - y);
      cv::rectangle(img, r, kEdgeColour[i % kNumEdges], cv::FILLED);
      if (ok[i] == chosen) cv::rectangle(img, r, kBlack, 2);
      const std::string label = formatFixed(*v, *v < 1 ? 3 : (*v < 10 ? 2 : 1));
      text(&img, label, {x + w / 2 - textWidth(label, 0.4) / 2, y - 4}, kBlack, 0.4);
    }
  }
  return img;
}

}  // namespace board_calib
