#include <board_calib/conversions.h>

#include "conversion_internal.h"

#include <sensor_msgs/point_cloud2_iterator.h>

#include <algorithm>
#include <cmath>
#include <cstring>

namespace board_calib {
using namespace conversion_internal;  // NOLINT: the limits read as plain names here
namespace {

const sensor_msgs::PointField* findField(const sensor_msgs::PointCloud2& msg,
                                         const std::string& name) {
  for (const auto& f : msg.fields)
    if (f.name == name) return &f;
  return nullptr;
}

size_t fieldSize(uint8_t datatype) {
  switch (datatype) {
    case sensor_msgs::PointField::INT8:
    case sensor_msgs::PointField::UINT8: return 1;
    case sensor_msgs::PointField::INT16:
    case sensor_msgs::PointField::UINT16: return 2;
    case sensor_msgs::PointField::INT32:
    case sensor_msgs::PointField::UINT32:
    case sensor_msgs::PointField::FLOAT32: return 4;
    case sensor_msgs::PointField::FLOAT64: return 8;
  }
  return 0;
}

// Reads one numeric field of any PointField datatype as double; `swap` reverses the bytes
// (message endianness differs from the host's).
double readAs(const uint8_t* p, uint8_t datatype, bool swap) {
  uint8_t bytes[8];
  const size_t n = fieldSize(datatype);
  std::memcpy(bytes, p, n);
  if (swap) std::reverse(bytes, bytes + n);
  switch (datatype) {
    case sensor_msgs::PointField::INT8: {
      int8_t v;
      std::memcpy(&v, bytes, 1);
      return v;
    }
    case sensor_msgs::PointField::UINT8: return bytes[0];
    case sensor_msgs::PointField::INT16: {
      int16_t v;
      std::memcpy(&v, bytes, 2);
      return v;
    }
    case sensor_msgs::PointField::UINT16: {
      uint16_t v;
      std::memcpy(&v, bytes, 2);
      return v;
    }
    case sensor_msgs::PointField::INT32: {
      int32_t v;
      std::memcpy(&v, bytes, 4);
      return v;
    }
    case sensor_msgs::PointField::UINT32: {
      uint32_t v;
      std::memcpy(&v, bytes, 4);
      return v;
    }
    case sensor_msgs::PointField::FLOAT32: {
      float v;
      std::memcpy(&v, bytes, 4);
      return v;
    }
    case sensor_msgs::PointField::FLOAT64: {
      double v;
      std::memcpy(&v, bytes, 8);
      return v;
    }
  }
  return 0.0;
}

// A ring index stored as a float or a huge integer must not overflow the int cast (UB).
int toRing(double value) {
  if (!std::isfinite(value) || value < 0 || value > kMaxRingIndex) return -1;
  return static_cast<int>(value);
}

geometry_msgs::Point32 toPoint32(const Eigen::Vector3d& p) {
  geometry_msgs::Point32 q;
  q.x = static_cast<float>(p.x());
  q.y = static_cast<float>(p.y());
  q.z = static_cast<float>(p.z());
  return q;
}

geometry_msgs::Vector3 toVector3(const Eigen::Vector3d& p) {
  geometry_msgs::Vector3 q;
  q.x = p.x();
  q.y = p.y();
  q.z = p.z();
  return q;
}

template <typename P>
Eigen::Vector3d toEigen(const P& p) {
  return {p.x, p.y, p.z};
}

}  // namespace

geometry_msgs::Point toPointMsg(const Eigen::Vector3d& p) {
  geometry_msgs::Point q;
  q.x = p.x();
  q.y = p.y();
  q.z = p.z();
  return q;
}

bool sameCameraInfo(const sensor_msgs::CameraInfo& a, const sensor_msgs::CameraInfo& b) {
  return a.width == b.width && a.height == b.height && a.K == b.K && a.D == b.D &&
         a.distortion_model == b.distortion_model;
}

std::string validateCameraInfo(const sensor_msgs::CameraInfo& info) {
  const uint64_t width = info.width, height = info.height;
  if (width == 0 || height == 0 || width > kMaxImageSidePx || height > kMaxImageSidePx)
    return "camera_info size " + std::to_string(width) + " x " + std::to_string(height) +
           " is not in 1.." + std::to_string(kMaxImageSidePx) + " px";
  for (size_t i = 0; i < info.K.size(); ++i)
    if (!std::isfinite(info.K[i])) return "camera_info K[" + std::to_string(i) + "] is not finite";
  if (!(info.K[0] > 0) || !(info.K[4] > 0))
    return "camera_info focal lengths K[0]=" + std::to_string(info.K[0]) +
           " K[4]=" + std::to_string(info.K[4]) + " are not positive (uncalibrated camera?)";
  if (info.D.size() > kMaxDistortionCoeffs)
    return "camera_info D has " + std::to_string(info.D.size()) + " coefficients (at most " +
           std::to_string(kMaxDistortionCoeffs) + ")";
  for (size_t i = 0; i < info.D.size(); ++i)
    if (!std::isfinite(info.D[i])) return "camera_info D[" + std::to_string(i) + "] is not finite";
  return {};
}

Expected<CameraIntrinsics> fromCameraInfo(const sensor_msgs::CameraInfo& info) {
  if (const std::string why = validateCameraInfo(info); !why.empty())
    return Expected<CameraIntrinsics>::failure(why);
  CameraIntrinsics in;
  in.width = static_cast<int>(info.width);
  in.height = static_cast<int>(info.height);
  in.fx = info.K[0];
  in.fy = info.K[4];
  in.cx = info.K[2];
  in.cy = info.K[5];
  auto model = parseDistortionModel(info.distortion_model);
  if (!model) {
    // An empty model with all-zero D is a common "no distortion" CameraInfo.
    return Expected<CameraIntrinsics>::failure(model.error());
  }
  in.model = *model;
  in.coeffs = info.D;
  // Trailing zeros beyond the model's count are harmless (some drivers pad D).
  const size_t max_coeffs = in.model == DistortionModel::kPlumbBob      ? 5
                            : in.model == DistortionModel::kEquidistant ? 4
                                                                        : 8;
  while (in.coeffs.size() > max_coeffs && in.coeffs.back() == 0.0) in.coeffs.pop_back();
  return in;
}

sensor_msgs::CameraInfo toCameraInfo(const CameraIntrinsics& in) {
  sensor_msgs::CameraInfo info;
  info.width = static_cast<uint32_t>(in.width);
  info.height = static_cast<uint32_t>(in.height);
  info.distortion_model =
      in.model == DistortionModel::kNone ? "plumb_bob" : distortionModelName(in.model);
  info.D = in.coeffs;
  if (in.model == DistortionModel::kNone) info.D.assign(5, 0.0);
  info.K = {in.fx, 0, in.cx, 0, in.fy, in.cy, 0, 0, 1};
  info.R = {1, 0, 0, 0, 1, 0, 0, 0, 1};
  info.P = {in.fx, 0, in.cx, 0, 0, in.fy, in.cy, 0, 0, 0, 1, 0};
  return info;
}

std::string validatePointCloud2(const sensor_msgs::PointCloud2& msg) {
  const auto* fx = findField(msg, "x");
  const auto* fy = findField(msg, "y");
  const auto* fz = findField(msg, "z");
  if (!fx || !fy || !fz) return "cloud has no x/y/z fields";
  for (const auto* f : {fx, fy, fz})
    if (f->datatype != sensor_msgs::PointField::FLOAT32 &&
        f->datatype != sensor_msgs::PointField::FLOAT64)
      return "cloud field '" + f->name + "' is not float32/float64 (datatype " +
             std::to_string(f->datatype) + ")";
  // 64-bit arithmetic throughout: every product of two uint32 fits.
  const uint64_t width = msg.width, height = msg.height, point_step = msg.point_step,
                 row_step = msg.row_step;
  const uint64_t points = width * height;
  if (points == 0) return {};  // an empty cloud is valid; nothing is read
  if (point_step == 0) return "cloud point_step is 0";
  for (const auto* f : {fx, fy, fz, findField(msg, "intensity"), findField(msg, "ring")}) {
    if (!f) continue;
    const uint64_t size = fieldSize(f->datatype);
    if (size == 0)
      return "cloud field '" + f->name + "' has unknown datatype " + std::to_string(f->datatype);
    const uint64_t count = std::max<uint64_t>(1, f->count);
    if (uint64_t(f->offset) + count * size > point_step)
      return "cloud field '" + f->name + "' (offset " + std::to_string(f->offset) + ", " +
             std::to_string(count) + "x" + std::to_string(size) +
             " bytes) lies outside point_step " + std::to_string(point_step);
  }
  if (points > kMaxCloudPoints)
    return "cloud has " + std::to_string(points) + " points (" + std::to_string(width) + "x" +
           std::to_string(height) + "), more than the " + std::to_string(kMaxCloudPoints) +
           " accepted";
  if (row_step < width * point_step)
    return "cloud row_step " + std::to_string(row_step) +
           " is smaller than width*point_step = " + std::to_string(width) + "*" +
           std::to_string(point_step);
  if (uint64_t(msg.data.size()) < height * row_step)
    return "cloud data holds " + std::to_string(msg.data.size()) +
           " bytes, height*row_step needs " + std::to_string(height * row_step);
  return {};
}

Expected<LidarCloud> fromPointCloud2(const sensor_msgs::PointCloud2& msg) {
  if (const std::string why = validatePointCloud2(msg); !why.empty())
    return Expected<LidarCloud>::failure(why);
  const auto* fx = findField(msg, "x");
  const auto* fy = findField(msg, "y");
  const auto* fz = findField(msg, "z");
  const auto* fi = findField(msg, "intensity");
  const auto* fr = findField(msg, "ring");
  const bool swap = bool(msg.is_bigendian) != hostIsBigEndian();
  const size_t n = size_t(msg.width) * msg.height;
  LidarCloud cloud;
  cloud.frame_id = msg.header.frame_id;
  cloud.stamp = msg.header.stamp.toSec();
  cloud.width = static_cast<int>(msg.width);
  cloud.height = static_cast<int>(msg.height);
  cloud.has_intensity = fi != nullptr;
  cloud.has_ring = fr != nullptr;
  cloud.points.resize(n);
  for (size_t r = 0; r < msg.height; ++r) {
    for (size_t c = 0; c < msg.width; ++c) {
      const uint8_t* p = msg.data.data() + r * msg.row_step + c * msg.point_step;
      LidarPoint& q = cloud.points[r * msg.width + c];
      q.x = static_cast<float>(readAs(p + fx->offset, fx->datatype, swap));
      q.y = static_cast<float>(readAs(p + fy->offset, fy->datatype, swap));
      q.z = static_cast<float>(readAs(p + fz->offset, fz->datatype, swap));
      if (fi) q.intensity = static_cast<float>(readAs(p + fi->offset, fi->datatype, swap));
      if (fr) q.ring = toRing(readAs(p + fr->offset, fr->datatype, swap));
    }
  }
  return cloud;
}

sensor_msgs::PointCloud2 toPointCloud2(const LidarCloud& cloud) {
  sensor_msgs::PointCloud2 msg;
  msg.header.frame_id = cloud.frame_id;
  msg.header.stamp = ros::Time(std::max(0.0, cloud.stamp));
  msg.height = static_cast<uint32_t>(std::max(1, cloud.height));
  msg.width = static_cast<uint32_t>(cloud.points.size() / msg.height);
  sensor_msgs::PointCloud2Modifier mod(msg);
  if (cloud.has_ring) {
    mod.setPointCloud2Fields(
        5, "x", 1, sensor_msgs::PointField::FLOAT32, "y", 1, sensor_msgs::PointField::FLOAT32, "z",
        1, sensor_msgs::PointField::FLOAT32, "intensity", 1, sensor_msgs::PointField::FLOAT32,
        "ring", 1, sensor_msgs::PointField::UINT16);
    // Pad 18 to 20 bytes: every float of every point stays 4-byte aligned (the iterators bind
    // float references; an 18-byte step misaligns them, undefined behaviour found by UBSan).
    constexpr uint32_t kAlignedRingPointStep = 20;
    msg.point_step = kAlignedRingPointStep;
  } else {
    mod.setPointCloud2Fields(
        4, "x", 1, sensor_msgs::PointField::FLOAT32, "y", 1, sensor_msgs::PointField::FLOAT32, "z",
        1, sensor_msgs::PointField::FLOAT32, "intensity", 1, sensor_msgs::PointField::FLOAT32);
  }
  mod.resize(msg.width * msg.height);  // resize() flattens to height 1; restore the layout
  msg.height = static_cast<uint32_t>(std::max(1, cloud.height));
  msg.width = static_cast<uint32_t>(cloud.points.size() / msg.height);
  msg.row_step = msg.width * msg.point_step;
  msg.is_dense = false;
  sensor_msgs::PointCloud2Iterator<float> ix(msg, "x"), iy(msg, "y"), iz(msg, "z"),
      ii(msg, "intensity");
  for (const auto& p : cloud.points) {
    *ix = p.x;
    *iy = p.y;
    *iz = p.z;
    *ii = p.intensity;
    ++ix;
    ++iy;
    ++iz;
    ++ii;
  }
  if (cloud.has_ring) {
    sensor_msgs::PointCloud2Iterator<uint16_t> ir(msg, "ring");
    for (const auto& p : cloud.points) {
      *ir = static_cast<uint16_t>(std::max(0, p.ring));
      ++ir;
    }
  }
  return msg;
}

sensor_msgs::PointCloud2 toPointCloud2(const ColoredCloud& cloud) {
  sensor_msgs::PointCloud2 msg;
  msg.header.frame_id = cloud.frame_id;
  msg.header.stamp = ros::Time(std::max(0.0, cloud.stamp));
  sensor_msgs::PointCloud2Modifier mod(msg);
  mod.setPointCloud2Fields(
      5, "x", 1, sensor_msgs::PointField::FLOAT32, "y", 1, sensor_msgs::PointField::FLOAT32, "z", 1,
      sensor_msgs::PointField::FLOAT32, "intensity", 1, sensor_msgs::PointField::FLOAT32, "rgb", 1,
      sensor_msgs::PointField::FLOAT32);
  mod.resize(cloud.points.size());
  msg.is_dense = true;  // only projected (finite) points are kept
  sensor_msgs::PointCloud2Iterator<float> ix(msg, "x"), iy(msg, "y"), iz(msg, "z"),
      ii(msg, "intensity"), irgb(msg, "rgb");
  for (const auto& p : cloud.points) {
    *ix = p.x;
    *iy = p.y;
    *iz = p.z;
    *ii = p.intensity;
    const uint32_t packed = (uint32_t(p.r) << 16) | (uint32_t(p.g) << 8) | uint32_t(p.b);
    std::memcpy(&*irgb, &packed, sizeof(packed));
    ++ix;
    ++iy;
    ++iz;
    ++ii;
    ++irgb;
  }
  return msg;
}

LidarBoard toMsg(const LidarBoardFeatures& f) {
  LidarBoard m;
  m.header.frame_id = f.frame_id;
  m.header.stamp = ros::Time(std::max(0.0, f.stamp));
  m.found = f.found;
  m.reason = f.reason;
  m.plane_normal = toVector3(f.plane.normal);
  m.plane_offset = f.plane.offset;
  m.plane_rms = f.plane_rms_m;
  m.board_points.reserve(f.board_points.size());
  for (const auto& p : f.board_points) m.board_points.push_back(toPoint32(p));
  for (int j = 0; j < kNumEdges; ++j) {
    auto& e = m.edges[j];
    e.valid = f.edge_valid[j];
    for (const auto& p : f.edge_points[j]) e.points.push_back(toPoint32(p));
    e.line_point = toPointMsg(f.edge_line_point[j]);
    e.line_direction = toVector3(f.edge_line_direction[j]);
    m.corners[j] = toPointMsg(f.corners[j]);
  }
  m.measured_size[0] = f.measured_size_m.x();
  m.measured_size[1] = f.measured_size_m.y();
  return m;
}

LidarBoardFeatures fromMsg(const LidarBoard& m) {
  LidarBoardFeatures f;
  f.frame_id = m.header.frame_id;
  f.stamp = m.header.stamp.toSec();
  f.found = m.found;
  f.reason = m.reason;
  f.plane.normal = toEigen(m.plane_normal);
  f.plane.offset = m.plane_offset;
  f.plane_rms_m = m.plane_rms;
  f.board_points.reserve(m.board_points.size());
  for (const auto& p : m.board_points) f.board_points.push_back(toEigen(p));
  for (int j = 0; j < kNumEdges; ++j) {
    const auto& e = m.edges[j];
    f.edge_valid[j] = e.valid;
    for (const auto& p : e.points) f.edge_points[j].push_back(toEigen(p));
    f.edge_line_point[j] = toEigen(e.line_point);
    f.edge_line_direction[j] = toEigen(e.line_direction);
    f.corners[j] = toEigen(m.corners[j]);
  }
  f.measured_size_m = {m.measured_size[0], m.measured_size[1]};
  return f;
}

CameraBoard toMsg(const CameraBoardFeatures& f) {
  CameraBoard m;
  m.header.frame_id = f.frame_id;
  m.header.stamp = ros::Time(std::max(0.0, f.stamp));
  m.found = f.found;
  m.reason = f.reason;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) m.K[r * 3 + c] = f.K(r, c);
  m.image_width = static_cast<uint32_t>(f.image_width);
  m.image_height = static_cast<uint32_t>(f.image_height);
  m.camera_pose_board = toPoseMsg(f.camera_T_board);
  m.plane_normal = toVector3(f.plane.normal);
  m.plane_offset = f.plane.offset;
  for (int j = 0; j < kNumEdges; ++j) {
    m.edges[j].valid = f.edge_valid[j];
    m.edges[j].a = f.edge_lines[j].x();
    m.edges[j].b = f.edge_lines[j].y();
    m.edges[j].c = f.edge_lines[j].z();
    m.corners[j].u = f.corners_px[j].x();
    m.corners[j].v = f.corners_px[j].y();
  }
  m.pattern.reserve(f.pattern.size());
  for (const auto& p : f.pattern) {
    PatternPoint q;
    q.id = p.id;
    q.board_point = toPointMsg(p.board_point);
    q.pixel.u = p.pixel.x();
    q.pixel.v = p.pixel.y();
    m.pattern.push_back(q);
  }
  m.reprojection_rms = f.reprojection_rms_px;
  return m;
}

CameraBoardFeatures fromMsg(const CameraBoard& m) {
  CameraBoardFeatures f;
  f.frame_id = m.header.frame_id;
  f.stamp = m.header.stamp.toSec();
  f.found = m.found;
  f.reason = m.reason;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) f.K(r, c) = m.K[r * 3 + c];
  f.image_width = static_cast<int>(m.image_width);
  f.image_height = static_cast<int>(m.image_height);
  f.camera_T_board = fromPoseMsg(m.camera_pose_board);
  f.plane.normal = toEigen(m.plane_normal);
  f.plane.offset = m.plane_offset;
  for (int j = 0; j < kNumEdges; ++j) {
    f.edge_valid[j] = m.edges[j].valid;
    f.edge_lines[j] = {m.edges[j].a, m.edges[j].b, m.edges[j].c};
    f.corners_px[j] = {m.corners[j].u, m.corners[j].v};
  }
  for (const auto& p : m.pattern)
    f.pattern.push_back({p.id, toEigen(p.board_point), {p.pixel.u, p.pixel.v}});
  f.reprojection_rms_px = m.reprojection_rms;
  return f;
}

std::string validateTransform(const geometry_msgs::Transform& m) {
  constexpr double kQuaternionNormSqTolerance = 0.01;  // tf2 refuses a transform beyond this
  const double values[7] = {m.translation.x, m.translation.y, m.translation.z, m.rotation.x,
                            m.rotation.y,    m.rotation.z,    m.rotation.w};
  for (double v : values)
    if (!std::isfinite(v)) return "transform holds a non-finite value";
  const double norm_sq = m.rotation.x * m.rotation.x + m.rotation.y * m.rotation.y +
                         m.rotation.z * m.rotation.z + m.rotation.w * m.rotation.w;
  if (std::abs(norm_sq - 1.0) > kQuaternionNormSqTolerance)
    return "transform quaternion is not unit (|q|^2 = " + std::to_string(norm_sq) + ")";
  return {};
}

geometry_msgs::Transform toTransformMsg(const Eigen::Isometry3d& T) {
  geometry_msgs::Transform m;
  m.translation = toVector3(T.translation());
  const Eigen::Quaterniond q(T.rotation());
  m.rotation.x = q.x();
  m.rotation.y = q.y();
  m.rotation.z = q.z();
  m.rotation.w = q.w();
  return m;
}

Eigen::Isometry3d fromTransformMsg(const geometry_msgs::Transform& m) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = Eigen::Quaterniond(m.rotation.w, m.rotation.x, m.rotation.y, m.rotation.z)
                   .normalized()
                   .toRotationMatrix();
  T.translation() = toEigen(m.translation);
  return T;
}

geometry_msgs::Pose toPoseMsg(const Eigen::Isometry3d& T) {
  geometry_msgs::Pose m;
  m.position = toPointMsg(T.translation());
  const Eigen::Quaterniond q(T.rotation());
  m.orientation.x = q.x();
  m.orientation.y = q.y();
  m.orientation.z = q.z();
  m.orientation.w = q.w();
  return m;
}

Eigen::Isometry3d fromPoseMsg(const geometry_msgs::Pose& m) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() =
      Eigen::Quaterniond(m.orientation.w, m.orientation.x, m.orientation.y, m.orientation.z)
          .normalized()
          .toRotationMatrix();
  T.translation() = toEigen(m.position);
  return T;
}

}  // namespace board_calib
