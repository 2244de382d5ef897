#include <board_calib/core/capture/stillness.h>
#include <board_calib/core/common/format.h>
#include <board_calib/core/transform.h>

#include <algorithm>
#include <cmath>
#include <sstream>

namespace board_calib {
namespace {

constexpr size_t kClockFrames = 32;  // recent stamps kept for the median interval
// m/s: a board carried, turned or waved by hand moves slower (a brisk walk is 2 m/s). Two
// frames of one stream further apart than this speed allows saw two different objects.
constexpr double kHandHeldSpeedMps = 5.0;

}  // namespace

std::string StillnessOptions::validate() const {
  if (!(window_s > 0.0) || !std::isfinite(window_s) || window_s > 10.0)
    return "still window must be in (0, 10] s";
  if (min_frames < 1 || min_frames > 1000) return "still frames must be in [1, 1000]";
  if (!(max_translation_m > 0.0) || !std::isfinite(max_translation_m))
    return "still max translation must be a finite value > 0";
  if (!(max_rotation_deg > 0.0) || !std::isfinite(max_rotation_deg))
    return "still max rotation must be a finite value > 0";
  if (!(noise_factor >= 0.0) || !std::isfinite(noise_factor))
    return "still noise factor must be finite and >= 0";
  if (!(snapshot_interval_s > 0.0) || !std::isfinite(snapshot_interval_s))
    return "snapshot interval must be a finite value > 0";
  return {};
}

void StreamClock::add(double stamp) {
  stamps_.push_back(stamp);
  while (stamps_.size() > kClockFrames) stamps_.pop_front();
}

double StreamClock::typicalInterval() const {
  std::vector<double> gaps;
  for (size_t i = 1; i < stamps_.size(); ++i)
    if (stamps_[i] > stamps_[i - 1]) gaps.push_back(stamps_[i] - stamps_[i - 1]);
  if (gaps.empty()) return 0.0;
  // The lower quartile: a thinned or paused stream still shows its frame rate in its bursts.
  const size_t k = gaps.size() / 4;
  std::nth_element(gaps.begin(), gaps.begin() + k, gaps.end());
  return gaps[k];
}

const char* stillStateName(StillState state) {
  switch (state) {
    case StillState::kPending: return "pending";
    case StillState::kStill: return "still";
    case StillState::kMoving: return "moving";
    case StillState::kNoBoard: return "no board";
    case StillState::kTooFewFrames: return "too few frames";
    case StillState::kSnapshot: return "snapshot";
  }
  return "unknown";
}

namespace {

// How far a frame's board is from the reference frame's, against what noise and the options
// allow: in the board plane (edge centres when both have them, else centroids), along the
// normal, and in turn.
struct Motion {
  bool moving = false;
  bool jump = false;  // faster than a hand-held board: not one object
  std::string why;
};

// The board's displacement from `ref` to `x` and each frame's in-plane 1 sigma: the centres from
// the edges when both have them, else the centroids of the scan lines both have, else the
// centroids of all points.
struct Displacement {
  Eigen::Vector3d d = Eigen::Vector3d::Zero();
  double sx = 0.0, sr = 0.0;
  const char* what = " of the centroids";
};

Displacement displacementOf(const BoardSample& x, const BoardSample& ref) {
  Displacement r;
  r.d = x.centroid - ref.centroid;
  r.sx = x.centroid_sigma_m;
  r.sr = ref.centroid_sigma_m;
  Eigen::Vector3d cx, cr;
  if (x.centre_from_edges && ref.centre_from_edges) {
    r.d = x.centre - ref.centre;
    r.sx = x.centre_sigma_m;
    r.sr = ref.centre_sigma_m;
    r.what = " from the edges";
  } else if (sharedLineCentroids(x, ref, &cx, &cr, &r.sx, &r.sr)) {
    r.d = cx - cr;
    r.what = " of the shared scan lines";
  }
  return r;
}

// A frame of the window that saw the board, with its displacement from the reference frame
// (computed once, for the pair check and the drift fit).
struct SeenFrame {
  const BoardSample* sample = nullptr;
  Displacement disp;
};

Motion motionOf(const SeenFrame& f, const BoardSample& ref, const StillnessOptions& o) {
  const BoardSample& x = *f.sample;
  const Displacement& disp = f.disp;
  const Eigen::Vector3d& d = disp.d;
  const double sx = disp.sx, sr = disp.sr;
  const char* what = disp.what;
  const Eigen::Vector3d n = ref.normal.normalized();
  const double along = std::abs(d.dot(n));
  const double in_plane = (d - d.dot(n) * n).norm();
  const double in_tol = o.max_translation_m + o.noise_factor * std::hypot(sx, sr);
  const double along_tol =
      o.max_translation_m + o.noise_factor * std::hypot(x.plane_sigma_m, ref.plane_sigma_m);
  const double turn_deg = angleBetweenDeg(x.normal, ref.normal);
  const double turn_tol_deg =
      o.max_rotation_deg +
      o.noise_factor * kDegPerRad * std::hypot(x.normal_sigma_rad, ref.normal_sigma_rad);
  Motion m;
  m.moving = in_plane > in_tol || along > along_tol || turn_deg > turn_tol_deg;
  const auto cm = [](double v) { return formatFixed(v * 100, 1); };
  const double dt = std::abs(x.stamp - ref.stamp), jump = d.norm() - std::max(in_tol, along_tol);
  if (m.moving && dt > 0.0 && jump > kHandHeldSpeedMps * dt) {
    m.jump = true;
    m.why = formatFixed(d.norm(), 2) + " m between frames " + formatFixed(dt, 2) +
            " s apart, faster than a hand-held board moves (" + formatFixed(kHandHeldSpeedMps, 0) +
            " m/s)";
    return m;
  }
  m.why = cm(in_plane) + " cm in its plane (allowed " + cm(in_tol) + ", 1 sigma " + cm(sx) + "/" +
          cm(sr) + what + "), " + cm(along) + " cm along its normal (allowed " + cm(along_tol) +
          "), turn " + formatFixed(turn_deg, 1) + " deg (allowed " + formatFixed(turn_tol_deg, 1) +
          ")";
  if (x.scan_lines > 0 || ref.scan_lines > 0)
    m.why +=
        "; " + std::to_string(x.scan_lines) + "/" + std::to_string(ref.scan_lines) + " scan lines";
  return m;
}

// A steady drift over the whole window, which no single pair of frames resolves: a straight
// line fitted (ordinary least squares in time, so no frame's claimed sigma steers the slope) to
// the positions of every frame seeing the board, per axis of the reference board plane and along
// its normal, and the fitted displacement from the first frame to the last against the same
// allowance as a pair: max_translation_m + noise_factor x its own 1 sigma. That 1 sigma is the
// frames' sigmas propagated through the fit, sigma_D = span sqrt(sum c_i^2 s_i^2) / sum c_i^2
// (c_i = t_i - mean t): the slope averages the independent noise of all N frames, about
// s sqrt(12 / N) over the span (5 frames: 1.3 s over 0.4 s), where a pair has sqrt(2) s over
// half the span. Positions: the centres from the edges when every frame has them (then the
// reference's own error is a common offset, which no slope sees); else each frame's displacement
// from the reference as a pair measures it, with both frames' sigmas (the shared scan lines
// differ from pair to pair, so the reference's error is counted for each: conservative). Needs 3
// frames (2 are a pair, judged already).
Motion driftOf(const std::vector<SeenFrame>& xs, const BoardSample& ref,
               const StillnessOptions& o) {
  Motion m;
  if (xs.size() < 3) return m;
  bool edges = true;
  double t_mean = 0.0;
  for (const SeenFrame& f : xs) {
    edges = edges && f.sample->centre_from_edges;
    t_mean += f.sample->stamp;
  }
  t_mean /= static_cast<double>(xs.size());
  const Eigen::Vector3d n = ref.normal.normalized();
  Eigen::Vector3d slope_sum = Eigen::Vector3d::Zero();
  double cc = 0.0, in_var = 0.0, along_var = 0.0, t_lo = xs.front().sample->stamp, t_hi = t_lo;
  for (const SeenFrame& f : xs) {
    const BoardSample* x = f.sample;
    const double c = x->stamp - t_mean;
    Eigen::Vector3d p = x->centre - ref.centre;
    double s = x->centre_sigma_m, a = x->plane_sigma_m;
    if (!edges && x != &ref) {
      p = f.disp.d;
      s = std::hypot(f.disp.sx, f.disp.sr);
      a = std::hypot(x->plane_sigma_m, ref.plane_sigma_m);
    } else if (!edges) {
      p.setZero();  // the reference's error is in every other frame's displacement
      s = a = 0.0;
    }
    slope_sum += c * p;
    cc += c * c;
    in_var += c * c * s * s;
    along_var += c * c * a * a;
    t_lo = std::min(t_lo, x->stamp);
    t_hi = std::max(t_hi, x->stamp);
  }
  if (!(cc > 0.0)) return m;
  const double span = t_hi - t_lo;
  const Eigen::Vector3d d = span * slope_sum / cc;  // fitted displacement over the span
  const double along = std::abs(d.dot(n));
  const double in_plane = (d - d.dot(n) * n).norm();
  const double in_sigma = span * std::sqrt(in_var) / cc;
  const double along_sigma = span * std::sqrt(along_var) / cc;
  const double in_tol = o.max_translation_m + o.noise_factor * in_sigma;
  const double along_tol = o.max_translation_m + o.noise_factor * along_sigma;
  m.moving = in_plane > in_tol || along > along_tol;
  const auto cm = [](double v) { return formatFixed(v * 100, 1); };
  m.why = "a steady drift of " + cm(in_plane) + " cm in its plane (allowed " + cm(in_tol) +
          ", fit 1 sigma " + cm(in_sigma) + (edges ? " from the edges" : " of the pairs") +
          ") and " + cm(along) + " cm along its normal (allowed " + cm(along_tol) + ") over " +
          std::to_string(xs.size()) + " frames, " + formatFixed(span, 2) + " s";
  return m;
}

// One stream's frames in [stamp - window, stamp + window] against the one nearest the moment;
// false with `j` set when they show motion, a lost board or (the fastest stream) too few frames.
bool streamStill(const StillnessStream& stream, bool is_fastest, double stamp,
                 double fastest_interval, const StillnessOptions& o, StillnessJudgement* j) {
  const double lo = stamp - o.window_s, hi = stamp + o.window_s;
  const auto& samples = *stream.samples;
  // Reference: the frame nearest the moment that sees the board.
  const BoardSample* ref = nullptr;
  for (const auto& x : samples)
    if (x.found && x.stamp >= lo && x.stamp <= hi &&
        (!ref || std::abs(x.stamp - stamp) < std::abs(ref->stamp - stamp)))
      ref = &x;
  int before = 0, after = 0, count = 0, missing = 0;
  const auto refuseMoving = [&](const std::string& what) {
    j->state = StillState::kMoving;
    j->why = "board moving: " + stream.name + " saw " + what + " within " +
             formatFixed(o.window_s, 2) + " s of the image";
    return false;
  };
  const auto refuseJump = [&](const std::string& what) {
    j->state = StillState::kMoving;
    j->different_objects = true;
    j->why = stream.name + " took different objects for the board: its board jumped " + what;
    return false;
  };
  std::vector<SeenFrame> seen;
  for (const auto& x : samples) {
    if (x.stamp < lo || x.stamp > hi) continue;
    // A detector misses a still board now and then: such a frame is no evidence either way.
    if (!x.found) {
      ++missing;
      continue;
    }
    ++count;
    seen.push_back({&x, displacementOf(x, *ref)});
    if (x.stamp < stamp) ++before;
    if (x.stamp > stamp) ++after;
    const Motion m = motionOf(seen.back(), *ref, o);
    if (m.jump) return refuseJump(m.why);
    if (m.moving) return refuseMoving("it move " + m.why);
  }
  if (o.fit_drift && ref) {  // no reference: no frame saw the board, nothing to fit
    const Motion m = driftOf(seen, *ref, o);
    if (m.moving) return refuseMoving(m.why);
  }
  // Lost in most of the window: the board left the view (or was never there).
  if (missing > 0 && missing >= count) {
    j->state = StillState::kNoBoard;
    j->why = stream.name + " lost the board in " + std::to_string(missing) + " of " +
             std::to_string(missing + count) + " frames within " + formatFixed(o.window_s, 2) +
             " s of the image";
    return false;
  }
  if (is_fastest) {
    j->fastest_frames = count;
    // Frames on both sides: the board was still across the moment, not only up to it.
    if (count < o.min_frames || before == 0 || after == 0) {
      j->state = StillState::kTooFewFrames;
      j->why = stream.name + " (the fastest stream, " + formatFixed(fastest_interval * 1e3, 0) +
               " ms between frames) has " + std::to_string(count) + " frame(s) within " +
               formatFixed(o.window_s, 2) + " s of the image (" + std::to_string(before) +
               " before, " + std::to_string(after) + " after; need " +
               std::to_string(o.min_frames) + " spanning it)";
      return false;
    }
  }
  return true;
}

}  // namespace

// Share of snapshot_interval_s a stream's interval must reach to count as sparse.
constexpr double kSnapshotIntervalShare = 0.95;

StillnessJudgement judgeStillness(const std::vector<StillnessStream>& streams, double stamp,
                                  const StillnessOptions& o, bool ended) {
  StillnessJudgement j;
  // No window around a moment that is not one (the frames' references would be unset).
  if (!std::isfinite(stamp)) {
    j.state = StillState::kNoBoard;
    j.why = "the moment's stamp is not finite";
    return j;
  }
  // The fastest stream counts the frames; a stream with one frame so far has no rate yet.
  double fastest_interval = 0.0;
  bool all_sparse = true, rates_known = true;
  for (size_t s = 0; s < streams.size(); ++s) {
    const double interval = streams[s].clock->typicalInterval();
    if (interval <= 0.0) {
      all_sparse = false;  // unknown rate: not (yet) evidence of a snapshot recording
      rates_known = false;
      continue;
    }
    // "0.5 s or more between frames": a 2 Hz stream's stamps jitter about its interval.
    if (interval < kSnapshotIntervalShare * o.snapshot_interval_s) all_sparse = false;
    if (!streams[s].judged) continue;
    if (j.fastest_stream < 0 || interval < fastest_interval) {
      j.fastest_stream = static_cast<int>(s);
      fastest_interval = interval;
    }
  }
  if (o.min_frames <= 1) {
    j.state = StillState::kSnapshot;
    j.why = "stillness check off (still frames 1): every synchronised pair is a candidate";
    return j;
  }
  if (!rates_known && !ended) return j;  // every stream's rate decides the rule: wait for it
  if (all_sparse && j.fastest_stream >= 0) {
    j.state = StillState::kSnapshot;
    j.why = "snapshot recording (every stream " + formatFixed(fastest_interval, 2) +
            " s or more between frames): each synchronised pair is a candidate";
    return j;
  }
  if (j.fastest_stream < 0) {
    if (!ended) return j;  // no rate known yet: wait for more frames
    j.state = StillState::kTooFewFrames;
    j.why = "too few frames to measure any stream's rate";
    return j;
  }
  // The window holds the frames it asks for: a fastest stream too slow for min_frames in
  // +-window_s (2-4 Hz with the defaults: never more than 2) widens it to min_frames intervals,
  // so the board must stay still longer rather than never be captured.
  StillnessOptions wide = o;
  wide.window_s = std::max(o.window_s, 0.5 * o.min_frames * fastest_interval);
  const double hi = stamp + wide.window_s;
  const StillnessStream& fast = streams[static_cast<size_t>(j.fastest_stream)];
  if (!ended && fast.clock->newest() < hi) return j;  // the window is not complete yet

  for (size_t s = 0; s < streams.size(); ++s)
    if (streams[s].judged && !streamStill(streams[s], static_cast<int>(s) == j.fastest_stream,
                                          stamp, fastest_interval, wide, &j)) {
      if (j.state == StillState::kNoBoard) j.lost_stream = static_cast<int>(s);
      return j;
    }
  j.state = StillState::kStill;
  j.why = "board still for +-" + formatFixed(wide.window_s, 2) + " s (" +
          std::to_string(j.fastest_frames) + " " +
          streams[static_cast<size_t>(j.fastest_stream)].name + " frames)";
  return j;
}

StillnessOptions StillCaptureOptions::stillness() const {
  StillnessOptions o;
  o.window_s = still_window_s;
  o.min_frames = still_frames_required;
  o.max_translation_m = still_max_translation_m;
  o.max_rotation_deg = still_max_rotation_deg;
  o.snapshot_interval_s = snapshot_interval_s;
  return o;
}

}  // namespace board_calib
