// ImageBoardDetector: input checks, dispatch by target type, and the AprilTag grid detector
// (which owns the libapriltag state).
#include "detection_internal.h"

#include <apriltag/apriltag.h>
#include <apriltag/tag36h11.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <map>

namespace board_calib {

namespace {

// libapriltag puts pixel centres at integer + 0.5 (libapriltag convention); OpenCV and CameraModel
// at integers.
constexpr double kAprilTagPixelOffset = 0.5;
constexpr int kMaxHammingSupported =
    2;  // tag36h11 with 3 bits corrected needs a huge table and gives false ids
// A colour board with most of its area inside a grey line quadrilateral is in front of it; one
// whose corners all lie within this share of the quadrilateral's side is the same board.
constexpr double kHeldInFrontShare = 0.5;
constexpr double kSameBoardFraction = 0.05;
constexpr double kSteepTurnFacing = 0.7071;  // cos 45 deg
// A tag36h11 spans 10 cells with its white border: at one pixel per cell not yet readable.
constexpr double kMinTagImageSidePx = 10;
constexpr int kMaxTagThreads = 64;

// Whether a board inside `place` could replace the grey board `found` (searchInColour), judged
// before the costly search: the place that is the grey board itself (each mostly inside the
// other) only when lines alone outlined it (one side may follow a scene edge of the board's grey
// that its colour contrast does not have: the simulated street at noise 0.5 kept a side 7.9 px
// off, corners fitting to 0.03 px), not a region; nor a place apart from it whose outline, grown
// by its tolerance, is shorter than the grey board's edge support (a board inside it cannot have
// more).
bool canChallenge(const ExpectedBoard& place, const ImageDetection& found) {
  const auto& board = found.features.corners_px;
  const double place_in_board = image_detection::shareInside(place.corners_px, board);
  if (place_in_board >= kHeldInFrontShare &&
      image_detection::shareInside(board, place.corners_px) >= kHeldInFrontShare)
    return found.details.board_source != image_detection::kRegionSource;
  const double bound =
      kNumEdges * (image_detection::meanSidePx(place.corners_px) + 2.0 * place.tolerance_px);
  return place_in_board > 0.0 || bound > found.details.board_support_px;
}

// A three-channel frame whose channels differ (a grey image sent as bgr8 has no colour to
// challenge a board with): more than kColourShare of a sparse grid of pixels spread their
// channels by more than kGreySpread grey levels (compression and demosaicing keep a grey scene
// within a few).
bool hasColour(const cv::Mat& image) {
  if (image.channels() != 3 || image.depth() != CV_8U) return false;
  constexpr int kStride = 8;
  constexpr int kGreySpread = 6;
  constexpr double kColourShare = 0.05;
  long coloured = 0, sampled = 0;
  for (int y = 0; y < image.rows; y += kStride) {
    const cv::Vec3b* row = image.ptr<cv::Vec3b>(y);
    for (int x = 0; x < image.cols; x += kStride, ++sampled) {
      const cv::Vec3b& p = row[x];
      const int spread = std::max({p[0], p[1], p[2]}) - std::min({p[0], p[1], p[2]});
      coloured += spread > kGreySpread;
    }
  }
  return sampled > 0 && coloured > kColourShare * sampled;
}

// Whether a grey board is searched for in colour too (searchInColour's challenge): a board of
// straight lines alone always (nothing vouched for its interior); a region only when turned past
// kSteepTurnFacing, where a board facing the camera with far less edge support outranks it (the
// holder's torso fits a board turned ~65 deg). A cost gate: the colour search takes 5-90 ms.
bool worthChallenging(const ImageDetection& grey) {
  return grey.details.board_source != image_detection::kRegionSource ||
         image_detection::facingCosine(grey.features.camera_T_board) < kSteepTurnFacing;
}

// A miss names the attempt its reason is from and where that was (raw px, as the image shows
// it): in a cluttered scene the attempt that got furthest may be another object, the board never
// outlined at all. The index is the one the debug image lists the hypotheses by.
void nameBestAttempt(const CameraModel& camera, ImageDetection* out) {
  const ImageDetectionDetails& d = out->details;
  const int k = d.best_attempt;
  if (out->features.found || k < 0 || k >= static_cast<int>(d.hypotheses_px.size()) ||
      k >= static_cast<int>(d.hypothesis_reasons.size()))
    return;
  const auto& q = d.hypotheses_px[static_cast<size_t>(k)];
  const double side = image_detection::meanSidePx(q);
  const Eigen::Vector2d raw = camera.distortPixel(0.25 * (q[0] + q[1] + q[2] + q[3]));
  if (!(side > 0) || !std::isfinite(side) || !raw.allFinite()) return;
  const std::string& tried = d.hypothesis_reasons[static_cast<size_t>(k)];
  out->features.reason =
      cv::format("best attempt #%d of %zu (%s, sides ~%.0f px, centred at (%.0f, %.0f) px): ", k,
                 d.hypotheses_px.size(), tried.substr(0, tried.find(':')).c_str(), side, raw.x(),
                 raw.y()) +
      out->features.reason;
}
}  // namespace

std::string ImageBoardDetectorOptions::validate() const {
  if (segmentation_width_px < 64) return "segmentation_width_px must be >= 64";
  if (!(min_board_area_fraction > 0 && min_board_area_fraction < 1))
    return "min_board_area_fraction must be in (0, 1)";
  if (!(min_solidity > 0 && min_solidity <= 1)) return "min_solidity must be in (0, 1]";
  if (!(max_flat_gradient > 0)) return "max_flat_gradient must be > 0";
  if (!(max_interior_texture > 0)) return "max_interior_texture must be > 0";
  if (max_board_candidates < 1) return "max_board_candidates must be >= 1";
  if (!(border_margin_px >= 0)) return "border_margin_px must be >= 0";
  if (!(coarse_search_px >= fine_search_px && fine_search_px >= 1))
    return "need coarse_search_px >= fine_search_px >= 1";
  if (!(sample_step_px >= 0.5)) return "sample_step_px must be >= 0.5";
  if (!(corner_exclusion_px >= 0)) return "corner_exclusion_px must be >= 0";
  if (!(min_edge_contrast > 0)) return "min_edge_contrast must be > 0";
  if (!(min_edge_length_px > 0)) return "min_edge_length_px must be > 0";
  if (min_edge_points < 2) return "min_edge_points must be >= 2";
  if (!(edge_inlier_px > 0)) return "edge_inlier_px must be > 0";
  if (!(max_edge_rms_px > 0)) return "max_edge_rms_px must be > 0";
  if (!(max_edge_bow_fraction > 0 && max_edge_bow_fraction <= 1))
    return "max_edge_bow_fraction must be in (0, 1]";
  if (fast_check_width_px < 160) return "fast_check_width_px must be >= 160";
  if (subpix_window_px < 2) return "subpix_window_px must be >= 2";
  if (!(tag_decimate >= 1)) return "tag_decimate must be >= 1";
  if (!(tag_sigma >= 0)) return "tag_sigma must be >= 0";
  // Each a thread of libapriltag's worker pool: a huge count exhausts the process.
  if (tag_threads < 1 || tag_threads > kMaxTagThreads) return "tag_threads must be in [1, 64]";
  if (tag_max_hamming < 0 || tag_max_hamming > kMaxHammingSupported)
    return "tag_max_hamming must be in [0, 2]";
  if (min_tags < 1) return "min_tags must be >= 1";
  if (!(min_board_size_px > 0)) return "min_board_size_px must be > 0";
  if (!(max_reprojection_rms_px > 0)) return "max_reprojection_rms_px must be > 0";
  if (!(max_plain_corner_rms_px > 0)) return "max_plain_corner_rms_px must be > 0";
  if (!(max_plain_corner_rms_fraction > 0)) return "max_plain_corner_rms_fraction must be > 0";
  if (!(edge_snr >= 0)) return "edge_snr must be >= 0";
  if (!(min_side_coverage > 0 && min_side_coverage <= 1))
    return "min_side_coverage must be in (0, 1]";
  if (line_detection_width_px != 0 && line_detection_width_px < 64)
    return "line_detection_width_px must be 0 (off) or >= 64";
  if (max_line_hypotheses < 0) return "max_line_hypotheses must be >= 0";
  if (max_lines < kNumEdges || max_lines_static_scene < kNumEdges)
    return "max_lines and max_lines_static_scene must be >= 4";
  if (!(max_board_tilt_deg > 0 && max_board_tilt_deg < 90))
    return "max_board_tilt_deg must be in (0, 90)";
  if (!(max_board_distance_m > 0)) return "max_board_distance_m must be > 0";
  if (!(pixel_sigma_px > 0)) return "pixel_sigma_px must be > 0";
  return {};
}

namespace {
// The stages of PlainStageTimes with their names, in the order they run.
template <typename Times, typename F>
void forEachStage(Times& t, F f) {
  f("noise", t.noise_ms);
  f("regions", t.regions_ms);
  f("line resize", t.line_resize_ms);
  f("LSD", t.lsd_ms);
  f("undistort", t.undistort_ms);
  f("merge", t.merge_ms);
  f("quads", t.quads_ms);
  f("trace", t.trace_ms);
  f("edges", t.edges_ms);
  f("fits", t.fits_ms);
}
}  // namespace

PlainStageTimes& PlainStageTimes::operator+=(const PlainStageTimes& other) {
  std::vector<double> add;
  forEachStage(other, [&](const char*, double ms) { add.push_back(ms); });
  size_t k = 0;
  forEachStage(*this, [&](const char*, double& ms) { ms += add[k++]; });
  return *this;
}

PlainStageTimes PlainStageTimes::scaled(double factor) const {
  PlainStageTimes out = *this;
  forEachStage(out, [&](const char*, double& ms) { ms *= factor; });
  return out;
}

double PlainStageTimes::total() const {
  double sum = 0.0;
  forEachStage(*this, [&](const char*, double ms) { sum += ms; });
  return sum;
}

std::string PlainStageTimes::text() const {
  std::string out;
  forEachStage(*this, [&](const char* name, double ms) {
    out += cv::format("%s%s %.1f", out.empty() ? "" : " | ", name, ms);
  });
  return out + cv::format(" = total %.1f", total());
}

struct ImageBoardDetector::Impl {
  Target target;
  ImageBoardDetectorOptions options;
  std::map<int, TagCorners> tags;  // grid id -> board-frame corners
  apriltag_family_t* family = nullptr;
  apriltag_detector_t* detector = nullptr;

  ~Impl() {
    if (detector) apriltag_detector_destroy(detector);
    if (family) tag36h11_destroy(family);
  }

  void detectAprilTags(const cv::Mat& gray, const CameraModel& camera, ImageDetection* out);
  void searchInColour(const cv::Mat& image, const cv::Mat& gray, const CameraModel& camera,
                      const ExpectedBoard* expected, const StaticScene* excluded,
                      ImageDetection* out) const;
};

Expected<ImageBoardDetector> ImageBoardDetector::create(const Target& target,
                                                        const ImageBoardDetectorOptions& options) {
  if (const std::string why = target.validate(); !why.empty())
    return Expected<ImageBoardDetector>::failure("target: " + why);
  if (const std::string why = options.validate(); !why.empty())
    return Expected<ImageBoardDetector>::failure("options: " + why);
  ImageBoardDetector det;
  det.impl_ = std::make_unique<Impl>();
  det.impl_->target = target;
  det.impl_->options = options;
  if (target.type == TargetType::kAprilTagGrid) {
    if (target.apriltag_grid.family != "tag36h11")
      return Expected<ImageBoardDetector>::failure("target: AprilTag family '" +
                                                   target.apriltag_grid.family +
                                                   "' not supported (only tag36h11)");
    for (const auto& t : target.aprilTagCorners()) det.impl_->tags[t.id] = t;
    det.impl_->family = tag36h11_create();
    det.impl_->detector = apriltag_detector_create();
    if (!det.impl_->family || !det.impl_->detector)
      return Expected<ImageBoardDetector>::failure("libapriltag: could not create the detector");
    apriltag_detector_add_family_bits(det.impl_->detector, det.impl_->family,
                                      options.tag_max_hamming);
    det.impl_->detector->quad_decimate = static_cast<float>(options.tag_decimate);
    det.impl_->detector->quad_sigma = static_cast<float>(options.tag_sigma);
    det.impl_->detector->nthreads = options.tag_threads;
    det.impl_->detector->refine_edges = options.tag_refine_edges;
  }
  return Expected<ImageBoardDetector>(std::move(det));
}

ImageBoardDetector::ImageBoardDetector(ImageBoardDetector&&) noexcept = default;
ImageBoardDetector& ImageBoardDetector::operator=(ImageBoardDetector&&) noexcept = default;
ImageBoardDetector::~ImageBoardDetector() = default;
const Target& ImageBoardDetector::target() const { return impl_->target; }
const ImageBoardDetectorOptions& ImageBoardDetector::options() const { return impl_->options; }

ImageDetection ImageBoardDetector::detect(const cv::Mat& image, const CameraModel& camera) {
  return run(image, camera, nullptr, nullptr);
}

ImageDetection ImageBoardDetector::detect(const cv::Mat& image, const CameraModel& camera,
                                          const StaticScene& excluded) {
  return run(image, camera, nullptr, excluded.empty() ? nullptr : &excluded);
}

ImageDetection ImageBoardDetector::detectNear(const cv::Mat& image, const CameraModel& camera,
                                              const ExpectedBoard& expected) {
  if (impl_->target.type != TargetType::kPlain || !(expected.tolerance_px > 0.0)) {
    ImageDetection out;
    out.features.K = camera.K();
    out.features.image_width = image.cols;
    out.features.image_height = image.rows;
    out.features.reason = impl_->target.type != TargetType::kPlain
                              ? "search near an expected board is for plain boards only"
                              : "expected board needs a tolerance > 0 px";
    return out;
  }
  return run(image, camera, &expected, nullptr);
}

// A board of the scene's grey but another colour (cardboard on a facade): searched once more in
// the channel where it stands out of its surroundings, inside a second chance's expected board or
// where the frame departs from the session's background, or (a single frame, or a session whose
// frame does not depart from its background) in the frame's parts of another colour than most of
// it. The place is what tells board from surroundings.
// Places where the frame departs from the scene that give no board in colour are followed by the
// frame's parts of another colour, as in a single frame.
// When the grey search did find a board but from straight lines alone, nothing vouched for its
// interior: a facade's outline fits a board of the declared shape too, and a holder's torso does
// at a steep turn. A board found in colour replaces it when it lies mostly inside it and fits the
// declared board better (held in front of it; a printed mark fits worse than the board it is on),
// or when it has more edge support weighed by its facing (the grey search's own ranking).
void ImageBoardDetector::Impl::searchInColour(const cv::Mat& image, const cv::Mat& gray,
                                              const CameraModel& camera,
                                              const ExpectedBoard* expected,
                                              const StaticScene* excluded,
                                              ImageDetection* out) const {
  std::vector<ExpectedBoard> places;
  image_detection::Foreground foreground;
  if (expected) {
    places.push_back(*expected);
  } else if (excluded && !excluded->background.empty()) {
    foreground = image_detection::foregroundMask(image, excluded->background);
    places = image_detection::foregroundBoards(foreground, camera, target, options);
  }
  const bool challenge = out->features.found;
  if (!challenge && !expected && !foreground.mask.empty() && places.empty())
    out->features.reason += "; no board-sized part of the frame departs from the scene";
  // Each place searched in its colour contrast; true when a board found there is now `out`.
  const auto searchPlaces = [&](const std::vector<ExpectedBoard>& places, bool colour_parts) {
    for (const ExpectedBoard& place : places) {
      if (challenge && !canChallenge(place, *out)) continue;
      ImageDetection colour;
      if (colour_parts) {
        // A colour part is searched in the window its contrast is measured in, not the frame.
        image_detection::detectPlainInColourWindow(image, camera, target, options, place, excluded,
                                                   &colour);
      } else {
        const cv::Mat contrast = image_detection::boardContrastImage(image, camera, place);
        if (contrast.empty()) continue;
        colour.features.K = out->features.K;
        colour.features.image_width = image.cols;
        colour.features.image_height = image.rows;
        image_detection::detectPlain(contrast, camera, target, options, &colour, &place, excluded);
      }
      // A single frame's colour part has no place to vouch for it: its sides must also end at
      // its corners in grey.
      if (colour.features.found && colour_parts)
        image_detection::sidesEndInGray(gray, camera, options, out->details.noise_sigma,
                                        &colour.features);
      if (colour.features.found)
        colour.details.board_source = std::string(colour_parts ? "colour part"
                                                  : expected   ? "colour contrast"
                                                               : "foreground") +
                                      ", " + colour.details.board_source;
      if (colour.features.found && challenge) {
        const auto& held = colour.features.corners_px;
        const auto& outline = out->features.corners_px;
        // Relative to its size, as the board test judges the fit: a flexed board misfits in
        // proportion to its size, a mark or a facade outline by its own shape.
        const auto misfit = [](const ImageDetection& d) {
          return d.features.reprojection_rms_px /
                 image_detection::meanSidePx(d.features.corners_px);
        };
        const bool in_front = image_detection::shareInside(held, outline) >= kHeldInFrontShare &&
                              misfit(colour) < misfit(*out);
        const bool better = colour.details.board_support_px > out->details.board_support_px;
        // The grey board itself: kept unless its colour contrast fits the declared board better
        // (a side's grey edge pulled by a scene edge of the board's grey).
        const bool same = image_detection::worstCornerOffset(held, outline) <
                          kSameBoardFraction * image_detection::meanSidePx(outline);
        if (same ? !(misfit(colour) < misfit(*out)) : !in_front && !better)
          continue;  // a lesser board elsewhere, or the grey board fitted as well
        colour.details.board_source += std::string(same       ? " (refitting"
                                                   : in_front ? " (held in front of"
                                                              : " (over") +
                                       " a " + out->details.board_source + " quadrilateral)";
      }
      if (colour.features.found) {
        *out = std::move(colour);
        return true;
      }
      if (challenge) continue;
      out->features.reason +=
          expected ? "; in its colour contrast: " + colour.features.reason
          : colour_parts
              ? "; in a part of one colour: " + colour.features.reason
              : "; where the frame departs from the scene, in colour: " + colour.features.reason;
    }
    return false;
  };
  if (expected || places.empty()) {
    searchPlaces(
        expected ? places : image_detection::colourPartBoards(image, camera, target, options),
        !expected);
    return;
  }
  // The frame's departures from the scene gave no board in colour (the board's part merged with
  // its holder's, or cut up by them): its parts of another colour may still, as in a single
  // frame (a board of lines alone whose one side followed a scene edge of the board's grey was
  // kept otherwise).
  if (!searchPlaces(places, false))
    searchPlaces(image_detection::colourPartBoards(image, camera, target, options), true);
}

ImageDetection ImageBoardDetector::run(const cv::Mat& image, const CameraModel& camera,
                                       const ExpectedBoard* expected, const StaticScene* excluded) {
  const auto t0 = std::chrono::steady_clock::now();
  ImageDetection out;
  CameraBoardFeatures& f = out.features;
  f.K = camera.K();
  f.image_width = image.cols;
  f.image_height = image.rows;
  if (image.empty()) {
    f.reason = "empty image";
  } else if (image.depth() != CV_8U || (image.channels() != 1 && image.channels() != 3)) {
    f.reason = "unsupported image type (need bgr8 or mono8), got " +
               std::to_string(image.channels()) + " channel(s) of depth " +
               std::to_string(image.depth());
  } else if (image.cols != camera.width() || image.rows != camera.height()) {
    f.reason = "image " + std::to_string(image.cols) + "x" + std::to_string(image.rows) +
               " does not match the camera model " + std::to_string(camera.width()) + "x" +
               std::to_string(camera.height());
  } else {
    // OpenCV asserts on degenerate input (a tiny or uniform image); that is a failed
    // detection with its short reason, never an exception through a nodelet callback.
    try {
      const cv::Mat gray = image_detection::toGray(image);
      switch (impl_->target.type) {
        case TargetType::kPlain:
          image_detection::detectPlain(gray, camera, impl_->target, impl_->options, &out, expected,
                                       excluded, true, hasColour(image));
          nameBestAttempt(camera, &out);
          if (image.channels() == 3 && (!f.found || worthChallenging(out)))
            impl_->searchInColour(image, gray, camera, expected, excluded, &out);
          break;
        case TargetType::kCheckerboard:
          image_detection::detectCheckerboard(gray, camera, impl_->target, impl_->options, &out);
          break;
        case TargetType::kAprilTagGrid: impl_->detectAprilTags(gray, camera, &out); break;
      }
    } catch (const cv::Exception& e) {
      out = ImageDetection{};
      f.K = camera.K();
      f.image_width = image.cols;
      f.image_height = image.rows;
      f.reason = "image detection failed: " + e.err;
    }
  }
  if (!f.found && f.reason.empty()) f.reason = "board not found";
  out.details.time_ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  return out;
}

void ImageBoardDetector::Impl::detectAprilTags(const cv::Mat& gray_in, const CameraModel& camera,
                                               ImageDetection* out) {
  CameraBoardFeatures& f = out->features;
  ImageDetectionDetails& d = out->details;
  // libapriltag reads out of bounds (and crashes) on an image whose decimated height is 2 px or
  // less, and on 1-2 px wide ones at fractional decimations; no tag fits in one that small anyway.
  // In double: tag_decimate has no upper bound here (dynamic_reconfigure clamps it to 8).
  const double min_side = std::max(kMinTagImageSidePx, std::ceil(4 * options.tag_decimate));
  if (gray_in.cols < min_side || gray_in.rows < min_side) {
    f.reason = cv::format("image too small for AprilTags (%dx%d px, need %.0f px on each side)",
                          gray_in.cols, gray_in.rows, min_side);
    return;
  }
  const cv::Mat gray = gray_in.isContinuous() ? gray_in : gray_in.clone();
  image_u8_t im{gray.cols, gray.rows, static_cast<int32_t>(gray.step[0]),
                const_cast<uint8_t*>(gray.ptr<uint8_t>())};
  zarray_t* detections = apriltag_detector_detect(detector, &im);
  Points3 board;
  Points2 undist;
  std::vector<int> ids;
  std::string wrong_ids;
  for (int i = 0; i < zarray_size(detections); ++i) {
    apriltag_detection_t* det = nullptr;
    zarray_get(detections, i, &det);
    const auto it = tags.find(det->id);
    if (it == tags.end()) {
      ++d.rejected_tags;
      wrong_ids += (wrong_ids.empty() ? "" : ",") + std::to_string(det->id);
      continue;
    }
    std::array<Eigen::Vector2d, 4> raw;
    for (int k = 0; k < 4; ++k) {
      raw[k] =
          Eigen::Vector2d(det->p[k][0] - kAprilTagPixelOffset, det->p[k][1] - kAprilTagPixelOffset);
      board.push_back(it->second.corners[k]);
      undist.push_back(camera.undistortPixel(raw[k]));
      ids.push_back(det->id * 4 + k);
      d.pattern_raw.push_back(raw[k]);
    }
    d.tag_ids.push_back(det->id);
    d.tag_corners_raw.push_back(raw);
  }
  apriltag_detections_destroy(detections);
  const int found_tags = static_cast<int>(d.tag_ids.size());
  if (found_tags == 0) {
    f.reason = d.rejected_tags > 0 ? "wrong ids: tags " + wrong_ids + " are not on the grid"
                                   : "board not found: no AprilTag";
    return;
  }
  if (found_tags < options.min_tags) {
    f.reason = "board not found: " + std::to_string(found_tags) + " tag(s), need " +
               std::to_string(options.min_tags);
    return;
  }
  double size_px = 0;
  for (size_t i = 1; i < undist.size(); ++i)
    size_px = std::max(size_px, (undist[i] - undist[0]).norm());
  if (size_px < options.min_board_size_px) {
    f.reason = cv::format("board too small: tags span %.0f px", size_px);
    return;
  }
  const image_detection::PoseFit pose =
      image_detection::fitPose(board, undist, f.K, options.pixel_sigma_px);
  if (!pose.ok) {
    f.reason = pose.reason;
    return;
  }
  for (size_t i = 0; i < undist.size(); ++i) f.pattern.push_back({ids[i], board[i], undist[i]});
  f.camera_T_board = pose.camera_T_board;
  f.plane = image_detection::planeFromPose(pose.camera_T_board);
  f.reprojection_rms_px = pose.rms_px;
  d.pattern_errors_px = pose.errors_px;
  d.pose_covariance = pose.covariance;
  image_detection::outerEdgesFromPose(target, &f);
  if (pose.rms_px > options.max_reprojection_rms_px) {
    f.reason = cv::format("tag corners do not fit the grid (rms %.2f px)", pose.rms_px);
    return;
  }
  if (d.rejected_tags > 0) f.reason = "ignored tags not on the grid: " + wrong_ids;
  f.found = true;
}

std::vector<BoardCandidate> boardCandidates(const ImageDetection& detection,
                                            const CameraModel& camera, const Target& target,
                                            double corner_sigma_px) {
  std::vector<std::array<Eigen::Vector2d, kNumEdges>> quads = detection.details.hypotheses_px;
  if (detection.features.found) quads.push_back(detection.features.corners_px);
  const auto outer = target.outerCorners();
  const Points3 board(outer.begin(), outer.end());
  const Eigen::Matrix3d K = camera.K();
  const double f = K(0, 0);
  std::vector<BoardCandidate> out;
  for (const auto& q : quads) {
    const double side = image_detection::meanSidePx(q);
    if (!(side > 0) || !std::isfinite(side)) continue;
    // Either side of the quadrilateral may be the board's width.
    image_detection::PoseFit best;
    for (int shift = 0; shift < 2; ++shift) {
      Points2 pixels;
      for (int k = 0; k < kNumEdges; ++k) pixels.push_back(q[(k + shift) % 4]);
      const image_detection::PoseFit fit =
          image_detection::fitPose(board, pixels, K, corner_sigma_px);
      if (fit.ok && (!best.ok || fit.rms_px < best.rms_px)) best = fit;
    }
    if (!best.ok || best.rms_px > 0.25 * side) continue;
    BoardCandidate c;
    c.centre = best.camera_T_board * target.center();
    const double depth = c.centre.norm(), sigma_px = std::max(best.rms_px, corner_sigma_px);
    // Depth from the apparent size: d = f w / w_px, so sigma_d = d^2 sigma_px / (f w).
    c.depth_sigma_m = depth * depth * sigma_px / (f * std::min(target.width, target.height));
    c.lateral_sigma_m = depth * sigma_px / f;
    if (c.centre.allFinite() && std::isfinite(c.depth_sigma_m)) out.push_back(c);
  }
  return out;
}

}  // namespace board_calib
