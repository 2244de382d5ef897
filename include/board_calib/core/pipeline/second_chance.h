// Second chance (issue 14, item 3b): once a first calibration from the confident views exists,
// a moment where one sensor found the board and the other did not is searched again in the
// other sensor, restricted to where the prior extrinsic puts the board: the image inside the
// projected LiDAR board (ImageBoardDetector::detectNear), the cloud inside the back-projected
// image board (detectLidarBoardNear). The same detectors and checks decide; only the search
// region changes. The offline pipeline runs it as a second pass over the same frames.
#pragma once

#include <board_calib/core/camera_model.h>
#include <board_calib/core/features.h>
#include <board_calib/core/image_detection/image_board_detector.h>
#include <board_calib/core/lidar_detection/lidar_board_detector.h>
#include <board_calib/core/pipeline/pair_calibration.h>
#include <board_calib/core/session/session.h>

#include <map>
#include <optional>
#include <string>
#include <vector>

namespace board_calib {

struct SecondChanceOptions {
  double sigma_factor = 3.0;  ///< tolerances are this many sigmas of the prior's error where the
                              ///< board is, plus the other sensor's sampling
  double min_rotation_sigma_deg =
      0.05;  ///< deg, floor of the prior's rotation sigma (a covariance can be optimistic)
  double min_translation_sigma_m = 0.005;  ///< m, floor of the prior's translation sigma
  double corner_sigma_px = 1.0;   ///< px, 1 sigma of a plain board's image corner (the depth
                                  ///< error of its PnP grows with range^2 from it)
  double min_tolerance_px = 4.0;  ///< px, smallest image search tolerance (line fits and bowing)
  /// Distinct board positions that must agree before a prior is taken from the session's
  /// consensus alone, without a first calibration (consensusPrior; at least 3: a rigid motion).
  int min_consensus_boards = 5;
  std::string validate() const;
};

/// A board the camera found, as much as the second chance needs of it.
struct ImageSighting {
  Eigen::Isometry3d camera_T_board = Eigen::Isometry3d::Identity();
  double depth_sigma_m = 0.0;  ///< m, 1 sigma of the PnP along the viewing ray at the board
};

/// A board the LiDAR found.
struct LidarSighting {
  /// m, LiDAR frame (when corners_valid); zeros otherwise (Eigen's `{}` leaves them unset)
  std::array<Eigen::Vector3d, kNumEdges> corners = {
      Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero(),
      Eigen::Vector3d::Zero()};
  bool corners_valid = false;  ///< all four edges fitted
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  double line_spacing_m =
      0.0;  ///< m, median gap between consecutive scan lines along the edges (0: unknown)
};

/// Every board each sensor found in one pass, by stamp, and the stamps of the frames where it
/// found none.
struct BoardSightings {
  std::map<double, ImageSighting> images;
  std::map<double, LidarSighting> clouds;
  std::vector<double> images_missed, clouds_missed;
  /// First pass, plain boards: every board-shaped quadrilateral each image search tried, found
  /// or not (boardCandidates), for a consensus without a calibration.
  std::map<double, std::vector<BoardCandidate>> image_candidates;
};

/// s, how far in time the other sensor's board may be from a missed frame: the session's still
/// window plus its sync tolerance (the session judges the frames around an image over that span;
/// a board that moved meanwhile is not found near, or is judged moving by the session).
double secondChanceWindowS(const SessionOptions& session);

/// Frames a second pass may recover: a miss with the other sensor's board within `window_s`
/// (0: a second pass has nothing to do). Images count for plain boards only: the pattern boards
/// are found alone or not at all (ImageBoardDetector::detectNear).
int secondChanceCandidates(const BoardSightings& sightings, double window_s, const Target& target);

ImageSighting imageSighting(const CameraBoardFeatures& features, const CameraModel& camera,
                            const Target& target, const SecondChanceOptions& options);
LidarSighting lidarSighting(const LidarBoardFeatures& features);

/// The first calibration and what the first pass found.
struct SecondChancePrior {
  Eigen::Isometry3d camera_T_lidar = Eigen::Isometry3d::Identity();
  double rotation_sigma_rad = 0.0;   ///< rad, largest 1 sigma of the prior's rotation
  double translation_sigma_m = 0.0;  ///< m, largest 1 sigma of the prior's translation
  BoardSightings first_pass;
};

/// The prior from a first run; nullopt (with the reason) when its verdict is failed.
std::optional<SecondChancePrior> secondChancePrior(const PairCalibration& run,
                                                   const BoardSightings& first_pass,
                                                   const SecondChanceOptions& options,
                                                   std::string* why_not);

/// Without a first calibration (issue 14, 3a: the board is what moves): a placement of the LiDAR
/// in the camera frame that puts the LiDAR's boards on image candidates of the same moments
/// (within `pair_tolerance_s`), drawn from triples of them and scored by the distinct board
/// positions it explains. The best, refitted on those, is the prior when at least
/// options.min_consensus_boards positions agree and they span more than a line; its 1 sigmas
/// come from their residuals. A scene rectangle stays put while the board moves, so it cannot
/// take part in such a consensus. nullopt with the reason otherwise; `summary` says what agreed.
std::optional<SecondChancePrior> consensusPrior(const BoardSightings& first_pass,
                                                double pair_tolerance_s, const Target& target,
                                                const SecondChanceOptions& options,
                                                std::string* why_not, std::string* summary);
/// Where the prior puts the board the LiDAR saw nearest to an image at `stamp` (within
/// `window_s`); nullopt with the reason when there is none.
std::optional<ExpectedBoard> expectedImageBoard(const SecondChancePrior& prior, double stamp,
                                                double window_s, const CameraModel& camera,
                                                const SecondChanceOptions& options,
                                                std::string* why_not);

/// Where the prior puts the board the camera saw nearest to a cloud at `stamp` (within
/// `window_s`), in the LiDAR frame; nullopt with the reason when there is none.
std::optional<ExpectedLidarBoard> expectedLidarBoard(const SecondChancePrior& prior, double stamp,
                                                     double window_s, const Target& target,
                                                     const SecondChanceOptions& options,
                                                     std::string* why_not);

/// What the second pass did, per side.
struct SecondChanceStats {
  int images_tried = 0, images_recovered = 0;
  int clouds_tried = 0, clouds_recovered = 0;
  std::map<std::string, int> images_not_recovered;  ///< reason -> count
  std::map<std::string, int> clouds_not_recovered;  ///< reason -> count
  std::string summary() const;
};

}  // namespace board_calib
