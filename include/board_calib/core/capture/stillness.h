// Stillness of the board around a moment, judged by every stream and counted on the fastest.
//
// A view pairs an image with a cloud taken up to a sync tolerance apart, and a camera may run at
// 1-2 Hz while the LiDAR runs at 10-20 Hz. Comparing consecutive images then says nothing about
// the board between them; the LiDAR frames around the image stamp do. So a moment t is judged
// still when every stream's frames inside [t - window, t + window] see the board and agree with
// the frame nearest t (centre and normal, tolerances widened by each frame's own noise), a
// straight line fitted to all of them shows no drift across the window beyond its own noise, and
// the fastest stream has enough frames there, on both sides of t. When every stream is sparse (one
// frame per pose, "snapshot" recordings) no stream can show stillness: every moment is a
// candidate and the consistency checks before solving must catch a moving board.
#pragma once

#include <board_calib/core/features.h>
#include <board_calib/core/target.h>

#include <Eigen/Core>

#include <deque>
#include <string>
#include <vector>

namespace board_calib {

/// One sensor's view of the board at one stamp, in that sensor's frame.
///
/// Two frames of a still board are compared like for like: the centres from the board's edges
/// when both frames have them (they do not move when a scan line enters or leaves the board),
/// else the centroids of the scan lines both frames have, else the centroids of all points. A
/// centre change is split into its part in the board plane (compared with the centre's sampling
/// noise) and its part along the normal (compared with the plane's noise, which no sampling of the
/// board moves).
struct BoardSample {
  double stamp = 0.0;  ///< s
  bool found = false;
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();   ///< m, the centre from the edges if known
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();  ///< unit
  double centre_sigma_m = 0.0;                        ///< m, 1 sigma of `centre` in the board plane
  double normal_sigma_rad = 0.0;                      ///< 1 sigma of the normal
  double plane_sigma_m = 0.0;      ///< m, 1 sigma of the board plane along its normal
  bool centre_from_edges = false;  ///< `centre` is the mean of the four edge-line corners
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();  ///< m, mean of the board points
  double centroid_sigma_m = 0.0;  ///< m, 1 sigma of `centroid` in the plane under the sampling
  int scan_lines = 0;             ///< LiDAR: scan lines on the board (0: a camera)
  /// LiDAR: the board points of one scan line, so two frames compare the lines both have.
  struct Line {
    double elevation_rad = 0.0;
    int points = 0;
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();  ///< m, sum of the line's points
    double chord_m = 0.0;                           ///< m, between the line's two ends
  };
  std::vector<Line> lines;
  double line_gap_rad = 0.0;   ///< median elevation step between the lines (0: one line)
  double point_sigma_m = 0.0;  ///< m, in-plane part of one point's range noise
};

/// The centroids of the scan lines two LiDAR frames share (matched by elevation, within half
/// their spacing) and each one's 1 sigma in the board plane: the range noise over the shared
/// points, and the column sampling (a point more or less at each end of a line, each with
/// probability about 1/2, moves the centroid by that end's offset / n). False when no line is
/// shared or a sample has no lines.
bool sharedLineCentroids(const BoardSample& a, const BoardSample& b, Eigen::Vector3d* centre_a,
                         Eigen::Vector3d* centre_b, double* sigma_a, double* sigma_b);

/// A LiDAR board as a stillness cue. Its noise follows the sampling measured on the board's own
/// points: scan lines (by elevation), their spacing and the column spacing along them.
///  - centroid of all points: which scan lines reach the board changes between sweeps (a grazing
///    line, a line a detector drops), so its in-plane sigma is the jackknife over scan lines (the
///    spread of the centroids that leave one line out), plus the range noise rms / sqrt(n); it
///    is the last resort, when two frames share no scan line;
///  - centre from the edges (all four edges fitted): each edge point lies on its scan line within
///    a column spacing (uniform: spacing / sqrt(12)) and the in-plane part of the range noise
///    (rms x the sine of the ray's incidence on the board), and an edge line's
///    offset averages its k points, so the centre (half of two opposite offsets per axis) has
///    1 sigma = 0.5 sigma_point sqrt(sum_j 1 / k_j);
///  - normal: the plane fit's tilt about the board's narrower in-plane spread, rms / (sqrt(n)
///    spread_min), and at least the jackknife over scan lines (three or more: a few lines tilt
///    the fit);
///  - plane: rms / sqrt(n).
BoardSample boardSampleOf(const LidarBoardFeatures& features);
/// A camera board pose as a stillness cue: its error grows with distance (lateral ~ D, depth
/// ~ D^2 / size). Without a target the board origin stands for the centre and the size is
/// taken as 1 m.
BoardSample boardSampleOf(const CameraBoardFeatures& features, const Target* target);

struct StillnessOptions {
  double window_s = 0.25;  ///< s, half-width of the window around a moment that must be still
  int min_frames =
      3;  ///< frames of the fastest stream in the window (>= 1 on each side); 1: no check
  double max_translation_m =
      0.03;  ///< m, board centre motion allowed inside the window (beyond noise)
  double max_rotation_deg =
      1.5;  ///< deg, board normal change allowed inside the window (beyond noise)
  double noise_factor =
      3.0;  ///< tolerances widen by this many 1-sigma of the two frames' combined noise
  double snapshot_interval_s = 0.5;  ///< s, when every stream's typical frame interval exceeds
                                     ///< this, each frame is its own pose (snapshot recording)
  /// Also fit a straight-line motion to each stream's frames over the whole window (3 or more)
  /// and judge its displacement against the fit's own 1 sigma: a steady slow drift that no pair
  /// resolves. false: pairs only (the session 6 judge, for comparison).
  bool fit_drift = true;
  std::string validate() const;
};

/// A stream whose stamps go back by more than this restarted (a bag played again, a clock
/// reset, or a stamp far in the future before): its buffered frames no longer compare.
constexpr double kStreamTimeJumpBackS = 2.0;

/// Stamps of one stream, for its measured frame interval.
class StreamClock {
 public:
  void add(double stamp);
  /// Lower quartile of the recent positive intervals (the frame period, even when the stream
  /// pauses between bursts); 0 before two frames.
  double typicalInterval() const;
  double newest() const { return stamps_.empty() ? -1e300 : stamps_.back(); }
  bool empty() const { return stamps_.empty(); }
  void clear() { stamps_.clear(); }

 private:
  std::deque<double> stamps_;
};

enum class StillState {
  kPending,  ///< the fastest stream has not yet passed the end of the window
  kStill,
  kMoving,        ///< a frame in the window disagrees with the one nearest the moment
  kNoBoard,       ///< a frame in the window does not see the board
  kTooFewFrames,  ///< the fastest stream has too few frames in the window to judge
  kSnapshot,      ///< every stream sparse: a candidate without a stillness check
};
const char* stillStateName(StillState state);

/// The capture's skip kind for a judgement with `different_objects` (pair and rig sessions).
inline constexpr char kDifferentObjects[] = "different objects taken for the board";

struct StillnessJudgement {
  StillState state = StillState::kPending;
  std::string why;  ///< in words, with the figures
  int fastest_stream = -1;
  int fastest_frames = 0;  ///< frames of the fastest stream inside the window
  int lost_stream = -1;    ///< kNoBoard: the stream that lost the board
  /// kMoving: one stream's board jumped faster than a hand-held board moves (its detector took
  /// different objects for the board, e.g. at the edge of its view or on a flat look-alike)
  bool different_objects = false;
};

/// The capture's skip kind for a kMoving judgement: a moving board, or different objects.
inline const char* movingKind(const StillnessJudgement& j) {
  return j.different_objects ? kDifferentObjects : "board moving";
}

/// One stream as the judge sees it: its samples (sorted by stamp) and its clock.
struct StillnessStream {
  const std::deque<BoardSample>* samples = nullptr;
  const StreamClock* clock = nullptr;
  std::string name;  ///< "LiDAR", "camera", a sensor name
  /// false: the stream does not see the board around this moment (a rig sensor the board is
  /// outside of); only its rate counts, for the snapshot rule. The fastest *judged* stream
  /// counts the frames.
  bool judged = true;
};

/// Judges the moment `stamp`. `ended`: no more frames will come (end of a bag), so a window the
/// fastest stream has not passed is judged with what is there.
StillnessJudgement judgeStillness(const std::vector<StillnessStream>& streams, double stamp,
                                  const StillnessOptions& options, bool ended);

/// The stillness settings of a capturing session, under the names the calibrator's parameters
/// use: the pair session (SessionOptions) and the rig session (RigSessionOptions) both extend it.
struct StillCaptureOptions {
  int still_frames_required = 2;  ///< frames of the fastest stream seeing the board in the still
                                  ///< window, on both sides of the moment (1 = no stillness check)
  double still_window_s = 0.25;   ///< s, the board must be still this long before and after
  double still_max_translation_m =
      0.03;  ///< m, board centre motion allowed inside the window (beyond noise)
  double still_max_rotation_deg =
      1.5;  ///< deg, board normal change allowed inside the window (beyond noise)
  double snapshot_interval_s = 0.5;  ///< s, every stream sparser than this: one frame per pose
  /// As the stillness judge takes them.
  StillnessOptions stillness() const;
};

}  // namespace board_calib
