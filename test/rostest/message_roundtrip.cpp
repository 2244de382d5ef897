// rostest: board feature messages travel through a real master and arrive intact. Proves the
// generated messages, the conversions and the rostest machinery work together in CI.
#include <board_calib/conversions.h>

#include <gtest/gtest.h>
#include <ros/ros.h>

TEST(MessageRoundTrip, LidarBoardThroughMaster) {
  ros::NodeHandle nh;
  board_calib::LidarBoardFeatures sent;
  sent.frame_id = "lidar";
  sent.stamp = 42.0;
  sent.found = true;
  sent.plane.offset = 2.75;
  sent.board_points.assign(500, Eigen::Vector3d(2.75, 0.1, -0.2));
  sent.edge_valid = {true, true, true, true};

  board_calib::LidarBoardFeatures received;
  bool got = false;
  ros::Subscriber sub = nh.subscribe<board_calib::LidarBoard>(
      "board", 1, [&](const board_calib::LidarBoardConstPtr& m) {
        received = board_calib::fromMsg(*m);
        got = true;
      });
  ros::Publisher pub = nh.advertise<board_calib::LidarBoard>("board", 1);
  const ros::WallTime deadline = ros::WallTime::now() + ros::WallDuration(20.0);
  while (!got && ros::ok() && ros::WallTime::now() < deadline) {
    if (pub.getNumSubscribers() > 0) pub.publish(board_calib::toMsg(sent));
    ros::spinOnce();
    ros::WallDuration(0.05).sleep();
  }
  ASSERT_TRUE(got) << "no message arrived within 20 s";
  EXPECT_EQ(received.frame_id, "lidar");
  EXPECT_DOUBLE_EQ(received.stamp, 42.0);
  EXPECT_DOUBLE_EQ(received.plane.offset, 2.75);
  EXPECT_EQ(received.board_points.size(), 500u);
  EXPECT_TRUE(received.allEdgesValid());
}

int main(int argc, char** argv) {
  ::testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "message_roundtrip_test");
  return RUN_ALL_TESTS();
}
