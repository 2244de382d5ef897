// Shared by the end-to-end rostests: waits, in wall time, until `rosbag play --clock` has
// finished (the simulated clock stops with the bag, so a sim-time timeout would never expire).
#pragma once

#include <ros/ros.h>
#include <rosgraph_msgs/Clock.h>

namespace board_calib_test {

/// True once /clock has advanced and then stayed still for `quiet_s`; false on timeout (or
/// when no /clock ever arrived).
inline bool waitForBagEnd(ros::NodeHandle& nh, double timeout_s, double quiet_s = 4.0) {
  ros::Time last_clock;
  ros::WallTime last_change = ros::WallTime::now();
  ros::Subscriber sub =
      nh.subscribe<rosgraph_msgs::Clock>("/clock", 10, [&](const rosgraph_msgs::ClockConstPtr& c) {
        if (c->clock != last_clock) {
          last_clock = c->clock;
          last_change = ros::WallTime::now();
        }
      });
  const ros::WallTime deadline = ros::WallTime::now() + ros::WallDuration(timeout_s);
  while (ros::ok() && ros::WallTime::now() < deadline) {
    ros::spinOnce();
    if (!last_clock.isZero() && (ros::WallTime::now() - last_change).toSec() > quiet_s) return true;
    ros::WallDuration(0.1).sleep();
  }
  return false;
}

}  // namespace board_calib_test
