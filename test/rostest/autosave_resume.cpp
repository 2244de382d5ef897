// Autosave + resume rostest (see autosave_resume.test): 10 views captured, the manager killed
// with SIGKILL, the respawned calibrator must hold the same 10 views.
#include <board_calib/CameraBoard.h>
#include <board_calib/LidarBoard.h>
#include <board_calib/SessionFile.h>
#include <board_calib/conversions.h>
#include <board_calib/core/session/session.h>
#include <board_calib/core/transform.h>

#include <gtest/gtest.h>
#include <ros/network.h>
#include <ros/ros.h>
#include <std_srvs/Trigger.h>
#include <xmlrpcpp/XmlRpc.h>

#include <signal.h>

#include <filesystem>

namespace {

constexpr int kViews = 10;
constexpr double kBoardSideM = 1.016;  // config/targets/plain_1016.yaml

// Both sensors' features of a board pose (camera frame; the LiDAR frame equals it here: the
// calibrator only pairs and gates, it does not solve in this test).
void features(const Eigen::Isometry3d& camera_T_board, double stamp, board_calib::LidarBoard* lidar,
              board_calib::CameraBoard* camera) {
  board_calib::CameraBoardFeatures c;
  c.found = true;
  c.frame_id = "camera";
  c.stamp = stamp;
  c.K << 800, 0, 640, 0, 800, 360, 0, 0, 1;
  c.image_width = 1280;
  c.image_height = 720;
  c.camera_T_board = camera_T_board;
  c.plane.normal = camera_T_board.linear().col(2);
  c.plane.offset = c.plane.normal.dot(camera_T_board.translation());
  board_calib::LidarBoardFeatures l;
  l.found = true;
  l.frame_id = "lidar";
  l.stamp = stamp;
  l.plane = c.plane;
  for (int i = 0; i < 10; ++i)
    for (int j = 0; j < 10; ++j)
      l.board_points.push_back(camera_T_board * Eigen::Vector3d(0.1 * i, 0.1 * j, 0.0));
  l.measured_size_m = {kBoardSideM, kBoardSideM};
  *camera = board_calib::toMsg(c);
  *lidar = board_calib::toMsg(l);
  camera->header.stamp = lidar->header.stamp = ros::Time(stamp);
  camera->header.frame_id = "camera";
  lidar->header.frame_id = "lidar";
}

int viewsHeld(ros::NodeHandle& nh, const std::string& path) {
  ros::ServiceClient save = nh.serviceClient<board_calib::SessionFile>("calibrator/save_session");
  if (!save.waitForExistence(ros::Duration(30.0))) return -1;
  board_calib::SessionFile srv;
  srv.request.path = path;
  if (!save.call(srv) || !srv.response.success) return -1;
  return static_cast<int>(srv.response.views);
}

int calibratorPid() {
  XmlRpc::XmlRpcValue args, result, payload;
  args[0] = ros::this_node::getName();
  args[1] = "/calibrator";
  if (!ros::master::execute("lookupNode", args, result, payload, false) || int(result[0]) != 1)
    return -1;
  const std::string uri = result[2];
  std::string host;
  uint32_t port = 0;
  if (!ros::network::splitURI(uri, host, port)) return -1;
  XmlRpc::XmlRpcClient client(host.c_str(), static_cast<int>(port), "/");
  XmlRpc::XmlRpcValue pid_args, pid_result;
  pid_args[0] = ros::this_node::getName();
  if (!client.execute("getPid", pid_args, pid_result) || int(pid_result[0]) != 1) return -1;
  return int(pid_result[2]);
}

}  // namespace

TEST(AutosaveResume, KilledManagerLosesNoView) {
  ros::NodeHandle nh;
  std::string output_dir;
  ASSERT_TRUE(ros::param::get("~output_dir", output_dir));
  const std::string check_file = output_dir + "/check_session.yaml";
  ASSERT_EQ(viewsHeld(nh, check_file), 0) << "the calibrator must start empty (stale autosave?)";

  ros::Publisher lidar_pub = nh.advertise<board_calib::LidarBoard>("lidar_board", 10);
  ros::Publisher camera_pub = nh.advertise<board_calib::CameraBoard>("camera_board", 10);
  const ros::WallTime wait_until = ros::WallTime::now() + ros::WallDuration(10.0);
  while ((lidar_pub.getNumSubscribers() == 0 || camera_pub.getNumSubscribers() == 0) &&
         ros::WallTime::now() < wait_until)
    ros::WallDuration(0.05).sleep();
  ASSERT_GT(lidar_pub.getNumSubscribers(), 0u);

  // Each pose held still for 7 frames at 10 Hz (auto-capture needs the board still for 0.25 s on
  // both sides of an image), poses 40 cm apart (diversity gate).
  double stamp = 100.0;
  for (int v = 0; v < kViews; ++v) {
    const Eigen::Isometry3d pose =
        board_calib::makeTransform(Eigen::Vector3d(-1.5 + 0.4 * v, -0.5, 3.0),
                                   Eigen::Vector4d(0.05 * (v % 3), 0.05 * (v % 2), 0, 1));
    for (int frame = 0; frame < 7; ++frame, stamp += 0.1) {
      board_calib::LidarBoard lidar;
      board_calib::CameraBoard camera;
      features(pose, stamp, &lidar, &camera);
      camera_pub.publish(camera);
      lidar_pub.publish(lidar);
      ros::WallDuration(0.1).sleep();
    }
  }
  ros::WallDuration(0.5).sleep();
  ASSERT_EQ(viewsHeld(nh, check_file), kViews);
  ASSERT_TRUE(std::filesystem::exists(output_dir + "/autosave_session.yaml"));

  const int pid = calibratorPid();
  ASSERT_GT(pid, 0);
  ASSERT_EQ(::kill(pid, SIGKILL), 0);
  // Wait for the respawned process (a new pid), then for its services.
  int new_pid = -1;
  const ros::WallTime respawn_until = ros::WallTime::now() + ros::WallDuration(30.0);
  while (ros::WallTime::now() < respawn_until) {
    new_pid = calibratorPid();
    if (new_pid > 0 && new_pid != pid) break;
    ros::WallDuration(0.2).sleep();
  }
  ASSERT_GT(new_pid, 0);
  ASSERT_NE(new_pid, pid) << "the calibrator was not respawned";
  ASSERT_EQ(viewsHeld(nh, check_file), kViews) << "views lost across the restart";

  board_calib::PairSession resumed(board_calib::Target{}, board_calib::SessionOptions{});
  ASSERT_TRUE(resumed.load(check_file).ok);
  for (int v = 0; v < kViews; ++v) EXPECT_EQ(resumed.views()[v].view.id, v);

  // ~reset empties the session and its autosave: a further restart would start empty.
  ros::ServiceClient reset = nh.serviceClient<std_srvs::Trigger>("calibrator/reset");
  std_srvs::Trigger trigger;
  ASSERT_TRUE(reset.call(trigger));
  board_calib::PairSession after_reset(board_calib::Target{}, board_calib::SessionOptions{});
  ASSERT_TRUE(after_reset.load(output_dir + "/autosave_session.yaml").ok);
  EXPECT_TRUE(after_reset.views().empty());
}

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_autosave_resume");
  ros::AsyncSpinner spinner(1);
  spinner.start();
  return RUN_ALL_TESTS();
}
