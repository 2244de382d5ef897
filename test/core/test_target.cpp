#include <board_calib/core/target.h>

#include <gtest/gtest.h>

#include <fstream>

using board_calib::parseTarget;
using board_calib::TargetType;

namespace {

const char* kPlain = "type: plain\nwidth: 1.016\nheight: 1.016\n";
const char* kChecker =
    "type: checkerboard\nwidth: 0.909\nheight: 0.6145\n"
    "checkerboard: {cols: 9, rows: 6, square: 0.0615, origin: [0.2005, 0.1565]}\n";
const char* kGrid =
    "type: apriltag_grid\nwidth: 1.016\nheight: 1.016\n"
    "apriltag_grid: {family: tag36h11, cols: 4, rows: 4, tag_size: 0.16, spacing: 0.04, first_id: "
    "0, "
    "origin: [0.1, 0.1]}\n";

// The error must name the key, so a user knows what to fix.
void expectErrorMentions(const std::string& yaml, const std::string& fragment) {
  const auto t = parseTarget(yaml);
  ASSERT_FALSE(t.ok()) << "accepted: " << yaml;
  EXPECT_NE(t.error().find(fragment), std::string::npos)
      << "error '" << t.error() << "' lacks '" << fragment << "'";
}

}  // namespace

TEST(Target, PlainBoardCornersInBoardFrame) {
  const auto t = parseTarget(kPlain);
  ASSERT_TRUE(t.ok()) << t.error();
  EXPECT_EQ(t->type, TargetType::kPlain);
  const auto c = t->outerCorners();
  EXPECT_TRUE(c[0].isApprox(Eigen::Vector3d(0, 0, 0)));
  EXPECT_TRUE(c[1].isApprox(Eigen::Vector3d(1.016, 0, 0)));
  EXPECT_TRUE(c[2].isApprox(Eigen::Vector3d(1.016, 1.016, 0)));
  EXPECT_TRUE(c[3].isApprox(Eigen::Vector3d(0, 1.016, 0)));
  EXPECT_TRUE(t->checkerboardCorners().empty());
  EXPECT_TRUE(t->aprilTagCorners().empty());
}

TEST(Target, CheckerboardCornersRowMajor) {
  const auto t = parseTarget(kChecker);
  ASSERT_TRUE(t.ok()) << t.error();
  const auto corners = t->checkerboardCorners();
  ASSERT_EQ(corners.size(), 54u);
  EXPECT_NEAR(corners[0].x(), 0.2005, 1e-12);
  EXPECT_NEAR(corners[0].y(), 0.1565, 1e-12);
  EXPECT_NEAR(corners[1].x(), 0.2005 + 0.0615, 1e-12);  // x runs fastest
  EXPECT_NEAR(corners[9].y(), 0.1565 + 0.0615, 1e-12);
  EXPECT_NEAR(corners[53].x(), 0.2005 + 8 * 0.0615, 1e-12);
}

TEST(Target, AprilTagGridIdsAndCorners) {
  const auto t = parseTarget(kGrid);
  ASSERT_TRUE(t.ok()) << t.error();
  const auto tags = t->aprilTagCorners();
  ASSERT_EQ(tags.size(), 16u);
  EXPECT_EQ(tags[0].id, 0);
  EXPECT_EQ(tags[5].id, 5);
  // Tag 5 is row 1, column 1: top-left corner at origin + pitch.
  EXPECT_TRUE(tags[5].corners[3].isApprox(Eigen::Vector3d(0.3, 0.3, 0)));
  EXPECT_TRUE(tags[5].corners[1].isApprox(Eigen::Vector3d(0.46, 0.46, 0)));
}

TEST(Target, RoundTripThroughYaml) {
  for (const char* text : {kPlain, kChecker, kGrid}) {
    const auto a = parseTarget(text);
    ASSERT_TRUE(a.ok());
    const auto b = parseTarget(board_calib::targetToYaml(*a));
    ASSERT_TRUE(b.ok()) << b.error();
    EXPECT_EQ(a->type, b->type);
    EXPECT_DOUBLE_EQ(a->width, b->width);
    EXPECT_EQ(a->checkerboardCorners().size(), b->checkerboardCorners().size());
    EXPECT_EQ(a->aprilTagCorners().size(), b->aprilTagCorners().size());
  }
}

TEST(Target, MalformedFilesNameTheKey) {
  expectErrorMentions("width: 1\nheight: 1\n", "'type'");
  expectErrorMentions("type: round\nwidth: 1\nheight: 1\n", "'type'");
  expectErrorMentions("type: plain\nheight: 1\n", "'width'");
  expectErrorMentions("type: plain\nwidth: -1\nheight: 1\n", "'width'");
  expectErrorMentions("type: plain\nwidth: abc\nheight: 1\n", "'width'");
  expectErrorMentions("type: plain\nwidth: 1\nheight: 1\ncolour: red\n", "'colour'");
  expectErrorMentions("type: checkerboard\nwidth: 1\nheight: 1\n", "'checkerboard'");
  expectErrorMentions(
      "type: checkerboard\nwidth: 1\nheight: 1\ncheckerboard: {cols: 7, rows: 5, square: 0.1}\n",
      "'checkerboard.origin'");
  expectErrorMentions(
      "type: checkerboard\nwidth: 1\nheight: 1\ncheckerboard: {cols: 7.5, rows: 5, square: 0.1, "
      "origin: [0.2, 0.2]}\n",
      "'checkerboard.cols'");
  expectErrorMentions(
      "type: checkerboard\nwidth: 1\nheight: 1\ncheckerboard: {cols: 7, rows: 5, square: 0.1, "
      "origin: [0.2, 0.2], "
      "size: 3}\n",
      "'checkerboard.size'");
  expectErrorMentions(
      "type: checkerboard\nwidth: 0.5\nheight: 0.5\ncheckerboard: {cols: 7, rows: 5, square: 0.1, "
      "origin: [0.1, 0.1]}\n",
      "does not fit");
  expectErrorMentions(
      "type: apriltag_grid\nwidth: 0.5\nheight: 0.5\napriltag_grid: {family: tag36h11, cols: 4, "
      "rows: 4, tag_size: "
      "0.16, spacing: 0.04, first_id: 0, origin: [0.1, 0.1]}\n",
      "does not fit");
  expectErrorMentions(
      "type: apriltag_grid\nwidth: 1\nheight: 1\napriltag_grid: {family: tag25h9, cols: 2, rows: "
      "2, tag_size: "
      "0.16, spacing: 0.04, first_id: 0, origin: [0.1, 0.1]}\n",
      "family");
  expectErrorMentions("[1, 2, 3]", "mapping");
  expectErrorMentions("type: plain\nwidth: [1\n", "invalid YAML");
}

TEST(Target, UnreadableFileIsAnError) {
  const auto t = board_calib::loadTarget("/nonexistent/target.yaml");
  ASSERT_FALSE(t.ok());
  EXPECT_NE(t.error().find("/nonexistent/target.yaml"), std::string::npos);
}

TEST(Target, ShippedAndSharedTargetsLoad) {
  for (const std::string& path :
       {std::string(BOARD_CALIB_SOURCE_DIR) + "/config/targets/plain_1016.yaml",
        std::string(BOARD_CALIB_SOURCE_DIR) + "/config/targets/checkerboard_7x5.yaml",
        std::string(BOARD_CALIB_SOURCE_DIR) + "/config/targets/apriltag_grid_4x4.yaml"}) {
    const auto t = board_calib::loadTarget(path);
    EXPECT_TRUE(t.ok()) << t.error();
  }
  const std::string shared = BOARD_CALIB_SHARED_DIR;
  for (const char* rel :
       {"/data/basler_os1_plain/target.yaml", "/data/left_vlp32_checker/target.yaml"}) {
    std::ifstream probe(shared + rel);
    if (!probe) continue;  // ../shared is optional outside CI
    const auto t = board_calib::loadTarget(shared + rel);
    EXPECT_TRUE(t.ok()) << t.error();
  }
}

// Issue 15: hostile target files end with a reason naming the value, never a crash.
TEST(Target, HostileValuesAreRefused) {
  // rows * cols overflowed int and passed the tag-count limit, then allocated until bad_alloc.
  expectErrorMentions(
      "type: apriltag_grid\nwidth: 1\nheight: 1\napriltag_grid: {family: tag36h11, cols: 65536, "
      "rows: 65536, "
      "tag_size: 0.00000001, spacing: 0, first_id: 0, origin: [0.1, 0.1]}\n",
      "65536 x 65536");
  expectErrorMentions("type: plain\nwidth: 1\nwidth: 2\nheight: 1\n", "duplicate key 'width'");
  expectErrorMentions("type: plain\nwidth: 1e9\nheight: 1\n", "larger than any board");
  expectErrorMentions("type: plain\nwidth: .inf\nheight: 1\n", "finite");
  expectErrorMentions("type: plain\nwidth: .nan\nheight: 1\n", "finite");
  expectErrorMentions(
      "type: checkerboard\nwidth: 1\nheight: 1\ncheckerboard: {cols: 7, rows: 5, square: 0.1, "
      "origin: [.nan, 0.2]}\n",
      "checkerboard.origin");
  expectErrorMentions(
      "type: checkerboard\nwidth: 1\nheight: 1\ncheckerboard: {cols: 2147483648, rows: 5, square: "
      "0.1, origin: [0.2, "
      "0.2]}\n",
      "checkerboard.cols");
  expectErrorMentions(
      "type: checkerboard\nwidth: 9\nheight: 9\ncheckerboard: {cols: 200, rows: 201, square: "
      "0.001, origin: [0.2, "
      "0.2]}\n",
      "inner corners");
}
