// Second chance in colour: a board whose grey level matches the scene behind it (cardboard on a
// facade) still differs in colour. Where the other sensor's board projects, the colour axis that
// best separates the inside of that board from the ring around it (Fisher's discriminant of
// the two pixel sets) turns the image into one channel in which the board stands out; the plain
// detector then runs on it as on a grey image, inside the expected board only.
#include "plain_internal.h"

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
// A single frame's colour regions tried (each a detection on its own colour channel).
constexpr size_t kMaxColourRegionBoards = 2;
constexpr double kColourMinSides = 2.0;

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

// A convex outline on an image downscaled by `scale` as an expected board (ExpectedBoard::inside)
// that a board may exceed by a quarter of its size (openings round the corners off, and a
// threshold may eat into a faint side); one downscaled pixel off a place already found is that
// place.
void addPlace(const std::vector<cv::Point>& hull, double scale, const CameraModel& camera,
              double rank, std::vector<std::pair<double, ExpectedBoard>>* found) {
  cv::Point2f box[4];
  cv::minAreaRect(hull).points(box);
  ExpectedBoard e;
  e.inside = true;
  double perimeter = 0;
  for (int k = 0; k < kNumEdges; ++k) {
    const Eigen::Vector2d raw((box[k].x + 0.5) / scale - 0.5, (box[k].y + 0.5) / scale - 0.5);
    e.corners_px[static_cast<size_t>(k)] = camera.undistortPixel(raw);
    perimeter += cv::norm(box[(k + 1) % 4] - box[k]) / scale;
  }
  e.tolerance_px = kForegroundCornerShare * perimeter / kNumEdges + 2.0 / scale;
  for (const auto& [r, other] : *found)
    if (worstCornerOffset(e.corners_px, other.corners_px) <= 2.0 / scale) return;
  found->emplace_back(rank, e);
}

std::vector<ExpectedBoard> largestPlaces(std::vector<std::pair<double, ExpectedBoard>> found,
                                         size_t max_places) {
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
  cv::fillConvexPoly(around, scaledQuad(expected, camera, 2.0), 255);
  cv::fillConvexPoly(around, scaledQuad(expected, camera, 1.5), 0);
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
  axis *= 100.0 / separation;
  const double offset = 127.5 - axis.dot(0.5 * (mean_in + mean_out));
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
  const cv::Mat diff = cv::max(cv::max(channels[0], channels[1]), channels[2]);
  // Most of a frame is background: its median departure is the noise and the lighting's drift.
  int histogram[256] = {};
  for (int y = 0; y < diff.rows; ++y) {
    const uchar* d = diff.ptr<uchar>(y);
    for (int x = 0; x < diff.cols; ++x) ++histogram[d[x]];
  }
  int median = 0;
  for (long seen = 0; median < 255; ++median)
    if ((seen += histogram[median]) * 2 >= static_cast<long>(diff.total())) break;
  const double threshold = std::max(kForegroundFloor, kForegroundMedians * median);
  out.mask = diff > threshold;
  cv::morphologyEx(out.mask, out.mask, cv::MORPH_OPEN, cv::Mat());
  cv::morphologyEx(out.mask, out.mask, cv::MORPH_CLOSE,
                   cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(5, 5)));
  out.scale = scale;
  return out;
}

std::vector<ExpectedBoard> foregroundBoards(const Foreground& foreground, const CameraModel& camera,
                                            const ImageBoardDetectorOptions& o) {
  std::vector<ExpectedBoard> out;
  if (foreground.mask.empty()) return out;
  const cv::Mat& mask = foreground.mask;
  const double scale = foreground.scale;
  std::vector<std::vector<cv::Point>> contours;
  cv::findContours(mask, contours, cv::RETR_EXTERNAL, cv::CHAIN_APPROX_NONE);
  const double min_side = o.min_board_size_px * scale, min_area = min_side * min_side;
  std::vector<std::pair<double, ExpectedBoard>> found;
  for (const auto& contour : contours) {
    if (cv::contourArea(contour) < min_area) continue;
    auto parts = openedParts(contour, mask.size(), min_area);
    parts.push_back(contour);
    for (const auto& part : parts) {
      std::vector<cv::Point> hull;
      cv::convexHull(part, hull);
      const double area = cv::contourArea(part), hull_area = cv::contourArea(hull);
      if (!(hull_area > 0) || area / hull_area < kForegroundSolidity) continue;
      addPlace(hull, scale, camera, area, &found);
    }
  }
  return largestPlaces(std::move(found), kMaxForegroundBoards);
}

std::vector<ExpectedBoard> colourRegionBoards(const cv::Mat& bgr, const CameraModel& camera,
                                              const ImageBoardDetectorOptions& o) {
  if (bgr.channels() != 3 || o.segmentation_width_px <= 0) return {};
  const double scale = std::min(1.0, o.segmentation_width_px / static_cast<double>(bgr.cols));
  cv::Mat small, lab;
  cv::resize(bgr, small, cv::Size(), scale, scale, cv::INTER_AREA);
  cv::cvtColor(small, lab, cv::COLOR_BGR2Lab);
  cv::Mat channels[3];
  cv::split(lab, channels);
  std::vector<std::pair<double, ExpectedBoard>> found;
  // The two chroma axes (green-red, blue-yellow): lightness is the grey search's.
  for (int c = 1; c < 3; ++c) {
    const double side = kColourMinSides * o.min_board_size_px * scale;
    const Segmentation seg = segmentBoard(channels[c], o, side * side);
    for (size_t i = 0; i < seg.candidates.size() && i < static_cast<size_t>(o.max_board_candidates);
         ++i)
      addPlace(seg.candidates[i].contour, scale, camera, seg.candidates[i].score, &found);
  }
  return largestPlaces(std::move(found), kMaxColourRegionBoards);
}

}  // namespace image_detection
}  // namespace board_calib
