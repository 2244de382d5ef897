// Deterministic fuzzer over the rig YAML reader (see fuzz_inputs.cpp): mutations of the shipped
// rig file must end in a reason or a valid rig, never a crash or a sanitizer report.
#include <board_calib/core/rig/rig_config.h>

#include "fuzz_text.h"

#include <gtest/gtest.h>

#include <fstream>

using namespace board_calib;

namespace {
constexpr int kIterations = 1500;  // as the other YAML fuzzers; a few seconds in Release
}  // namespace

TEST(FuzzRig, RigYaml) {
  std::mt19937 rng(fuzz::seed(15007));
  const std::string dir = std::string(BOARD_CALIB_SOURCE_DIR) + "/config/rigs";
  std::ifstream in(dir + "/multi_rig_apriltag.yaml");
  std::stringstream buffer;
  buffer << in.rdbuf();
  const std::string rig = buffer.str();
  ASSERT_TRUE(parseRigConfig(rig, dir).ok());
  int accepted = 0;
  for (int i = 0; i < kIterations; ++i) {
    const auto parsed = parseRigConfig(fuzz::mutateText(rng, rig), dir);
    if (!parsed) {
      EXPECT_FALSE(parsed.error().empty());
      continue;
    }
    ++accepted;
    ASSERT_FALSE(parsed->cameras.empty() && parsed->lidars.empty());
  }
  EXPECT_GT(accepted, 0);  // some mutations (comments, whitespace) keep the rig valid
}

TEST(FuzzRig, NonFiles) {
  EXPECT_FALSE(loadRigConfig(std::string(BOARD_CALIB_SOURCE_DIR) + "/config").ok());
  EXPECT_FALSE(loadRigConfig("/dev/null").ok());
}
