// Real plain-board frames with reference lines and their augmentations (augmented_frames.h).
#include "augmented_frames.h"

#include <board_calib/bag_reader.h>
#include <board_calib/core/image_detection/image_board_detector.h>

#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>
#include <Eigen/Geometry>
#include <opencv2/core/eigen.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/photo.hpp>

#include <cmath>
#include <optional>

namespace board_calib {
namespace augmented {
namespace {

const std::string kData = std::string(BOARD_CALIB_SHARED_DIR) + "/data/";
const std::string kRef = std::string(BOARD_CALIB_SHARED_DIR) + "/tools/mlre/ref_basler_os1_plain/";

struct Recording {
  std::optional<CameraIntrinsics> intrinsics;
  std::vector<cv::Mat> images;
};

Recording readRecording(const std::string& name) {
  Recording r;
  BagTopics topics;
  topics.image_topics = {"/camera/image_raw"};
  topics.camera_info_topics = {"/camera/camera_info"};
  BagCallbacks cb;
  cb.on_image = [&](const ImageFrame& f) { r.images.push_back(f.image); };
  cb.on_camera_info = [&](const std::string&, const std::string&, const CameraIntrinsics& in) {
    if (!r.intrinsics) r.intrinsics = in;
  };
  const Status st = readBags({kData + name + "/session.bag"}, topics, cb);
  EXPECT_TRUE(st.ok) << st.reason;
  return r;
}

void setCorners(Frame* f) {
  for (int j = 0; j < kNumEdges; ++j) {
    const Eigen::Vector3d x = f->lines[j].cross(f->lines[(j + 1) % 4]);
    f->corners[j] = x.head<2>() / x.z();
  }
}

std::vector<Frame> baslerFrames() {
  std::vector<Frame> frames;
  const Recording rec = readRecording("basler_os1_plain");
  auto target = loadTarget(kData + "basler_os1_plain/target.yaml");
  EXPECT_TRUE(target.ok());
  for (size_t i = 0; i < rec.images.size(); ++i) {
    Frame f;
    f.name = "basler" + std::to_string(i);
    f.image = rec.images[i];
    f.intrinsics = *rec.intrinsics;
    f.target = *target;
    const YAML::Node ref =
        YAML::LoadFile(kRef + "frame" + std::to_string(2 * i) + ".yaml")["image"]["edges"];
    bool complete = true;
    for (int j = 0; j < kNumEdges; ++j) {
      const YAML::Node e = ref[edgeName(j)];
      if (!e || !e["valid"].as<bool>()) {
        complete = false;
        break;
      }
      const auto l = e["line_undist"].as<std::vector<double>>();
      const auto seg = e["segment_undist"].as<std::vector<std::vector<double>>>();
      f.lines[j] = Eigen::Vector3d(l[0], l[1], l[2]);
      for (int k = 0; k < 2; ++k) {
        Eigen::Vector2d p(seg[k][0], seg[k][1]);
        f.segments[j][k] =
            p - (f.lines[j].head<2>().dot(p) + f.lines[j].z()) * f.lines[j].head<2>();
      }
    }
    if (!complete) continue;
    setCorners(&f);
    frames.push_back(f);
  }
  return frames;
}

// rs16: the board's corners picked by eye on each clean frame (raw px of the 1920x1080 image,
// from a half-size view: good to ~20 px), in the order top, right, bottom, left. They only say
// WHICH rectangle is the board: the whole-image search took another rectangle of the office in 4
// of the 8 clean frames (the glass wall behind), which made a wrong reference before.
constexpr double kRs16PickedCorners[8][4][2] = {{{998, 270}, {1473, 422}, {1362, 765}, {897, 646}},
                                                {{996, 284}, {1470, 425}, {1362, 765}, {897, 646}},
                                                {{998, 268}, {1481, 415}, {1371, 766}, {897, 646}},
                                                {{963, 260}, {1484, 376}, {1391, 749}, {891, 662}},
                                                {{939, 248}, {1480, 241}, {1398, 762}, {855, 686}},
                                                {{910, 240}, {1490, 244}, {1414, 769}, {828, 686}},
                                                {{919, 211}, {1540, 310}, {1484, 778}, {851, 705}},
                                                {{923, 211}, {1578, 253}, {1511, 791}, {864, 699}}};
// Picked by eye (~20 px) through the wide-angle undistortion (up to ~1.5x at the board): the
// second-chance search accepts only a board whose corners all lie this close.
constexpr double kRs16PickTolerancePx = 45.0;
constexpr uint64_t kBlankNoiseSeed = 14;  // any fixed value: the blanked frames are then fixed too

// rs16: reference = the detector's lines found inside the picked corners (detectNear, the same
// sub-pixel edges as the whole-image search), segments = extent of its edge pixels.
std::vector<Frame> rs16Frames() {
  std::vector<Frame> frames;
  const Recording rec = readRecording("rs16_plain");
  auto target = loadTarget(kData + "rs16_plain/target.yaml");
  EXPECT_TRUE(target.ok());
  auto det = ImageBoardDetector::create(*target, ImageBoardDetectorOptions{});
  EXPECT_TRUE(det.ok());
  const CameraModel camera = *CameraModel::create(*rec.intrinsics);
  for (size_t i = 0; i < rec.images.size() && i < 8; ++i) {
    Frame f;
    f.name = "rs16_" + std::to_string(i);
    f.image = rec.images[i];
    f.intrinsics = *rec.intrinsics;
    f.target = *target;
    ExpectedBoard picked;
    for (int k = 0; k < kNumEdges; ++k)
      picked.corners_px[k] = camera.undistortPixel(
          Eigen::Vector2d(kRs16PickedCorners[i][k][0], kRs16PickedCorners[i][k][1]));
    picked.tolerance_px = kRs16PickTolerancePx;
    const ImageDetection d = det->detectNear(f.image, camera, picked);
    if (!d.features.found || !d.features.allEdgesValid()) {
      std::printf("  %s: no reference (%s)\n", f.name.c_str(), d.features.reason.c_str());
      continue;
    }
    for (int j = 0; j < kNumEdges; ++j) {
      f.lines[j] = d.features.edge_lines[j];
      const Eigen::Vector2d dir(-f.lines[j].y(), f.lines[j].x());
      double lo = 1e18, hi = -1e18;
      Eigen::Vector2d plo, phi;
      for (const auto& raw : d.details.edge_points_raw[j]) {
        Eigen::Vector2d u = camera.undistortPixel(raw);
        u -= (f.lines[j].head<2>().dot(u) + f.lines[j].z()) * f.lines[j].head<2>();
        const double t = dir.dot(u);
        if (t < lo) lo = t, plo = u;
        if (t > hi) hi = t, phi = u;
      }
      f.segments[j] = {plo, phi};
    }
    setCorners(&f);
    frames.push_back(f);
  }
  return frames;
}

// ---- augmentations --------------------------------------------------------------------------

// Board polygon in raw pixels (sides sampled in undistorted px, then distorted).
std::vector<cv::Point> boardPolygon(const Frame& f) {
  const CameraModel camera = f.camera();
  std::vector<cv::Point> poly;
  constexpr int kPerSide = 64;
  for (int j = 0; j < kNumEdges; ++j) {
    const Eigen::Vector2d a = f.corners[(j + 3) % 4], b = f.corners[j];
    for (int k = 0; k < kPerSide; ++k) {
      const Eigen::Vector2d r = camera.distortPixel(a + (b - a) * (double(k) / kPerSide));
      poly.emplace_back(static_cast<int>(std::lround(std::clamp(r.x(), -4000.0, 8000.0))),
                        static_cast<int>(std::lround(std::clamp(r.y(), -4000.0, 8000.0))));
    }
  }
  return poly;
}

cv::Mat boardMask(const Frame& f, int erode_px = 0) {
  cv::Mat mask = cv::Mat::zeros(f.image.size(), CV_8U);
  cv::fillPoly(mask, std::vector<std::vector<cv::Point>>{boardPolygon(f)}, 255);
  if (erode_px > 0) cv::erode(mask, mask, cv::Mat(), cv::Point(-1, -1), erode_px);
  if (erode_px < 0) cv::dilate(mask, mask, cv::Mat(), cv::Point(-1, -1), -erode_px);
  return mask;
}

double boardSizePx(const Frame& f) {
  double s = 0;
  for (int j = 0; j < kNumEdges; ++j)
    s += (f.corners[(j + 1) % 4] - f.corners[j]).norm() / kNumEdges;
  return s;
}

// Board pixels take a new colour, keeping their relative shading and noise.
void recolourBoard(Frame* f, const cv::Scalar& bgr) {
  const cv::Mat mask = boardMask(*f);
  const cv::Scalar mean = cv::mean(f->image, mask);
  cv::Mat img;
  f->image.convertTo(img, CV_32FC3);
  std::vector<cv::Mat> ch;
  cv::split(img, ch);
  const double grey = (mean[0] + mean[1] + mean[2]) / 3;
  for (int c = 0; c < 3; ++c) ch[c] = ch[c] * (bgr[c] / std::max(1.0, grey));
  cv::Mat recoloured;
  cv::merge(ch, recoloured);
  recoloured.convertTo(recoloured, CV_8UC3);
  recoloured.copyTo(f->image, mask);
}

// The board inpainted from the background around it, out to `margin_px` past its edges (plus
// noise); outside that the frame is unchanged.
void inpaintBoard(Frame* f, int margin_px) {
  const cv::Mat mask = boardMask(*f, -margin_px);
  constexpr int kCoarse = 8;
  cv::Mat small, small_mask, filled, big;
  cv::resize(f->image, small, f->image.size() / kCoarse, 0, 0, cv::INTER_AREA);
  cv::resize(mask, small_mask, small.size(), 0, 0, cv::INTER_NEAREST);
  cv::dilate(small_mask, small_mask, cv::Mat());
  cv::inpaint(small, small_mask, filled, 5, cv::INPAINT_TELEA);
  cv::resize(filled, big, f->image.size(), 0, 0, cv::INTER_CUBIC);
  cv::Mat noise(big.size(), CV_8UC3);
  // Its own generator: a blanked frame must not depend on what else in the process drew from
  // OpenCV's global one (figures unchanged: 211/252, 818/844 edges).
  cv::RNG noise_rng(kBlankNoiseSeed);
  noise_rng.fill(noise, cv::RNG::NORMAL, cv::Scalar::all(0), cv::Scalar::all(2));
  cv::Mat noisy;
  cv::add(big, noise, noisy, cv::noArray(), CV_8UC3);
  noisy.copyTo(f->image, mask);
}

// Board brought to `delta` grey levels from the background around it: blended towards the
// background inpainted behind it, I' = B + w (I - B) with w = delta / (board - background
// contrast). The edge keeps its own profile (blur, bow, rim) at the new contrast; a shift inside
// the board's outline would leave the old contrast's blur tail outside it as an outline. The blend
// fades out over a band past the edge blur, so the background's fine texture has no border.
void lowContrast(Frame* f, double delta) {
  constexpr int kFullPx = 4, kFadePx = 12;  // blend weight 1 up to here past the edge, 0 from here
  const cv::Mat mask = boardMask(*f);
  cv::Mat ring = boardMask(*f, -25);
  ring.setTo(0, mask);
  const cv::Scalar in = cv::mean(f->image, mask), around = cv::mean(f->image, ring);
  const double contrast = (in[0] + in[1] + in[2] - around[0] - around[1] - around[2]) / 3;
  if (std::abs(contrast) <= std::abs(delta)) return;  // already that faint
  const double w = delta / contrast;
  Frame behind = *f;
  behind.image = f->image.clone();
  inpaintBoard(&behind, kFadePx);
  cv::Mat outside, distance;
  cv::bitwise_not(mask, outside);
  cv::distanceTransform(outside, distance, cv::DIST_L2, cv::DIST_MASK_PRECISE);
  cv::Mat img, bg;
  f->image.convertTo(img, CV_32FC3);
  behind.image.convertTo(bg, CV_32FC3);
  for (int y = 0; y < img.rows; ++y) {
    const float* d = distance.ptr<float>(y);
    cv::Vec3f* p = img.ptr<cv::Vec3f>(y);
    const cv::Vec3f* b = bg.ptr<cv::Vec3f>(y);
    for (int x = 0; x < img.cols; ++x) {
      const double m = std::clamp((kFadePx - d[x]) / double(kFadePx - kFullPx), 0.0, 1.0);
      if (m > 0) p[x] -= static_cast<float>((1 - w) * m) * (p[x] - b[x]);
    }
  }
  img.convertTo(f->image, CV_8UC3);
}

// Background contrast scaled and tinted (board untouched).
void changeBackground(Frame* f, double gain, const cv::Scalar& offset) {
  const cv::Mat mask = boardMask(*f);
  cv::Mat bg;
  f->image.convertTo(bg, CV_8UC3, gain);
  bg += offset;
  bg.copyTo(f->image, 255 - mask);
}

// Printed marks: dark and coloured rectangles, discs and text inside the board.
void printMarks(Frame* f, std::mt19937& rng) {
  const double size = boardSizePx(*f);
  const cv::Mat inner = boardMask(*f, std::max(3, static_cast<int>(0.08 * size)));
  std::vector<cv::Point> pts;
  cv::findNonZero(inner, pts);
  if (pts.empty()) return;
  std::uniform_int_distribution<size_t> pick(0, pts.size() - 1);
  std::uniform_real_distribution<double> u(0, 1);
  cv::Mat marks = f->image.clone();
  for (int k = 0; k < 14; ++k) {
    const cv::Point c = pts[pick(rng)];
    const cv::Scalar colour =
        u(rng) < 0.6 ? cv::Scalar(30, 30, 30) : cv::Scalar(40 + 150 * u(rng), 40, 150 * u(rng));
    const int r = std::max(2, static_cast<int>((0.02 + 0.05 * u(rng)) * size));
    switch (k % 3) {
      case 0: cv::circle(marks, c, r, colour, cv::FILLED, cv::LINE_AA); break;
      case 1:
        cv::rectangle(marks, c - cv::Point(r, r / 2), c + cv::Point(r, r / 2), colour, cv::FILLED);
        break;
      default:
        cv::putText(marks, "BOARD 14", c, cv::FONT_HERSHEY_SIMPLEX, std::max(0.3, size / 600.0),
                    colour, std::max(1, static_cast<int>(size / 300)), cv::LINE_AA);
    }
  }
  marks.copyTo(f->image, inner);
}

// Wood grain: wavy stripes modulating the board brightness by about +-15 %.
void woodGrain(Frame* f, std::mt19937& rng) {
  const cv::Mat mask = boardMask(*f);
  std::uniform_real_distribution<double> u(0, 1);
  const double angle = u(rng) * M_PI, period = (0.02 + 0.03 * u(rng)) * boardSizePx(*f);
  cv::Mat img;
  f->image.convertTo(img, CV_32FC3);
  const double ca = std::cos(angle), sa = std::sin(angle);
  for (int y = 0; y < img.rows; ++y) {
    const uchar* m = mask.ptr<uchar>(y);
    cv::Vec3f* p = img.ptr<cv::Vec3f>(y);
    for (int x = 0; x < img.cols; ++x) {
      if (!m[x]) continue;
      const double s = x * ca + y * sa, t = -x * sa + y * ca;
      const double g =
          1.0 +
          0.15 * std::sin(2 * M_PI * (s + 0.3 * period * std::sin(t / (7 * period))) / period);
      p[x] *= static_cast<float>(g);
    }
  }
  img.convertTo(f->image, CV_8UC3);
}

// Legs under the lowest board corner (or where the board leaves the image at the bottom) and a
// hand over the lower right side: occluders of any colour in front of the board's lower part.
void occludeLowerCorners(Frame* f, std::mt19937& rng) {
  const CameraModel camera = f->camera();
  const double size = boardSizePx(*f);
  const cv::Mat mask = boardMask(*f);
  // Lowest visible board pixel.
  cv::Point lowest(-1, -1);
  for (int y = mask.rows - 1; y >= 0 && lowest.y < 0; --y)
    for (int x = 0; x < mask.cols; ++x)
      if (mask.at<uchar>(y, x)) {
        lowest = {x, y};
        break;
      }
  if (lowest.y < 0) return;
  std::uniform_real_distribution<double> u(0, 1);
  const cv::Scalar colours[] = {{110, 60, 40}, {40, 40, 45}, {170, 170, 175}, {60, 90, 140}};
  const cv::Scalar leg_colour = colours[rng() % 4];
  const int leg_w = std::max(4, static_cast<int>(0.09 * size));
  const int top = lowest.y - static_cast<int>(0.22 * size);
  for (int side : {-1, 1}) {
    const int x = lowest.x + side * static_cast<int>((0.06 + 0.04 * u(rng)) * size);
    const std::vector<cv::Point> leg = {{x - leg_w / 2, top},
                                        {x + leg_w / 2, top},
                                        {x + leg_w / 2 + side * leg_w / 3, f->image.rows},
                                        {x - leg_w / 2 + side * leg_w / 3, f->image.rows}};
    cv::fillPoly(f->image, std::vector<std::vector<cv::Point>>{leg}, leg_colour, cv::LINE_AA);
  }
  // A hand over the lower right side (LR), 65 % along from its upper end, inside the image.
  const Eigen::Vector2d a = f->corners[1], b = f->corners[2];
  const Eigen::Vector2d h = camera.distortPixel(a + 0.65 * (b - a));
  if (h.x() > 0 && h.y() > 0 && h.x() < f->image.cols && h.y() < f->image.rows)
    cv::ellipse(f->image, cv::Point(int(h.x()), int(h.y())),
                cv::Size(int(0.06 * size), int(0.035 * size)), 45, 0, 360,
                cv::Scalar(120, 150, 200), cv::FILLED, cv::LINE_AA);
}

// The reference corners and segments through a pixel mapping that keeps lines straight, the lines
// refitted through the mapped segments.
template <typename Map>
void mapReference(Frame* f, const Map& map) {
  Eigen::Vector2d centre = Eigen::Vector2d::Zero();
  for (auto& corner : f->corners) {
    corner = map(corner);
    centre += 0.25 * corner;
  }
  for (int j = 0; j < kNumEdges; ++j) {
    for (auto& p : f->segments[j]) p = map(p);
    f->lines[j] = lineThrough(f->segments[j][0], f->segments[j][1], centre);
  }
}

// A far rs16 board: the board, with the background around it (a feathered disc), moved into the
// blanked full-size frame as the same camera would see it elsewhere. Its plane (from the reference
// corners and the camera) moves 1/s times farther along its own rays, then turns about the camera
// centre; the disc's pixels follow that plane's homography through the unchanged lens, drawn from
// a copy shrunk by s, and the reference follows the same homography. (Until session 27 the shrunk
// board was pasted and the camera's focal length scaled and principal point moved with it: through
// the rs16's wide-angle lens, k1 -0.34, the rest of the frame then lay at normalised radii where
// the distortion polynomial folds over, and its lines undistorted into curves.)
void moveBoardThroughLens(Frame* f, double s, std::mt19937& rng) {
  cv::Mat small;
  cv::resize(f->image, small, cv::Size(), s, s, cv::INTER_AREA);
  const CameraModel camera = f->camera();
  Frame blank = *f;
  blankBoard(&blank, rng);
  cv::Mat out = blank.image;
  const double radius = 0.5 * s * boardSizePx(*f) * 1.6;
  std::uniform_real_distribution<double> ux(radius, out.cols - radius),
      uy(radius, out.rows - radius);
  const Eigen::Vector2d place(ux(rng), uy(rng));  // raw pixels
  // The board plane's homography from the unit square, K^-1 H = [a1 a2 a3] up to scale (a3
  // towards a corner): a3 x 1/s puts the plane 1/s times farther.
  const Eigen::Matrix3d k = camera.K(), k_inverse = k.inverse();
  const std::vector<cv::Point2f> square = {{0, 0}, {1, 0}, {1, 1}, {0, 1}};
  std::vector<cv::Point2f> corners;
  Eigen::Vector2d centre = Eigen::Vector2d::Zero();
  for (const auto& c : f->corners) {
    corners.emplace_back(float(c.x()), float(c.y()));
    centre += 0.25 * c;
  }
  Eigen::Matrix3d h;
  cv::cv2eigen(cv::getPerspectiveTransform(square, corners), h);
  const Eigen::Matrix3d a = k_inverse * h;
  Eigen::Matrix3d farther = a;
  farther.col(2) /= s;
  const Eigen::Matrix3d move = farther * a.inverse();
  const Eigen::Vector3d from = move * k_inverse * centre.homogeneous();
  const Eigen::Vector3d to = k_inverse * camera.undistortPixel(place).homogeneous();
  const Eigen::Matrix3d turn = Eigen::Quaterniond::FromTwoVectors(from, to).toRotationMatrix();
  const Eigen::Matrix3d g = k * turn * move * k_inverse, g_inverse = g.inverse();
  auto moved = [&](const Eigen::Vector2d& u) -> Eigen::Vector2d {
    return (g * u.homogeneous()).hnormalized();
  };
  cv::Mat alpha = cv::Mat::zeros(out.size(), CV_32F);
  cv::circle(alpha, cv::Point(int(place.x()), int(place.y())), int(radius), 1.0, cv::FILLED);
  const int blur = 2 * static_cast<int>(0.15 * radius) + 1;
  cv::GaussianBlur(alpha, alpha, cv::Size(blur, blur), 0);
  const int reach = static_cast<int>(radius + blur);
  const cv::Rect dst =
      cv::Rect(int(place.x()) - reach, int(place.y()) - reach, 2 * reach + 1, 2 * reach + 1) &
      cv::Rect(0, 0, out.cols, out.rows);
  // Each disc pixel: its undistorted place, the source's undistorted place, its raw pixel in
  // the source frame, that pixel in the shrunk copy.
  cv::Mat map_x(dst.size(), CV_32F), map_y(dst.size(), CV_32F);
  for (int y = 0; y < dst.height; ++y)
    for (int x = 0; x < dst.width; ++x) {
      const Eigen::Vector2d u = camera.undistortPixel(Eigen::Vector2d(dst.x + x, dst.y + y));
      const Eigen::Vector2d raw = camera.distortPixel((g_inverse * u.homogeneous()).hnormalized());
      map_x.at<float>(y, x) = static_cast<float>(s * (raw.x() + 0.5) - 0.5);
      map_y.at<float>(y, x) = static_cast<float>(s * (raw.y() + 0.5) - 0.5);
    }
  cv::Mat patch;
  cv::remap(small, patch, map_x, map_y, cv::INTER_LINEAR, cv::BORDER_REPLICATE);
  for (int y = 0; y < dst.height; ++y)
    for (int x = 0; x < dst.width; ++x) {
      const float w = alpha.at<float>(dst.y + y, dst.x + x);
      cv::Vec3b& o = out.at<cv::Vec3b>(dst.y + y, dst.x + x);
      const cv::Vec3b& p = patch.at<cv::Vec3b>(y, x);
      for (int c = 0; c < 3; ++c) o[c] = cv::saturate_cast<uchar>(w * p[c] + (1 - w) * o[c]);
    }
  f->image = out;
  mapReference(f, moved);
}

// Shrinks the frame by `s` (a board farther away): the camera and the reference follow the pixel
// mapping u' = s (u + 0.5) - 0.5 (distortion acts on normalised coordinates: unchanged).
void shrink(Frame* f, double s) {
  cv::Mat small;
  cv::resize(f->image, small, cv::Size(), s, s, cv::INTER_AREA);
  auto map = [&](const Eigen::Vector2d& p) -> Eigen::Vector2d {
    return Eigen::Vector2d(s * (p.array() + 0.5) - 0.5);
  };
  CameraIntrinsics& in = f->intrinsics;
  in.fx *= s;
  in.fy *= s;
  const Eigen::Vector2d c = map({in.cx, in.cy});
  in.cx = c.x();
  in.cy = c.y();
  in.width = small.cols;
  in.height = small.rows;
  f->image = small;
  mapReference(f, map);
}

}  // namespace

// The board replaced by the background around it (inpainted on a coarse copy, plus noise).
void blankBoard(Frame* f, std::mt19937& rng) {
  (void)rng;
  inpaintBoard(f, 6);
}

// The 16 basler_os1_plain frames, then the rs16_plain frames with a reference. Read once per
// process: decompressing the two bags is ~20 s, shared by both tests.
const std::vector<Frame>& recordedFrames() {
  static const std::vector<Frame> frames = [] {
    std::vector<Frame> all = baslerFrames();
    EXPECT_EQ(all.size(), 16u);
    const std::vector<Frame> rs16 = rs16Frames();
    all.insert(all.end(), rs16.begin(), rs16.end());
    return all;
  }();
  return frames;
}

Frame augment(const Frame& clean, const Case& c, int index, std::mt19937& rng) {
  Frame f = clean;
  f.image = clean.image.clone();
  for (const Op op : c.ops) {
    switch (op) {
      case kColour:
        recolourBoard(&f, index % 2 ? cv::Scalar(95, 140, 180) : cv::Scalar(150, 90, 50));
        break;
      case kLowContrast: lowContrast(&f, index % 2 ? 12.0 : -12.0); break;
      case kBackground:
        changeBackground(&f, index % 2 ? 0.6 : 1.3,
                         index % 2 ? cv::Scalar(40, 10, 0) : cv::Scalar(0, -10, -30));
        break;
      case kPrint: printMarks(&f, rng); break;
      case kWood: woodGrain(&f, rng); break;
      case kOcclude: occludeLowerCorners(&f, rng); break;
      case kFar: {
        // Board 80-250 px across (5-15 m for a 1 m board at f ~ 1200 px).
        const double sizes[] = {85, 120, 170, 240};
        const double s = sizes[index % 4] / boardSizePx(f);
        // Whole rs16 boards go into a full-size cluttered frame; basler boards are cut by the
        // image border, so the whole frame shrinks (a pasted part would add a false border).
        if (f.name.rfind("rs16", 0) == 0)
          moveBoardThroughLens(&f, s, rng);
        else
          shrink(&f, s);
        break;
      }
    }
  }
  return f;
}

double segmentDistancePx(const Frame& f, int ref, const Eigen::Vector3d& line) {
  double dist = 0.0;
  for (const auto& p : f.segments[ref])
    dist = std::max(dist, std::abs(line.head<2>().dot(p) + line.z()));
  return dist;
}

double edgeErrorPx(const Frame& f, const CameraBoardFeatures& found, int j) {
  const double dist = segmentDistancePx(f, j, found.edge_lines[j]);
  const double along = f.lines[j].head<2>().dot(found.edge_lines[j].head<2>());
  return along < 0.99 ? std::max(dist, 1e3) : dist;
}

const std::vector<Case>& augmentedCases() {
  static const std::vector<Case> cases = {
      // Floors: the measured count minus one (the 95 % = 15.2 of 16 is not met by every
      // case yet: low contrast and the far + low contrast + wood combination fall short). Low
      // contrast: 14 of 16 while its shift left the old contrast's blur tail as an outline; 5
      // since the blend keeps each edge's own profile (a 12-level step over the basler edges'
      // blur, sigma ~1.7 px, peaks at ~3 levels per px, below min_edge_contrast); 11 since a
      // soft edge is judged by its step; 16 since the faint-line search (LSD's raw gradient
      // bound kept those sides out of the line stage; far + low contrast + wood 2 -> 4). Wood
      // grain: 15 since the rival-line test (a stripe beside a side is as well supported as the
      // edge). Far + low contrast + wood: 8 since a small image's line quadrilaterals search
      // their sides no wider than their lines' error (a wide search met the grain's stripes). Far
      // basler frames: 16 in the three far cases without low contrast since a short side needs
      // half its length, not min_edge_length_px (basler0's 29 px side).
      {"clean", {}, 15},
      {"board colour (cardboard, blue)", {kColour}, 15},
      {"low contrast (+-12 grey levels)", {kLowContrast}, 15},
      {"background tint and contrast", {kBackground}, 15},
      {"printed marks", {kPrint}, 15},
      {"wood grain", {kWood}, 14},
      {"far (board 80-250 px)", {kFar}, 15},
      {"legs and hand over the lower corners", {kOcclude}, 15},
      {"colour + print + occluders", {kColour, kPrint, kOcclude}, 15},
      {"far + low contrast + wood", {kLowContrast, kWood, kFar}, 7},
      {"far + colour + occluders", {kColour, kOcclude, kFar}, 15},
      {"far + background + print + occluders", {kBackground, kPrint, kOcclude, kFar}, 15},
  };
  return cases;
}

}  // namespace augmented
}  // namespace board_calib
