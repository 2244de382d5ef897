#include <board_calib/core/file_io.h>
#include <board_calib/core/target.h>

#include <yaml-cpp/yaml.h>

#include <cmath>
#include <cstdint>
#include <set>
#include <sstream>

namespace board_calib {
namespace {

// A parse error that already names the key; converted to Expected at the API boundary.
struct TargetError {
  std::string message;
};

// Limits far beyond any real board; they keep sizes finite and counts inside int.
constexpr double kMaxBoardSideM = 10.0;
constexpr int64_t kMaxPatternCorners = 10000;  ///< rows * cols of a checkerboard

void rejectUnknownKeys(const YAML::Node& node, const std::set<std::string>& allowed,
                       const std::string& where) {
  std::set<std::string> seen;
  for (const auto& kv : node) {
    if (!kv.first.IsScalar()) throw TargetError{"a key under '" + where + "' is not a plain name"};
    const std::string key = kv.first.as<std::string>();
    // yaml-cpp keeps the first of two equal keys silently; the user meant one of them.
    if (!seen.insert(key).second) throw TargetError{"duplicate key '" + where + key + "'"};
    if (!allowed.count(key)) {
      std::string list;
      for (const auto& a : allowed) list += (list.empty() ? "" : ", ") + a;
      throw TargetError{"unknown key '" + where + key + "' (allowed: " + list + ")"};
    }
  }
}

template <typename T>
T readScalar(const YAML::Node& node, const std::string& key, const std::string& where,
             const char* type_name) {
  const YAML::Node value = node[key];
  if (!value) throw TargetError{"missing key '" + where + key + "'"};
  if (!value.IsScalar()) throw TargetError{"key '" + where + key + "' must be a " + type_name};
  try {
    return value.as<T>();
  } catch (const YAML::Exception&) {
    throw TargetError{"key '" + where + key + "' must be a " + type_name + ", got '" +
                      value.Scalar() + "'"};
  }
}

double readFinite(const YAML::Node& node, const std::string& key, const std::string& where) {
  const double v = readScalar<double>(node, key, where, "number");
  if (!std::isfinite(v))
    throw TargetError{"key '" + where + key + "' must be finite, got " + node[key].Scalar()};
  return v;
}

double readPositive(const YAML::Node& node, const std::string& key, const std::string& where) {
  const double v = readFinite(node, key, where);
  if (!(v > 0.0))
    throw TargetError{"key '" + where + key + "' must be > 0, got " + std::to_string(v)};
  if (v > kMaxBoardSideM)
    throw TargetError{"key '" + where + key + "' = " + std::to_string(v) +
                      " m is larger than any board (" + std::to_string(kMaxBoardSideM) + " m)"};
  return v;
}

int readPositiveInt(const YAML::Node& node, const std::string& key, const std::string& where) {
  const int v = readScalar<int>(node, key, where, "integer");
  if (v <= 0)
    throw TargetError{"key '" + where + key + "' must be a positive integer, got " +
                      std::to_string(v)};
  return v;
}

Eigen::Vector2d readVec2(const YAML::Node& node, const std::string& key, const std::string& where) {
  const YAML::Node value = node[key];
  if (!value) throw TargetError{"missing key '" + where + key + "'"};
  if (!value.IsSequence() || value.size() != 2)
    throw TargetError{"key '" + where + key + "' must be a list of two numbers [x, y] in metres"};
  try {
    const Eigen::Vector2d v(value[0].as<double>(), value[1].as<double>());
    if (!v.allFinite()) throw TargetError{"key '" + where + key + "' must hold finite numbers"};
    return v;
  } catch (const YAML::Exception&) {
    throw TargetError{"key '" + where + key + "' must be a list of two numbers [x, y] in metres"};
  }
}

Target parseNode(const YAML::Node& root) {
  if (!root.IsMap()) throw TargetError{"target description must be a YAML mapping"};
  rejectUnknownKeys(root, {"type", "width", "height", "checkerboard", "apriltag_grid"}, "");
  Target t;
  const std::string type = readScalar<std::string>(root, "type", "", "string");
  if (type == "plain")
    t.type = TargetType::kPlain;
  else if (type == "checkerboard")
    t.type = TargetType::kCheckerboard;
  else if (type == "apriltag_grid")
    t.type = TargetType::kAprilTagGrid;
  else
    throw TargetError{"key 'type' must be plain, checkerboard or apriltag_grid, got '" + type +
                      "'"};
  t.width = readPositive(root, "width", "");
  t.height = readPositive(root, "height", "");

  // Only the block matching the type is required; a present block is still checked.
  if (t.type == TargetType::kCheckerboard || root["checkerboard"]) {
    const YAML::Node cb = root["checkerboard"];
    if (!cb) throw TargetError{"missing key 'checkerboard' (required for type checkerboard)"};
    if (!cb.IsMap()) throw TargetError{"key 'checkerboard' must be a mapping"};
    const std::string w = "checkerboard.";
    rejectUnknownKeys(cb, {"cols", "rows", "square", "origin"}, w);
    t.checkerboard.cols = readPositiveInt(cb, "cols", w);
    t.checkerboard.rows = readPositiveInt(cb, "rows", w);
    t.checkerboard.square = readPositive(cb, "square", w);
    t.checkerboard.origin = readVec2(cb, "origin", w);
  }
  if (t.type == TargetType::kAprilTagGrid || root["apriltag_grid"]) {
    const YAML::Node ag = root["apriltag_grid"];
    if (!ag) throw TargetError{"missing key 'apriltag_grid' (required for type apriltag_grid)"};
    if (!ag.IsMap()) throw TargetError{"key 'apriltag_grid' must be a mapping"};
    const std::string w = "apriltag_grid.";
    rejectUnknownKeys(ag, {"family", "cols", "rows", "tag_size", "spacing", "first_id", "origin"},
                      w);
    t.apriltag_grid.family = readScalar<std::string>(ag, "family", w, "string");
    t.apriltag_grid.cols = readPositiveInt(ag, "cols", w);
    t.apriltag_grid.rows = readPositiveInt(ag, "rows", w);
    t.apriltag_grid.tag_size = readPositive(ag, "tag_size", w);
    t.apriltag_grid.spacing = readFinite(ag, "spacing", w);
    if (t.apriltag_grid.spacing < 0) throw TargetError{"key 'apriltag_grid.spacing' must be >= 0"};
    t.apriltag_grid.first_id = readScalar<int>(ag, "first_id", w, "integer");
    if (t.apriltag_grid.first_id < 0)
      throw TargetError{"key 'apriltag_grid.first_id' must be >= 0"};
    t.apriltag_grid.origin = readVec2(ag, "origin", w);
  }
  const std::string why = t.validate();
  if (!why.empty()) throw TargetError{why};
  return t;
}

}  // namespace

const char* targetTypeName(TargetType type) {
  switch (type) {
    case TargetType::kPlain: return "plain";
    case TargetType::kCheckerboard: return "checkerboard";
    case TargetType::kAprilTagGrid: return "apriltag_grid";
  }
  return "unknown";
}

const char* edgeName(int edge) {
  static const char* kNames[] = {"UL", "UR", "LR", "LL"};
  return (edge >= 0 && edge < kNumEdges) ? kNames[edge] : "??";
}

std::array<Eigen::Vector3d, 4> Target::outerCorners() const {
  return {Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(width, 0, 0), Eigen::Vector3d(width, height, 0),
          Eigen::Vector3d(0, height, 0)};
}

Points3 Target::checkerboardCorners() const {
  Points3 out;
  if (type != TargetType::kCheckerboard) return out;
  const auto& cb = checkerboard;
  for (int r = 0; r < cb.rows; ++r)
    for (int c = 0; c < cb.cols; ++c)
      out.emplace_back(cb.origin.x() + c * cb.square, cb.origin.y() + r * cb.square, 0.0);
  return out;
}

std::vector<TagCorners> Target::aprilTagCorners() const {
  std::vector<TagCorners> out;
  if (type != TargetType::kAprilTagGrid) return out;
  const auto& g = apriltag_grid;
  const double pitch = g.tag_size + g.spacing;
  for (int r = 0; r < g.rows; ++r) {
    for (int c = 0; c < g.cols; ++c) {
      const double x0 = g.origin.x() + c * pitch;
      const double y0 = g.origin.y() + r * pitch;
      const double s = g.tag_size;
      TagCorners tag;
      tag.id = g.first_id + r * g.cols + c;
      tag.corners = {Eigen::Vector3d(x0, y0 + s, 0), Eigen::Vector3d(x0 + s, y0 + s, 0),
                     Eigen::Vector3d(x0 + s, y0, 0), Eigen::Vector3d(x0, y0, 0)};
      out.push_back(tag);
    }
  }
  return out;
}

std::string Target::validate() const {
  constexpr double kTolerance = 1e-9;  // m, rounding slack when a pattern touches the edge
  if (!(width > 0) || !(height > 0)) return "board width and height must be > 0";
  if (type == TargetType::kCheckerboard) {
    const auto& cb = checkerboard;
    if (cb.cols < 2 || cb.rows < 2)
      return "checkerboard.cols and checkerboard.rows must be >= 2 (inner corners)";
    if (int64_t(cb.cols) * cb.rows > kMaxPatternCorners)
      return "checkerboard has " + std::to_string(int64_t(cb.cols) * cb.rows) +
             " inner corners (at most " + std::to_string(kMaxPatternCorners) + ")";
    if (cb.cols == cb.rows)
      return "checkerboard.cols equals checkerboard.rows: a square pattern is ambiguous under 90° "
             "rotation";
    // The printed squares extend one square beyond the outermost inner corners.
    const double x_min = cb.origin.x() - cb.square, y_min = cb.origin.y() - cb.square;
    const double x_max = cb.origin.x() + cb.cols * cb.square;
    const double y_max = cb.origin.y() + cb.rows * cb.square;
    if (x_min < -kTolerance || y_min < -kTolerance || x_max > width + kTolerance ||
        y_max > height + kTolerance) {
      std::ostringstream s;
      s << "checkerboard pattern (" << (cb.cols + 1) * cb.square << " x "
        << (cb.rows + 1) * cb.square << " m at origin " << cb.origin.x() << ", " << cb.origin.y()
        << ") does not fit on the board (" << width << " x " << height << " m)";
      return s.str();
    }
  }
  if (type == TargetType::kAprilTagGrid) {
    const auto& g = apriltag_grid;
    if (g.family != "tag36h11")
      return "apriltag_grid.family '" + g.family + "' is not supported (supported: tag36h11)";
    const double x_max = g.origin.x() + g.cols * g.tag_size + (g.cols - 1) * g.spacing;
    const double y_max = g.origin.y() + g.rows * g.tag_size + (g.rows - 1) * g.spacing;
    if (g.origin.x() < -kTolerance || g.origin.y() < -kTolerance || x_max > width + kTolerance ||
        y_max > height + kTolerance) {
      std::ostringstream s;
      s << "apriltag_grid (" << x_max - g.origin.x() << " x " << y_max - g.origin.y()
        << " m) does not fit on the board (" << width << " x " << height << " m)";
      return s.str();
    }
    constexpr int kTag36h11Count = 587;
    // 64-bit: rows * cols of a hostile file overflows int (65536 x 65536 used to end in bad_alloc).
    if (g.rows <= 0 || g.cols <= 0 || g.first_id < 0 ||
        int64_t(g.first_id) + int64_t(g.rows) * g.cols > kTag36h11Count)
      return "apriltag_grid ids " + std::to_string(g.first_id) + " + " + std::to_string(g.rows) +
             " x " + std::to_string(g.cols) + " exceed the tag36h11 family (587 tags)";
  }
  return {};
}

Expected<Target> parseTarget(const std::string& yaml_text) {
  try {
    return parseNode(YAML::Load(yaml_text));
  } catch (const TargetError& e) {
    return Expected<Target>::failure(e.message);
  } catch (const YAML::Exception& e) {
    return Expected<Target>::failure(std::string("invalid YAML: ") + e.what());
  } catch (const std::exception& e) {  // e.g. bad_alloc from a hostile document
    return Expected<Target>::failure(std::string("cannot parse the target: ") + e.what());
  }
}

Expected<Target> loadTarget(const std::string& path) {
  const auto text = readTextFile(path, "target file");
  if (!text) return Expected<Target>::failure(text.error());
  auto parsed = parseTarget(*text);
  if (!parsed) return Expected<Target>::failure("target file '" + path + "': " + parsed.error());
  return parsed;
}

std::string targetToYaml(const Target& t) {
  std::ostringstream s;
  s.precision(10);
  s << "type: " << targetTypeName(t.type) << "\nwidth: " << t.width << "\nheight: " << t.height
    << "\n";
  if (t.type == TargetType::kCheckerboard) {
    const auto& cb = t.checkerboard;
    s << "checkerboard: {cols: " << cb.cols << ", rows: " << cb.rows << ", square: " << cb.square
      << ", origin: [" << cb.origin.x() << ", " << cb.origin.y() << "]}\n";
  }
  if (t.type == TargetType::kAprilTagGrid) {
    const auto& g = t.apriltag_grid;
    s << "apriltag_grid: {family: " << g.family << ", cols: " << g.cols << ", rows: " << g.rows
      << ", tag_size: " << g.tag_size << ", spacing: " << g.spacing << ", first_id: " << g.first_id
      << ", origin: [" << g.origin.x() << ", " << g.origin.y() << "]}\n";
  }
  return s.str();
}

}  // namespace board_calib
