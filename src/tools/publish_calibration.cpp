// publish_calibration: broadcasts a saved board_calib result file as static TF, so a robot can
// use a calibration without re-running it (and without tf2_ros's static_transform_publisher,
// which Debian's ROS packages do not ship). A single-pair result gives parent = LiDAR frame,
// child = camera frame (or ~child_frame); a rig result gives every sensor from the reference
// frame (child = sensor frame + ~child_frame_suffix).
//   rosrun board_calib publish_calibration _result_file:=/path/pbpc_result.yaml
#include <board_calib/conversions.h>
#include <board_calib/core/result_io.h>

#include <geometry_msgs/TransformStamped.h>
#include <ros/ros.h>
#include <tf2_ros/static_transform_broadcaster.h>

#include <cstdlib>
#include <vector>

namespace {

geometry_msgs::TransformStamped stamped(const std::string& parent, const std::string& child,
                                        const Eigen::Isometry3d& parent_T_child) {
  geometry_msgs::TransformStamped tf;
  tf.header.stamp = ros::Time::now();
  tf.header.frame_id = parent;
  tf.child_frame_id = child;
  tf.transform = board_calib::toTransformMsg(parent_T_child);
  return tf;
}

}  // namespace

int main(int argc, char** argv) {
  ros::init(argc, argv, "publish_calibration");
  ros::NodeHandle pnh("~");
  std::string result_file, child_frame, child_frame_suffix;
  if (!pnh.getParam("result_file", result_file) || result_file.empty()) {
    ROS_FATAL(
        "publish_calibration: private parameter ~result_file (a board_calib result YAML) is "
        "required");
    return 2;
  }
  // The shell does not expand `~` after `result_file:=` (README's form), so expand it here.
  if (result_file.rfind("~/", 0) == 0)
    if (const char* home = std::getenv("HOME"))
      result_file = std::string(home) + result_file.substr(1);
  pnh.param("child_frame", child_frame, std::string());
  pnh.param("child_frame_suffix", child_frame_suffix, std::string());
  const auto result = board_calib::loadResultFile(result_file);
  if (!result) {
    ROS_FATAL_STREAM("publish_calibration: " << result.error());
    return 1;
  }

  std::vector<geometry_msgs::TransformStamped> tfs;
  if (!result->sensors.empty()) {
    // Rig result: every sensor's pose in the reference frame.
    std::string reference = result->reference_frame;
    for (const auto& s : result->sensors)
      if (reference.empty() && s.reference_T_sensor.matrix().isIdentity(1e-12)) reference = s.frame;
    if (reference.empty()) {
      ROS_FATAL_STREAM("publish_calibration: " << result_file
                                               << " lists sensors but no reference_frame");
      return 1;
    }
    for (const auto& s : result->sensors)
      if (s.frame != reference)
        tfs.push_back(stamped(reference, s.frame + child_frame_suffix, s.reference_T_sensor));
  } else {
    if (result->camera_frame.empty() || result->lidar_frame.empty()) {
      ROS_FATAL_STREAM("publish_calibration: " << result_file
                                               << " has no camera_frame / lidar_frame");
      return 1;
    }
    const std::string child =
        child_frame.empty() ? result->camera_frame + child_frame_suffix : child_frame;
    tfs.push_back(stamped(result->lidar_frame, child, result->camera_T_lidar.inverse()));
  }
  // The reader refuses non-finite numbers; this is the last line before the robot's TF tree.
  for (const auto& tf : tfs)
    if (const std::string why = board_calib::validateTransform(tf.transform); !why.empty()) {
      ROS_FATAL_STREAM("publish_calibration: " << result_file << ": " << tf.header.frame_id
                                               << " -> " << tf.child_frame_id << ": " << why
                                               << "; nothing broadcast");
      return 1;
    }
  tf2_ros::StaticTransformBroadcaster broadcaster;
  broadcaster.sendTransform(tfs);
  for (const auto& tf : tfs)
    ROS_INFO_STREAM("publish_calibration: " << tf.header.frame_id << " -> " << tf.child_frame_id
                                            << " (from " << result_file << ")");
  ros::spin();
  return 0;
}
