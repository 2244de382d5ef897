// Calibration target (board) description: parsed from a target YAML (config/targets/) and
// turned into geometry in the board frame (origin at the top-left outer corner, x right along
// the width, y down along the height, z = x × y into the board).
#pragma once

#include <board_calib/core/types.h>

#include <string>
#include <vector>

namespace board_calib {

enum class TargetType { kPlain, kCheckerboard, kAprilTagGrid };
const char* targetTypeName(TargetType type);

struct CheckerboardPattern {
  int cols = 0;         ///< inner corners along board x
  int rows = 0;         ///< inner corners along board y
  double square = 0.0;  ///< m
  Eigen::Vector2d origin =
      Eigen::Vector2d::Zero();  ///< first inner corner from the top-left outer corner, m
};

struct AprilTagGridPattern {
  std::string family = "tag36h11";
  int cols = 0;
  int rows = 0;
  double tag_size = 0.0;                             ///< outer black edge length, m
  double spacing = 0.0;                              ///< gap between neighbouring tags, m
  int first_id = 0;                                  ///< id of the top-left tag; ids run row-major
  Eigen::Vector2d origin = Eigen::Vector2d::Zero();  ///< top-left corner of the top-left tag, m
};

/// Corners of one tag in the board frame, in libapriltag's order as seen upright:
/// 0 bottom-left, 1 bottom-right, 2 top-right, 3 top-left (board y points down).
struct TagCorners {
  int id = 0;
  std::array<Eigen::Vector3d, 4> corners;
};

struct Target {
  TargetType type = TargetType::kPlain;
  double width = 0.0;   ///< m, along board x
  double height = 0.0;  ///< m, along board y
  CheckerboardPattern checkerboard;
  AprilTagGridPattern apriltag_grid;

  /// Outer corners, clockwise as printed: top-left, top-right, bottom-right, bottom-left (z = 0).
  std::array<Eigen::Vector3d, 4> outerCorners() const;
  Eigen::Vector3d center() const { return {width / 2, height / 2, 0.0}; }
  /// Checkerboard inner corners, row-major (x fastest), as OpenCV's findChessboardCorners
  /// orders them for a (cols, rows) pattern seen upright. Empty for other types.
  Points3 checkerboardCorners() const;
  /// Every tag of the grid with its id and corners. Empty for other types.
  std::vector<TagCorners> aprilTagCorners() const;
  /// Reason the description is inconsistent, empty when it is valid.
  std::string validate() const;
};

/// Parse a target description from YAML text. Errors name the offending key.
Expected<Target> parseTarget(const std::string& yaml_text);
/// Load and parse a target file. Errors name the file and the offending key.
Expected<Target> loadTarget(const std::string& path);
/// Serialise a target back to the contract YAML.
std::string targetToYaml(const Target& target);

}  // namespace board_calib
