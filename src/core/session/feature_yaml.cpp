// YAML form of the board features (see feature_yaml.h).
#include <board_calib/core/session/feature_yaml.h>

#include <board_calib/core/transform.h>

#include <cmath>
#include <limits>

namespace board_calib {
namespace feature_yaml {
namespace {

void emitVec(YAML::Emitter& out, const Eigen::VectorXd& v) {
  out << YAML::Flow << YAML::BeginSeq;
  for (int i = 0; i < v.size(); ++i) out << v[i];
  out << YAML::EndSeq;
}

void emitPoints(YAML::Emitter& out, const Points3& pts) {
  // Flat [x0, y0, z0, x1, ...] keeps large point lists compact.
  out << YAML::Flow << YAML::BeginSeq;
  for (const auto& p : pts) out << p.x() << p.y() << p.z();
  out << YAML::EndSeq;
}

// Limits of a plausible feature file (hand-edited or corrupted files fail with the key).
constexpr double kUnitNormalTolerance = 0.01;  ///< |n| - 1, loose enough for hand-rounded values
constexpr double kMinQuaternionNorm = 0.5;  ///< saved quaternions are unit; 0 is no rotation at all

void requireFinite(const Eigen::VectorXd& v, const std::string& key) {
  if (!v.allFinite()) throw FeatureYamlError{"'" + key + "' holds a non-finite number"};
}

void requirePlane(const Eigen::VectorXd& plane, const std::string& key) {
  requireFinite(plane, key);
  if (std::abs(plane.head<3>().norm() - 1.0) > kUnitNormalTolerance)
    throw FeatureYamlError{
        "'" + key + "' normal is not unit (|n| = " + std::to_string(plane.head<3>().norm()) + ")"};
}

Eigen::VectorXd readVec(const YAML::Node& n, const std::string& key, int size) {
  if (!n || !n.IsSequence() || (size >= 0 && static_cast<int>(n.size()) != size))
    throw FeatureYamlError{"'" + key + "' must be a list of " + std::to_string(size) + " numbers"};
  Eigen::VectorXd v(n.size());
  for (size_t i = 0; i < n.size(); ++i) v[static_cast<int>(i)] = n[i].as<double>();
  return v;
}

Points3 readPoints(const YAML::Node& n, const std::string& key) {
  if (!n) return {};
  if (!n.IsSequence() || n.size() % 3 != 0)
    throw FeatureYamlError{"'" + key + "' must be a flat list of x y z triples"};
  Points3 pts;
  pts.reserve(n.size() / 3);
  for (size_t i = 0; i < n.size(); i += 3)
    pts.emplace_back(n[i].as<double>(), n[i + 1].as<double>(), n[i + 2].as<double>());
  for (const auto& p : pts)
    if (!p.allFinite()) throw FeatureYamlError{"'" + key + "' holds a non-finite point"};
  return pts;
}

}  // namespace

void emitLidar(YAML::Emitter& out, const LidarBoardFeatures& f) {
  out << YAML::BeginMap;
  out << YAML::Key << "frame_id" << YAML::Value << f.frame_id;
  out << YAML::Key << "stamp" << YAML::Value << f.stamp;
  out << YAML::Key << "reason" << YAML::Value << f.reason;
  out << YAML::Key << "plane" << YAML::Value;
  emitVec(out, Eigen::Vector4d(f.plane.normal.x(), f.plane.normal.y(), f.plane.normal.z(),
                               f.plane.offset));
  out << YAML::Key << "plane_rms_m" << YAML::Value << f.plane_rms_m;
  out << YAML::Key << "measured_size_m" << YAML::Value;
  emitVec(out, f.measured_size_m);
  out << YAML::Key << "board_points" << YAML::Value;
  emitPoints(out, f.board_points);
  out << YAML::Key << "edges" << YAML::Value << YAML::BeginSeq;
  for (int j = 0; j < kNumEdges; ++j) {
    out << YAML::BeginMap << YAML::Key << "valid" << YAML::Value << f.edge_valid[j];
    out << YAML::Key << "line_point" << YAML::Value;
    emitVec(out, f.edge_line_point[j]);
    out << YAML::Key << "line_direction" << YAML::Value;
    emitVec(out, f.edge_line_direction[j]);
    out << YAML::Key << "corner" << YAML::Value;
    emitVec(out, f.corners[j]);
    out << YAML::Key << "points" << YAML::Value;
    emitPoints(out, f.edge_points[j]);
    out << YAML::EndMap;
  }
  out << YAML::EndSeq << YAML::EndMap;
}

LidarBoardFeatures readLidar(const YAML::Node& n) {
  LidarBoardFeatures f;
  f.found = true;
  f.frame_id = n["frame_id"].as<std::string>("");
  f.stamp = n["stamp"].as<double>(0.0);
  f.reason = n["reason"].as<std::string>("");
  const Eigen::VectorXd plane = readVec(n["plane"], "lidar.plane", 4);
  requirePlane(plane, "lidar.plane");
  f.plane.normal = plane.head<3>();
  f.plane.offset = plane[3];
  f.plane_rms_m = n["plane_rms_m"].as<double>(0.0);
  f.measured_size_m = readVec(n["measured_size_m"], "lidar.measured_size_m", 2);
  requireFinite(f.measured_size_m, "lidar.measured_size_m");
  f.board_points = readPoints(n["board_points"], "lidar.board_points");
  const YAML::Node edges = n["edges"];
  if (!edges || !edges.IsSequence() || edges.size() != kNumEdges)
    throw FeatureYamlError{"'lidar.edges' must list 4 edges"};
  for (int j = 0; j < kNumEdges; ++j) {
    const YAML::Node e = edges[j];
    f.edge_valid[j] = e["valid"].as<bool>(false);
    f.edge_line_point[j] = readVec(e["line_point"], "lidar.edges.line_point", 3);
    f.edge_line_direction[j] = readVec(e["line_direction"], "lidar.edges.line_direction", 3);
    f.corners[j] = readVec(e["corner"], "lidar.edges.corner", 3);
    f.edge_points[j] = readPoints(e["points"], "lidar.edges.points");
  }
  return f;
}

void emitCamera(YAML::Emitter& out, const CameraBoardFeatures& f) {
  out << YAML::BeginMap;
  out << YAML::Key << "frame_id" << YAML::Value << f.frame_id;
  out << YAML::Key << "stamp" << YAML::Value << f.stamp;
  out << YAML::Key << "reason" << YAML::Value << f.reason;
  out << YAML::Key << "K" << YAML::Value;
  emitVec(out,
          Eigen::Map<const Eigen::Matrix<double, 9, 1>>(Eigen::Matrix3d(f.K.transpose()).data()));
  out << YAML::Key << "image_size" << YAML::Value << YAML::Flow << YAML::BeginSeq << f.image_width
      << f.image_height << YAML::EndSeq;
  const Eigen::Vector4d q = quaternionXyzw(f.camera_T_board);
  Eigen::Matrix<double, 7, 1> pose;
  pose << f.camera_T_board.translation(), q;
  out << YAML::Key << "camera_T_board_xyz_qxyzw" << YAML::Value;
  emitVec(out, pose);
  out << YAML::Key << "plane" << YAML::Value;
  emitVec(out, Eigen::Vector4d(f.plane.normal.x(), f.plane.normal.y(), f.plane.normal.z(),
                               f.plane.offset));
  out << YAML::Key << "reprojection_rms_px" << YAML::Value << f.reprojection_rms_px;
  out << YAML::Key << "edges" << YAML::Value << YAML::BeginSeq;
  for (int j = 0; j < kNumEdges; ++j) {
    out << YAML::BeginMap << YAML::Key << "valid" << YAML::Value << f.edge_valid[j];
    out << YAML::Key << "line" << YAML::Value;
    emitVec(out, f.edge_lines[j]);
    out << YAML::Key << "corner_px" << YAML::Value;
    emitVec(out, f.corners_px[j]);
    out << YAML::EndMap;
  }
  out << YAML::EndSeq;
  out << YAML::Key << "pattern" << YAML::Value << YAML::Flow << YAML::BeginSeq;
  for (const auto& p : f.pattern)
    out << YAML::Flow << YAML::BeginSeq << p.id << p.board_point.x() << p.board_point.y()
        << p.board_point.z() << p.pixel.x() << p.pixel.y() << YAML::EndSeq;
  out << YAML::EndSeq << YAML::EndMap;
}

CameraBoardFeatures readCamera(const YAML::Node& n) {
  CameraBoardFeatures f;
  f.found = true;
  f.frame_id = n["frame_id"].as<std::string>("");
  f.stamp = n["stamp"].as<double>(0.0);
  f.reason = n["reason"].as<std::string>("");
  const Eigen::VectorXd k = readVec(n["K"], "camera.K", 9);
  requireFinite(k, "camera.K");
  if (!(k[0] > 0) || !(k[4] > 0)) throw FeatureYamlError{"'camera.K' focal lengths must be > 0"};
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) f.K(r, c) = k[r * 3 + c];
  const Eigen::VectorXd size = readVec(n["image_size"], "camera.image_size", 2);
  for (int i = 0; i < 2; ++i)
    if (!(size[i] >= 1 && size[i] <= kMaxFeatureImageSidePx) || size[i] != std::floor(size[i]))
      throw FeatureYamlError{"'camera.image_size' must be two whole numbers in 1.." +
                             std::to_string(kMaxFeatureImageSidePx) + ", got [" +
                             std::to_string(size[0]) + ", " + std::to_string(size[1]) + "]"};
  f.image_width = static_cast<int>(size[0]);
  f.image_height = static_cast<int>(size[1]);
  const Eigen::VectorXd pose =
      readVec(n["camera_T_board_xyz_qxyzw"], "camera.camera_T_board_xyz_qxyzw", 7);
  requireFinite(pose, "camera.camera_T_board_xyz_qxyzw");
  if (pose.tail<4>().norm() < kMinQuaternionNorm)
    throw FeatureYamlError{"'camera.camera_T_board_xyz_qxyzw' quaternion is not a rotation"};
  f.camera_T_board =
      makeTransform(Eigen::Vector3d(pose.head<3>()), Eigen::Vector4d(pose.tail<4>()));
  const Eigen::VectorXd plane = readVec(n["plane"], "camera.plane", 4);
  requirePlane(plane, "camera.plane");
  f.plane.normal = plane.head<3>();
  f.plane.offset = plane[3];
  f.reprojection_rms_px = n["reprojection_rms_px"].as<double>(0.0);
  const YAML::Node edges = n["edges"];
  if (!edges || !edges.IsSequence() || edges.size() != kNumEdges)
    throw FeatureYamlError{"'camera.edges' must list 4 edges"};
  for (int j = 0; j < kNumEdges; ++j) {
    f.edge_valid[j] = edges[j]["valid"].as<bool>(false);
    f.edge_lines[j] = readVec(edges[j]["line"], "camera.edges.line", 3);
    f.corners_px[j] = readVec(edges[j]["corner_px"], "camera.edges.corner_px", 2);
  }
  if (const YAML::Node pattern = n["pattern"]) {
    for (const auto& p : pattern) {
      const Eigen::VectorXd v = readVec(p, "camera.pattern[]", 6);
      requireFinite(v, "camera.pattern[]");
      if (std::abs(v[0]) > std::numeric_limits<int>::max())
        throw FeatureYamlError{"'camera.pattern[]' id out of range"};
      f.pattern.push_back({static_cast<int>(v[0]), v.segment<3>(1), v.segment<2>(4)});
    }
  }
  return f;
}

}  // namespace feature_yaml
}  // namespace board_calib
