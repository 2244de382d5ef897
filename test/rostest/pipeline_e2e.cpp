// End-to-end rostest: a simulated bag is played (--clock) into the detector nodelets and the
// calibrator; once the bag has finished, ~calibrate is called and the broadcast static TF is
// compared with the simulator's ground truth.
#include <board_calib/Calibrate.h>
#include <board_calib/conversions.h>
#include <board_calib/core/result_io.h>
#include <board_calib/core/transform.h>

#include "wait_for_bag_end.h"

#include <gtest/gtest.h>
#include <ros/ros.h>
#include <tf2_eigen/tf2_eigen.h>
#include <tf2_ros/transform_listener.h>
#include <algorithm>
#include <cmath>
#include <set>

namespace {

std::string param(const std::string& name, const std::string& fallback = "") {
  std::string v;
  ros::param::param("~" + name, v, fallback);
  return v;
}

}  // namespace

TEST(PipelineEndToEnd, CalibratedTfMatchesGroundTruth) {
  ros::NodeHandle nh;
  const std::string truth_file = param("truth_file");
  const std::string method = param("method", "pbpc");
  double rotation_tol_deg = 0.2, translation_tol_m = 0.01, timeout_s = 240;
  ros::param::param("~rotation_tolerance_deg", rotation_tol_deg, rotation_tol_deg);
  ros::param::param("~translation_tolerance_m", translation_tol_m, translation_tol_m);
  ros::param::param("~timeout", timeout_s, timeout_s);
  auto truth = board_calib::loadResultFile(truth_file);
  ASSERT_TRUE(truth.ok()) << truth.error();

  // Listen for TF from the start; every wait below is in wall time, since the simulated clock
  // stops with the bag (a sim-time timeout would never expire).
  tf2_ros::Buffer buffer;
  tf2_ros::TransformListener listener(buffer);

  ASSERT_TRUE(board_calib_test::waitForBagEnd(nh, timeout_s))
      << "the bag did not play to its end within " << timeout_s
      << " s (or no /clock from rosbag play)";

  ros::ServiceClient client = nh.serviceClient<board_calib::Calibrate>("calibrator/calibrate");
  ASSERT_TRUE(client.waitForExistence(ros::Duration(30.0)));
  board_calib::Calibrate srv;
  srv.request.method = method;
  ASSERT_TRUE(client.call(srv));
  ASSERT_TRUE(srv.response.success) << srv.response.message;
  const auto& r = srv.response.result;
  EXPECT_GE(r.views_used, 8u) << "too few views collected from the bag";

  // Ground truth of this pair.
  Eigen::Isometry3d truth_T = truth->camera_T_lidar;
  for (const auto& p : truth->pairs)
    if (p.camera_frame == r.camera_frame && p.lidar_frame == r.lidar_frame)
      truth_T = p.camera_T_lidar;

  // The broadcast TF (parent LiDAR, child camera) carries lidar_T_camera.
  const ros::WallTime tf_deadline = ros::WallTime::now() + ros::WallDuration(10.0);
  while (!buffer.canTransform(r.lidar_frame, r.camera_frame, ros::Time(0)) &&
         ros::WallTime::now() < tf_deadline)
    ros::WallDuration(0.05).sleep();
  geometry_msgs::TransformStamped tf;
  try {
    tf = buffer.lookupTransform(r.lidar_frame, r.camera_frame, ros::Time(0));
  } catch (const tf2::TransformException& e) {
    FAIL() << "no static TF " << r.lidar_frame << " -> " << r.camera_frame << ": " << e.what();
  }
  const Eigen::Isometry3d camera_T_lidar = tf2::transformToEigen(tf).inverse();
  const double rot = board_calib::rotationErrorDeg(camera_T_lidar, truth_T);
  const double trans = board_calib::translationErrorM(camera_T_lidar, truth_T);
  std::cout << "[pipeline_e2e] " << method << " with " << r.views_used << " views: rotation error "
            << rot << " deg, translation error " << trans * 1e3 << " mm, MLRE " << r.mlre_px
            << " px" << std::endl;
  // Tolerances from the issue: the simulated noise (2 cm range, 0.2 px) supports 0.2 deg / 1 cm.
  EXPECT_LT(rot, rotation_tol_deg);
  EXPECT_LT(trans, translation_tol_m);

  // Per-view residuals (what the rviz panel lists): one entry per view, finite exactly for the
  // used views, and in the units of the totals: the overall plane RMS pools every used point and
  // the overall MLRE every used edge point, so each lies between its per-view extremes (a unit
  // or indexing slip breaks that).
  ASSERT_EQ(r.view_ids.size(), r.view_mlre_px.size());
  ASSERT_EQ(r.view_ids.size(), r.view_plane_rms_mm.size());
  EXPECT_GE(r.view_ids.size(), r.views_used);
  EXPECT_EQ(std::set<int>(r.view_ids.begin(), r.view_ids.end()).size(), r.view_ids.size())
      << "duplicate view ids";
  std::vector<double> plane, mlre;
  for (size_t i = 0; i < r.view_ids.size(); ++i) {
    if (std::isfinite(r.view_plane_rms_mm[i])) plane.push_back(r.view_plane_rms_mm[i]);
    if (std::isfinite(r.view_mlre_px[i])) mlre.push_back(r.view_mlre_px[i]);
  }
  ASSERT_EQ(plane.size(), r.views_used);
  EXPECT_LE(*std::min_element(plane.begin(), plane.end()), r.plane_rms_mm);
  EXPECT_GE(*std::max_element(plane.begin(), plane.end()), r.plane_rms_mm);
  if (std::isfinite(r.mlre_px)) {
    ASSERT_FALSE(mlre.empty());
    EXPECT_LE(*std::min_element(mlre.begin(), mlre.end()), r.mlre_px);
    EXPECT_GE(*std::max_element(mlre.begin(), mlre.end()), r.mlre_px);
  }
}

int main(int argc, char** argv) {
  ::testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "pipeline_e2e_test");
  ros::NodeHandle nh;  // keeps the node alive for the whole test
  return RUN_ALL_TESTS();
}
