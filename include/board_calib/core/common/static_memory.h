// Session memory of board-like places (issue 14, 3a): the board is what moves between views;
// what a detector finds at one place over a long stretch of the session is the static scene
// (door, poster, window, screen). One timing rule for both sensors: the LiDAR tracker's places are
// planes (centroid and normal), the camera tracker's are quadrilaterals (corners in px).
#pragma once

#include <string>

namespace board_calib {

struct StaticMemoryOptions {
  bool enabled = true;  ///< used by the pair pipeline and the detector nodelets (`~session_memory`)
  double place_radius_m = 0.3;  ///< LiDAR: candidates whose centroids are this close (and normals
                                ///< agree) are one place, m
  double max_normal_angle_deg = 10.0;  ///< LiDAR: deg
  double static_after_s =
      6.0;  ///< seen at one place over this long: background (a held pose lasts a few s), s
  double min_seen_fraction =
      0.5;  ///< ... and in at least this fraction of the frames since (not a board revisiting)
  double forget_after_s = 30.0;  ///< a place unseen this long is forgotten, s
  /// LiDAR: two board-like places not known as static: ambiguous whatever their support. Off by
  /// default: real rooms keep a second board-like plane that is not static in every cloud (0 of
  /// 16 clouds of basler_os1_plain found with it); on for a cluttered room where a wrong board
  /// during the first static_after_s is worse than a lost one.
  bool strict_ambiguity = false;
  std::string validate() const;
};

/// When and how often one place was seen (its geometry is the tracker's).
struct PlaceSightings {
  double first_s = 0.0, last_s = 0.0;  ///< s, stamps of the first and last frame seen there
  long first_frame = 0, last_frame = 0;
  int seen = 0;  ///< frames that saw it

  static PlaceSightings start(double stamp, long frame);
  /// One more frame saw the place; false (nothing counted) when this frame already did.
  bool see(double stamp, long frame);
  /// Seen over static_after_s and in min_seen_fraction of the frames since its first (`frame`:
  /// the current frame's number).
  bool isStatic(const StaticMemoryOptions& o, long frame) const;
  bool forgotten(const StaticMemoryOptions& o, double stamp) const {
    return stamp - last_s > o.forget_after_s;
  }
};

}  // namespace board_calib
