// Every class declared in nodelet_plugins.xml loads through pluginlib (the way a nodelet
// manager loads it), and every nodelet source has its declaration: the two stay in sync.
#include <gtest/gtest.h>
#include <nodelet/nodelet.h>
#include <ros/ros.h>
#include <pluginlib/class_loader.hpp>

#include <fstream>
#include <regex>
#include <set>
#include <sstream>

namespace {

std::set<std::string> declaredClasses() {
  std::ifstream f(std::string(BOARD_CALIB_SOURCE_DIR) + "/nodelet_plugins.xml");
  std::stringstream text;
  text << f.rdbuf();
  const std::string xml = text.str();
  std::set<std::string> names;
  const std::regex class_name(R"re(<class\s+name="([^"]+)")re");
  for (auto it = std::sregex_iterator(xml.begin(), xml.end(), class_name);
       it != std::sregex_iterator(); ++it)
    names.insert((*it)[1]);
  return names;
}

}  // namespace

TEST(NodeletPlugins, DeclarationsMatchTheNodeletSources) {
  const std::set<std::string> expected = {"board_calib/cloud_board_detector",
                                          "board_calib/image_board_detector",
                                          "board_calib/calibrator", "board_calib/projection"};
  EXPECT_EQ(declaredClasses(), expected);
}

TEST(NodeletPlugins, EveryDeclaredClassLoads) {
  pluginlib::ClassLoader<nodelet::Nodelet> loader("nodelet", "nodelet::Nodelet");
  const auto declared = declaredClasses();
  ASSERT_FALSE(declared.empty());
  for (const auto& name : declared) {
    ASSERT_TRUE(loader.isClassAvailable(name))
        << name << " is not visible to pluginlib (package export?)";
    try {
      boost::shared_ptr<nodelet::Nodelet> instance = loader.createInstance(name);
      EXPECT_TRUE(instance != nullptr) << name;
    } catch (const pluginlib::PluginlibException& e) {
      ADD_FAILURE() << name << ": " << e.what();
    }
  }
}

// Nodelet constructors may create NodeHandles: roscpp must be initialised and a master running
// (rostest).
int main(int argc, char** argv) {
  ::testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_nodelet_plugins",
            ros::init_options::AnonymousName | ros::init_options::NoSigintHandler);
  return RUN_ALL_TESTS();
}
