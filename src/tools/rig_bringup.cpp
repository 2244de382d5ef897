// rig_bringup: brings up a whole MSG-Cal rig from its rig file (docs/MSG.md) in a running nodelet
// manager: one image detector per camera and one cloud detector per LiDAR, subscribed to the
// rig file's topics and loading its target, the calibrator in rig mode, and a projection per
// camera <-> LiDAR pair. Nothing is given twice: topics and target come from the rig file only,
// parsed by the same core loader as `calibrate_bag --config`, so a bad key fails here by name.
// It stays up to reload its nodelets when the (respawned) manager lost them, and unloads them
// when it stops. launch/rig_calibration.launch starts it.
//   rosrun board_calib rig_bringup _rig_file:=my_rig.yaml _manager:=board_calib_manager
#include <board_calib/core/rig/rig_config.h>

#include <nodelet/NodeletList.h>
#include <nodelet/NodeletLoad.h>
#include <nodelet/NodeletUnload.h>
#include <ros/names.h>
#include <ros/ros.h>

#include <atomic>
#include <csignal>
#include <cstdlib>
#include <map>
#include <set>
#include <string>
#include <utility>
#include <vector>

namespace {

constexpr char kLog[] = "rig_bringup";

// Set by SIGINT/SIGTERM: the node unloads its nodelets while it can still call the manager.
std::atomic<bool> g_stop{false};
void onSignal(int) { g_stop = true; }

// One nodelet to load: its name (relative to this node's namespace), type, remappings
// (nodelet's name -> rig topic) and private parameters.
struct NodeletSpec {
  std::string name;
  std::string type;
  std::vector<std::pair<std::string, std::string>> remaps;
  std::map<std::string, std::string> params;
};

// Sensor names become node and topic names, and every topic is remapped: all must be valid ROS
// names (resolveName would throw on the first bad one). The reason names the key.
std::string checkNames(const board_calib::RigConfig& rig) {
  std::string why;
  for (const auto& name : rig.sensorNames())
    if (!ros::names::validate(name, why) || name.find('/') != std::string::npos ||
        name.front() == '~')
      return "sensor name '" + name +
             "' is not usable as a ROS node name (letters, digits, '_' only)";
  auto topic = [&](const std::string& key, const std::string& value) {
    return ros::names::validate(value, why) ? std::string()
                                            : key + ": '" + value + "' is not a ROS name: " + why;
  };
  for (size_t i = 0; i < rig.cameras.size(); ++i) {
    const std::string at = "cameras[" + std::to_string(i) + "].";
    for (const auto& bad : {topic(at + "image_topic", rig.cameras[i].image_topic),
                            topic(at + "camera_info_topic", rig.cameras[i].camera_info_topic),
                            topic(at + "features_topic", rig.cameras[i].features_topic)})
      if (!bad.empty()) return bad;
  }
  for (size_t i = 0; i < rig.lidars.size(); ++i) {
    const std::string at = "lidars[" + std::to_string(i) + "].";
    for (const auto& bad : {topic(at + "cloud_topic", rig.lidars[i].cloud_topic),
                            topic(at + "features_topic", rig.lidars[i].features_topic)})
      if (!bad.empty()) return bad;
  }
  return "";
}

std::vector<NodeletSpec> plan(const board_calib::RigConfig& rig, const std::string& rig_file,
                              bool projections) {
  std::vector<NodeletSpec> out;
  for (const auto& c : rig.cameras) {
    NodeletSpec s{c.name + "_board_detector", "board_calib/image_board_detector", {}, {}};
    s.remaps = {{"image_raw", c.image_topic},
                {"camera_info", c.camera_info_topic},
                {"camera_board", c.features_topic},
                {"debug_image", s.name + "/debug_image"}};
    s.params["target_file"] = rig.target_path;
    out.push_back(s);
  }
  for (const auto& l : rig.lidars) {
    NodeletSpec s{l.name + "_board_detector", "board_calib/cloud_board_detector", {}, {}};
    // Every LiDAR's debug outputs under its detector's name, so several LiDARs never share one.
    s.remaps = {{"points", l.cloud_topic},
                {"lidar_board", l.features_topic},
                {"board_points", s.name + "/board_points"},
                {"edge_points", s.name + "/edge_points"},
                {"markers", s.name + "/markers"}};
    s.params["target_file"] = rig.target_path;
    out.push_back(s);
  }
  out.push_back({"calibrator", "board_calib/calibrator", {}, {{"rig_file", rig_file}}});
  if (!projections) return out;
  for (const auto& c : rig.cameras)
    for (const auto& l : rig.lidars) {
      const std::string pair = c.name + "_" + l.name;
      NodeletSpec s{"projection_" + pair, "board_calib/projection", {}, {}};
      // The extrinsic comes from the calibrator's static TF (every sensor from the reference).
      s.remaps = {{"image", c.image_topic},
                  {"camera_info", c.camera_info_topic},
                  {"points", l.cloud_topic},
                  {"camera_board", c.features_topic},
                  {"lidar_board", l.features_topic},
                  {"overlay", pair + "/overlay"},
                  {"colored_cloud", pair + "/colored_cloud"},
                  {"camera_frustum", pair + "/camera_frustum"}};
      out.push_back(s);
    }
  return out;
}

class Bringup {
 public:
  Bringup(ros::NodeHandle nh, std::string manager, std::vector<NodeletSpec> specs)
      : nh_(nh), manager_(std::move(manager)), specs_(std::move(specs)) {}

  // Sets the parameters and loads every nodelet not yet in the manager; false with the reason.
  bool loadMissing(double wait_s, std::string* why) {
    ros::ServiceClient list = nh_.serviceClient<nodelet::NodeletList>(manager_ + "/list");
    ros::ServiceClient load = nh_.serviceClient<nodelet::NodeletLoad>(manager_ + "/load_nodelet");
    if (!load.waitForExistence(ros::Duration(wait_s))) {
      *why = "no nodelet manager at " + nh_.resolveName(manager_) +
             " (its load_nodelet service did not appear)";
      return false;
    }
    nodelet::NodeletList listed;
    if (!list.call(listed)) {
      *why = "cannot list the nodelets of " + nh_.resolveName(manager_);
      return false;
    }
    const std::set<std::string> present(listed.response.nodelets.begin(),
                                        listed.response.nodelets.end());
    for (const auto& s : specs_) {
      const std::string name = nh_.resolveName(s.name, false);
      if (present.count(name)) continue;
      for (const auto& [key, value] : s.params) ros::param::set(name + "/" + key, value);
      nodelet::NodeletLoad srv;
      srv.request.name = name;
      srv.request.type = s.type;
      for (const auto& [from, to] : s.remaps) {
        srv.request.remap_source_args.push_back(nh_.resolveName(from, false));
        srv.request.remap_target_args.push_back(nh_.resolveName(to, false));
      }
      if (!load.call(srv) || !srv.response.success) {
        *why = "the manager refused to load " + name + " (" + s.type + "); its log says why";
        return false;
      }
      ROS_INFO_STREAM_NAMED(kLog, "rig_bringup: loaded " << name << " (" << s.type << ")");
    }
    return true;
  }

  void unloadAll() {
    ros::ServiceClient unload =
        nh_.serviceClient<nodelet::NodeletUnload>(manager_ + "/unload_nodelet");
    if (!unload.exists()) return;  // the manager is gone, and its nodelets with it
    for (auto it = specs_.rbegin(); it != specs_.rend(); ++it) {
      nodelet::NodeletUnload srv;
      srv.request.name = nh_.resolveName(it->name, false);
      (void)unload.call(srv);
    }
  }

 private:
  ros::NodeHandle nh_;
  std::string manager_;
  std::vector<NodeletSpec> specs_;
};

}  // namespace

int main(int argc, char** argv) {
  ros::init(argc, argv, "rig_bringup", ros::init_options::NoSigintHandler);
  std::signal(SIGINT, onSignal);
  std::signal(SIGTERM, onSignal);
  ros::NodeHandle nh, pnh("~");
  std::string rig_file, working_dir, manager;
  bool projections = true;
  double manager_wait_s = 30.0, check_period_s = 2.0;
  if (!pnh.getParam("rig_file", rig_file) || rig_file.empty()) {
    ROS_FATAL_NAMED(kLog,
                    "rig_bringup: no rig file: give rig_file:=RIG.yaml to rig_calibration.launch "
                    "(~rig_file; docs/MSG.md)");
    return 2;
  }
  pnh.param("working_dir", working_dir, std::string());
  pnh.param("manager", manager, std::string("board_calib_manager"));
  pnh.param("projections", projections, true);
  pnh.param("manager_wait", manager_wait_s, manager_wait_s);
  pnh.param("check_period", check_period_s, check_period_s);
  // roslaunch runs nodes in ROS_HOME: a relative rig file is relative to where roslaunch was
  // called.
  if (rig_file.rfind("~/", 0) == 0)
    if (const char* home = std::getenv("HOME")) rig_file = std::string(home) + rig_file.substr(1);
  if (rig_file.front() != '/' && !working_dir.empty()) rig_file = working_dir + "/" + rig_file;

  const auto rig = board_calib::loadRigConfig(rig_file);
  if (!rig) {
    ROS_FATAL_STREAM_NAMED(kLog, "rig_bringup: " << rig.error());
    return 1;
  }
  if (const std::string why = checkNames(*rig); !why.empty()) {
    ROS_FATAL_STREAM_NAMED(kLog, "rig_bringup: " << rig_file << ": " << why);
    return 1;
  }
  Bringup bringup(nh, manager, plan(*rig, rig_file, projections));
  std::string why;
  if (!bringup.loadMissing(manager_wait_s, &why)) {
    ROS_FATAL_STREAM_NAMED(kLog, "rig_bringup: " << why);
    return 1;
  }
  ROS_INFO_STREAM_NAMED(kLog, "rig_bringup: " << rig_file << ": " << rig->cameras.size()
                                              << " camera(s), " << rig->lidars.size()
                                              << " LiDAR(s), target " << rig->target_path);
  // A respawned manager comes back empty: load the rig again (the calibrator resumes its autosave).
  ros::WallTimer check =
      nh.createWallTimer(ros::WallDuration(check_period_s), [&](const ros::WallTimerEvent&) {
        std::string reason;
        if (!bringup.loadMissing(check_period_s, &reason))
          ROS_WARN_STREAM_THROTTLE_NAMED(10.0, kLog, "rig_bringup: " << reason);
      });
  while (!g_stop && ros::ok()) {
    ros::spinOnce();
    ros::WallDuration(0.05).sleep();
  }
  check.stop();
  bringup.unloadAll();
  ros::shutdown();
  return 0;
}
