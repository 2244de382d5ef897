// Second chance in colour: a board whose grey level matches the scene behind it (cardboard on a
// facade) still differs in colour. Where the other sensor's board projects, the colour axis that
// best separates the inside of that board from the ring around it (Fisher's discriminant of
// the two pixel sets) turns the image into one channel in which the board stands out; the plain
// detector then runs on it as on a grey image, inside the expected board only.
#include "plain_internal.h"

#include <board_calib/core/common/statistics.h>

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <deque>
#include <vector>

namespace board_calib {
namespace image_detection {
namespace {

// A pixel departs from the background by this many times the frame's median departure, and at
// least by the floor (8-bit levels: quantisation and compression).
constexpr double kForegroundMedians = 4.0;
constexpr double kForegroundFloor = 6.0;
// Parts of the foreground this convex (area over hull) are tried as boards; openings round a
// board's corners, a person or a car stays concave.
constexpr double kForegroundSolidity = 0.8;
constexpr double kForegroundCornerShare = 0.25;
constexpr size_t kMaxForegroundBoards = 4;
// A single frame's colour parts tried (each a detection in its own colour contrast; with the parts
// cut by the image border last, the board was among the first two in every frame measured).
constexpr size_t kMaxColourPartBoards = 2;
// The ring a place's colour contrast is measured against, in board sizes about its centre
// (boardContrastImage); the outer one also bounds a place's search window.
constexpr double kContrastRingInner = 1.5;
constexpr double kContrastRingOuter = 2.0;
constexpr int kWindowGridPx = 12;
// boardContrastImage's mapping: the board's and the ring's means this far either side of the
// midpoint.
constexpr double kContrastMidpoint = 127.5;
constexpr double kContrastHalfSeparation = 50.0;
// The bands either side of a colour board's side (sidesPartColours): this far from it, over the
// middle of the side.
constexpr double kBandMinPx = 3.0;
constexpr double kBandSideShare = 0.05;
constexpr double kBandFrom = 0.15;
constexpr double kBandStep = 0.02;
// Measured across the sides of true colour boards: 34-120 levels (simulated rooms and streets,
// held boards beside a same-coloured holder or tile), on the augmented real frames 77 and more;
// a quadrilateral inside a printed, occluded board: 14.
constexpr double kMinSideContrastShare = 0.25;

// The expected board scaled about its centre, as a raw-pixel polygon.
std::vector<cv::Point> scaledQuad(const ExpectedBoard& expected, const CameraModel& camera,
                                  double scale) {
  Eigen::Vector2d centre = Eigen::Vector2d::Zero();
  for (const auto& c : expected.corners_px) centre += 0.25 * c;
  std::vector<cv::Point> poly;
  for (const auto& c : expected.corners_px) {
    const Eigen::Vector2d raw = camera.distortPixel(centre + scale * (c - centre));
    poly.emplace_back(static_cast<int>(std::lround(std::clamp(raw.x(), -1e5, 1e5))),
                      static_cast<int>(std::lround(std::clamp(raw.y(), -1e5, 1e5))));
  }
  return poly;
}

// Mean and covariance of the bgr pixels under a mask.
bool colourStats(const cv::Mat& bgr, const cv::Mat& mask, Eigen::Vector3d* mean,
                 Eigen::Matrix3d* cov) {
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  Eigen::Matrix3d sq = Eigen::Matrix3d::Zero();
  double n = 0;
  for (int y = 0; y < bgr.rows; ++y) {
    const cv::Vec3b* row = bgr.ptr<cv::Vec3b>(y);
    const uchar* m = mask.ptr<uchar>(y);
    for (int x = 0; x < bgr.cols; ++x) {
      if (!m[x]) continue;
      const Eigen::Vector3d v(row[x][0], row[x][1], row[x][2]);
      sum += v;
      sq += v * v.transpose();
      n += 1;
    }
  }
  if (n < 16) return false;
  *mean = sum / n;
  *cov = sq / n - *mean * mean->transpose();
  return true;
}

// Median of an 8-bit single-channel image.
int medianLevel(const cv::Mat& image) {
  int histogram[256] = {};
  for (int y = 0; y < image.rows; ++y) {
    const uchar* p = image.ptr<uchar>(y);
    for (int x = 0; x < image.cols; ++x) ++histogram[p[x]];
  }
  int median = 0;
  for (long seen = 0; median < 255; ++median)
    if ((seen += histogram[median]) * 2 >= static_cast<long>(image.total())) break;
  return median;
}

// Pixels departing by more than kForegroundMedians x the image's median departure (most of a
// frame departs by its noise only), at least kForegroundFloor; specks opened away, gaps closed.
cv::Mat departureMask(const cv::Mat& departure) {
  const double threshold = std::max(kForegroundFloor, kForegroundMedians * medianLevel(departure));
  cv::Mat mask = departure > threshold;
  cv::morphologyEx(mask, mask, cv::MORPH_OPEN, cv::Mat());
  cv::morphologyEx(mask, mask, cv::MORPH_CLOSE,
                   cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(5, 5)));
  return mask;
}

// Board-sized, nearly convex parts of a mask (openings cut a holder off) as expected boards
// (ExpectedBoard::inside) that a board may exceed by a quarter of its size: openings round the
// corners off, and a threshold may eat into a faint side. Largest first. A part within one
// downscaled pixel of one already kept is that one. `by_colour` (a single frame's colour parts,
// not what moved): parts cut by the image border come last.
std::vector<ExpectedBoard> boardPlaces(const Foreground& parts_of, const CameraModel& camera,
                                       const Target& target, const ImageBoardDetectorOptions& o,
                                       bool by_colour, size_t max_places) {
  if (parts_of.mask.empty()) return {};
  const cv::Mat& mask = parts_of.mask;
  const double scale = parts_of.scale;
  std::vector<std::vector<cv::Point>> contours;
  cv::findContours(mask, contours, cv::RETR_EXTERNAL, cv::CHAIN_APPROX_NONE);
  const double min_side = o.min_board_size_px * scale, min_area = min_side * min_side;
  const double holder_fraction = holderOpeningFraction(target);
  std::vector<std::pair<double, ExpectedBoard>> found;
  for (const auto& contour : contours) {
    if (cv::contourArea(contour) < min_area) continue;
    auto parts = openedParts(contour, mask.size(), min_area, holder_fraction);
    parts.push_back(contour);
    for (const auto& part : parts) {
      std::vector<cv::Point> hull;
      cv::convexHull(part, hull);
      const double area = cv::contourArea(part), hull_area = cv::contourArea(hull);
      if (!(hull_area > 0) || area / hull_area < kForegroundSolidity) continue;
      const cv::RotatedRect rect = cv::minAreaRect(hull);
      cv::Point2f box[4];
      rect.points(box);
      ExpectedBoard e;
      e.inside = true;
      double perimeter = 0;
      for (int k = 0; k < kNumEdges; ++k) {
        const Eigen::Vector2d raw((box[k].x + 0.5) / scale - 0.5, (box[k].y + 0.5) / scale - 0.5);
        e.corners_px[static_cast<size_t>(k)] = camera.undistortPixel(raw);
        perimeter += cv::norm(box[(k + 1) % 4] - box[k]) / scale;
      }
      e.tolerance_px = kForegroundCornerShare * perimeter / kNumEdges + 2.0 / scale;
      bool duplicate = false;
      for (const auto& [r, other] : found)
        duplicate = duplicate || worstCornerOffset(e.corners_px, other.corners_px) <= 2.0 / scale;
      if (duplicate) continue;
      // A colour part cut by the image border (the sky, a wall) has no outline of its own:
      // tried after the whole ones.
      const cv::Rect box_px = cv::boundingRect(hull);
      const bool cut = box_px.x <= 0 || box_px.y <= 0 || box_px.br().x >= mask.cols ||
                       box_px.br().y >= mask.rows;
      found.emplace_back(by_colour && cut ? area - static_cast<double>(mask.total()) : area, e);
    }
  }
  std::sort(found.begin(), found.end(),
            [](const auto& a, const auto& b) { return a.first > b.first; });
  std::vector<ExpectedBoard> out;
  for (size_t k = 0; k < found.size() && k < max_places; ++k) out.push_back(found[k].second);
  return out;
}

}  // namespace

cv::Mat boardContrastImage(const cv::Mat& bgr, const CameraModel& camera,
                           const ExpectedBoard& expected) {
  if (bgr.channels() != 3) return {};
  // Inside: the central half of the expected board (within it for any prior error up to a
  // quarter of its size). Around: a ring from 1.5 to 2 board sizes (outside it for the same
  // error); holder and clutter there are part of what the board must stand out from.
  cv::Mat inside = cv::Mat::zeros(bgr.size(), CV_8U), around = inside.clone();
  cv::fillConvexPoly(inside, scaledQuad(expected, camera, 0.5), 255);
  cv::fillConvexPoly(around, scaledQuad(expected, camera, kContrastRingOuter), 255);
  cv::fillConvexPoly(around, scaledQuad(expected, camera, kContrastRingInner), 0);
  Eigen::Vector3d mean_in, mean_out;
  Eigen::Matrix3d cov_in, cov_out;
  if (!colourStats(bgr, inside, &mean_in, &cov_in) ||
      !colourStats(bgr, around, &mean_out, &cov_out))
    return {};
  // Fisher's axis; the pooled covariance gets a floor of one grey level squared per channel
  // (8-bit quantisation) so a flat synthetic or clipped region cannot make it singular.
  const Eigen::Matrix3d pooled = cov_in + cov_out + Eigen::Matrix3d::Identity();
  Eigen::Vector3d axis = pooled.ldlt().solve(mean_in - mean_out);
  const double separation = axis.dot(mean_in - mean_out);
  if (!(separation > 0) || !std::isfinite(separation)) return {};
  // Board and ring means 100 grey levels apart, centred in the 8-bit range; the detector's
  // thresholds follow the noise it measures in this image.
  axis *= 2.0 * kContrastHalfSeparation / separation;
  const double offset = kContrastMidpoint - axis.dot(0.5 * (mean_in + mean_out));
  cv::Mat out(bgr.size(), CV_8U);
  for (int y = 0; y < bgr.rows; ++y) {
    const cv::Vec3b* row = bgr.ptr<cv::Vec3b>(y);
    uchar* o = out.ptr<uchar>(y);
    for (int x = 0; x < bgr.cols; ++x)
      o[x] = cv::saturate_cast<uchar>(axis.x() * row[x][0] + axis.y() * row[x][1] +
                                      axis.z() * row[x][2] + offset);
  }
  return out;
}

namespace {

// The window's camera: same intrinsics, principal point in window pixels. Raw and undistorted
// pixels both move by the window's corner (distortion acts on normalised coordinates).
Expected<CameraModel> windowCamera(const CameraModel& camera, const cv::Rect& window) {
  CameraIntrinsics in = camera.intrinsics();
  in.width = window.width;
  in.height = window.height;
  in.cx -= window.x;
  in.cy -= window.y;
  return CameraModel::create(in);
}

void shiftPoints(const Eigen::Vector2d& by, Points2* pts) {
  for (auto& p : *pts) p += by;
}

template <size_t N>
void shiftPoints(const Eigen::Vector2d& by, std::vector<std::array<Eigen::Vector2d, N>>* sets) {
  for (auto& set : *sets)
    for (auto& p : set) p += by;
}

// A line a u + b v + c = 0 moved by `by`.
Eigen::Vector3d shiftLine(const Eigen::Vector3d& l, const Eigen::Vector2d& by) {
  return {l.x(), l.y(), l.z() - l.head<2>().dot(by)};
}

}  // namespace

bool sidesPartColours(const cv::Mat& contrast, const CameraModel& camera, CameraBoardFeatures* f) {
  const double needed = kMinSideContrastShare * 2.0 * kContrastHalfSeparation;
  for (int j = 0; j < kNumEdges; ++j) {
    const Eigen::Vector2d a = f->corners_px[(j + 3) % 4], b = f->corners_px[j];
    const Eigen::Vector2d outward = f->edge_lines[j].head<2>();
    // Past the edge's blur, inside a far board.
    const double band = std::max(kBandMinPx, kBandSideShare * (b - a).norm());
    std::vector<double> inside, outside;
    for (double t = kBandFrom; t <= 1.0 - kBandFrom; t += kBandStep)
      for (const double side : {-1.0, 1.0}) {
        const Eigen::Vector2d q = camera.distortPixel(a + t * (b - a) + side * band * outward);
        const int x = static_cast<int>(std::lround(q.x())),
                  y = static_cast<int>(std::lround(q.y()));
        if (x < 0 || y < 0 || x >= contrast.cols || y >= contrast.rows) continue;
        (side < 0 ? inside : outside).push_back(contrast.at<uchar>(y, x));
      }
    const double in = inside.empty() ? 0.0 : medianOf(inside);
    const double out = outside.empty() ? 0.0 : medianOf(outside);
    if (inside.empty() || outside.empty() || in - out >= needed) continue;
    f->found = false;
    f->reason = cv::format(
        "side %s does not part the board's colour from its surroundings' (%.0f levels across it, "
        "need %.0f of the board's %.0f)",
        edgeName(j), in - out, needed, 2.0 * kContrastHalfSeparation);
    return false;
  }
  return true;
}

void detectPlainInColourWindow(const cv::Mat& bgr, const CameraModel& camera, const Target& target,
                               const ImageBoardDetectorOptions& options, const ExpectedBoard& place,
                               const StaticScene* excluded, ImageDetection* out) {
  out->features.K = camera.K();
  out->features.image_width = bgr.cols;
  out->features.image_height = bgr.rows;
  const cv::Rect ring = cv::boundingRect(scaledQuad(place, camera, kContrastRingOuter));
  // The board may exceed its place by the place's tolerance: so may its ring.
  const int grow = std::isfinite(place.tolerance_px)
                       ? static_cast<int>(std::ceil(
                             std::clamp(place.tolerance_px, 0.0, double(bgr.cols + bgr.rows))))
                       : 0;
  // Snapped outward to the downscaled images' pixel grid (12 px: whole downscaled pixels at
  // factors 2, 3, 4 and 6, e.g. 4 and 3 at the default widths of a 1920 px frame), so the
  // window's pixels average as the whole frame's do; then clipped to the image.
  const auto snap = [](int v, bool up) {
    const double cells = static_cast<double>(v) / kWindowGridPx;
    return static_cast<int>(up ? std::ceil(cells) : std::floor(cells)) * kWindowGridPx;
  };
  const cv::Rect window =
      cv::Rect(cv::Point(snap(ring.x - grow, false), snap(ring.y - grow, false)),
               cv::Point(snap(ring.br().x + grow, true), snap(ring.br().y + grow, true))) &
      cv::Rect(0, 0, bgr.cols, bgr.rows);
  const Expected<CameraModel> window_camera = windowCamera(camera, window);
  if (window.area() == 0 || !window_camera) {
    out->features.reason = "the place lies outside the image";
    return;
  }
  const Eigen::Vector2d to_window(-window.x, -window.y);
  ExpectedBoard local = place;
  for (auto& c : local.corners_px) c += to_window;
  const cv::Mat contrast = boardContrastImage(bgr(window), *window_camera, local);
  if (contrast.empty()) {
    out->features.reason = "the place does not differ in colour from its surroundings";
    return;
  }
  ImageBoardDetectorOptions o = options;
  const double share = static_cast<double>(window.width) / bgr.cols;
  auto narrowed = [share](int width_px) {
    return width_px > 0 ? std::max(1, static_cast<int>(std::lround(width_px * share))) : width_px;
  };
  o.segmentation_width_px = narrowed(o.segmentation_width_px);
  o.line_detection_width_px = narrowed(o.line_detection_width_px);
  StaticScene local_scene;
  if (excluded) {
    local_scene.rectangles = excluded->rectangles;
    for (auto& r : local_scene.rectangles)
      for (auto& c : r.corners_px) c += to_window;
    local_scene.lines_px = excluded->lines_px;
    shiftPoints(to_window, &local_scene.lines_px);
  }
  ImageDetection found;
  found.features.K = window_camera->K();
  found.features.image_width = window.width;
  found.features.image_height = window.height;
  detectPlain(contrast, *window_camera, target, o, &found, &local,
              excluded ? &local_scene : nullptr, /*grey_frame=*/false, /*colour_challenge=*/false,
              /*expected_is_prior=*/false);
  if (found.features.found) sidesPartColours(contrast, *window_camera, &found.features);
  // Back to whole-frame pixels.
  const Eigen::Vector2d back = -to_window;
  CameraBoardFeatures& f = found.features;
  f.K = camera.K();
  f.image_width = bgr.cols;
  f.image_height = bgr.rows;
  for (auto& c : f.corners_px) c += back;
  for (auto& l : f.edge_lines) l = shiftLine(l, back);
  ImageDetectionDetails& d = found.details;
  for (auto& pts : d.edge_points_raw) shiftPoints(back, &pts);
  shiftPoints(back, &d.outline_raw);
  shiftPoints(back, &d.hypotheses_px);
  shiftPoints(back, &d.boards_px);
  shiftPoints(back, &d.lines_px);
  shiftPoints(back, &d.segments_raw);
  *out = std::move(found);
}

cv::Mat medianImage(const std::deque<cv::Mat>& frames) {
  if (frames.empty()) return {};
  const cv::Mat& first = frames.front();
  for (const auto& f : frames)
    if (f.size() != first.size() || f.type() != first.type() || f.depth() != CV_8U) return {};
  cv::Mat out(first.size(), first.type());
  const size_t n = frames.size(), values = first.total() * first.channels();
  std::vector<const uchar*> rows(n);
  std::vector<uchar> v(n);
  for (int y = 0; y < first.rows; ++y) {
    for (size_t k = 0; k < n; ++k) rows[k] = frames[k].ptr<uchar>(y);
    uchar* o = out.ptr<uchar>(y);
    const size_t row_values = values / first.rows;
    for (size_t i = 0; i < row_values; ++i) {
      for (size_t k = 0; k < n; ++k) v[k] = rows[k][i];
      std::nth_element(v.begin(), v.begin() + n / 2, v.end());
      o[i] = v[n / 2];
    }
  }
  return out;
}

Foreground foregroundMask(const cv::Mat& bgr, const cv::Mat& background) {
  Foreground out;
  if (bgr.channels() != 3 || background.empty() || background.type() != CV_8UC3) return out;
  const double scale = static_cast<double>(background.cols) / bgr.cols;
  if (std::abs(scale * bgr.rows - background.rows) > 1.5) return out;  // another image size
  cv::Mat small, diff3;
  cv::resize(bgr, small, background.size(), 0, 0, cv::INTER_AREA);
  cv::absdiff(small, background, diff3);
  cv::Mat channels[3];
  cv::split(diff3, channels);
  // Most of a frame is background: its median departure is the noise and the lighting's drift.
  out.mask = departureMask(cv::max(cv::max(channels[0], channels[1]), channels[2]));
  out.scale = scale;
  return out;
}

std::vector<ExpectedBoard> foregroundBoards(const Foreground& foreground, const CameraModel& camera,
                                            const Target& target,
                                            const ImageBoardDetectorOptions& o) {
  return boardPlaces(foreground, camera, target, o, false, kMaxForegroundBoards);
}

Foreground chromaDeparture(const cv::Mat& bgr, int width_px) {
  Foreground out;
  if (bgr.channels() != 3 || width_px <= 0 || bgr.empty()) return out;
  out.scale = std::min(1.0, width_px / static_cast<double>(bgr.cols));
  cv::Mat small, lab;
  cv::resize(bgr, small, cv::Size(), out.scale, out.scale, cv::INTER_AREA);
  cv::cvtColor(small, lab, cv::COLOR_BGR2Lab);
  cv::Mat channels[3];
  cv::split(lab, channels);
  // Per chroma axis (green-red, blue-yellow) the departure from the frame's median colour;
  // lightness is the grey search's.
  cv::Mat diff = cv::Mat::zeros(small.size(), CV_8U);
  for (int c = 1; c < 3; ++c) {
    cv::Mat d;
    cv::absdiff(channels[c], cv::Scalar(medianLevel(channels[c])), d);
    diff = cv::max(diff, d);
  }
  out.mask = departureMask(diff);
  return out;
}

std::vector<ExpectedBoard> colourPartBoards(const cv::Mat& bgr, const CameraModel& camera,
                                            const Target& target,
                                            const ImageBoardDetectorOptions& o) {
  return boardPlaces(chromaDeparture(bgr, o.segmentation_width_px), camera, target, o, true,
                     kMaxColourPartBoards);
}

}  // namespace image_detection
}  // namespace board_calib
