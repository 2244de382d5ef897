// Atomic writes: a failed write never leaves a truncated or empty file in place of the previous
// one, and the reason names the path. Reads refuse what is not a regular file.
#include <board_calib/core/file_io.h>

#include <gtest/gtest.h>

#include <signal.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <sstream>

using namespace board_calib;
namespace fs = std::filesystem;

namespace {

std::string slurp(const fs::path& path) {
  std::ifstream in(path);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

size_t filesIn(const fs::path& dir) {
  size_t n = 0;
  for (const auto& e : fs::directory_iterator(dir)) n += e.is_regular_file();
  return n;
}

class FileIo : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("board_calib_file_io_" + std::to_string(::getpid()));
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  fs::path dir_;
};

}  // namespace

TEST_F(FileIo, WritesAndReplaces) {
  const std::string path = (dir_ / "result.yaml").string();
  ASSERT_TRUE(writeFileAtomic(path, "first\n").ok);
  ASSERT_TRUE(writeFileAtomic(path, "second\n").ok);
  EXPECT_EQ(slurp(path), "second\n");
  EXPECT_EQ(filesIn(dir_), 1u);  // no temporary left behind
  const auto back = readTextFile(path);
  ASSERT_TRUE(back.ok()) << back.error();
  EXPECT_EQ(*back, "second\n");
}

TEST_F(FileIo, RefusesDirectoriesAndMissingFolders) {
  const Status on_dir = writeFileAtomic(dir_.string(), "x");
  ASSERT_FALSE(on_dir.ok);
  EXPECT_NE(on_dir.reason.find("directory"), std::string::npos) << on_dir.reason;
  EXPECT_TRUE(fs::is_directory(dir_));

  const std::string missing = (dir_ / "no_such_folder" / "result.yaml").string();
  const Status no_folder = writeFileAtomic(missing, "x");
  ASSERT_FALSE(no_folder.ok);
  EXPECT_NE(no_folder.reason.find(missing), std::string::npos) << no_folder.reason;

  std::ofstream(dir_ / "plain_file") << "keep";
  EXPECT_FALSE(writeFileAtomic((dir_ / "plain_file" / "child.yaml").string(), "x").ok);
  EXPECT_EQ(slurp(dir_ / "plain_file"), "keep");
  EXPECT_EQ(filesIn(dir_), 1u);
}

TEST_F(FileIo, CreatesFoldersOrSaysWhyNot) {
  const fs::path nested = dir_ / "report" / "pair";
  ASSERT_TRUE(createFolder(nested.string()).ok);
  EXPECT_TRUE(fs::is_directory(nested));
  EXPECT_TRUE(createFolder(nested.string()).ok);  // already there: fine

  std::ofstream(dir_ / "plain_file") << "keep";
  const std::string under_file = (dir_ / "plain_file" / "report").string();
  const Status st = createFolder(under_file, "report folder");
  ASSERT_FALSE(st.ok);
  EXPECT_NE(st.reason.find("cannot create the report folder '" + under_file + "'"),
            std::string::npos)
      << st.reason;
  const Status on_file = createFolder((dir_ / "plain_file").string());
  ASSERT_FALSE(on_file.ok);  // a file where the folder should be
  EXPECT_EQ(slurp(dir_ / "plain_file"), "keep");
}

// Disk full / file-size limit: the child may write 4 KB; the new text is 1 MB. The write must
// fail with a reason and leave the previous file byte for byte.
TEST_F(FileIo, FileSizeLimitKeepsPreviousFile) {
  const std::string path = (dir_ / "session.yaml").string();
  const std::string previous = "board_calib_session: 1\nviews: []\n";
  ASSERT_TRUE(writeFileAtomic(path, previous).ok);
  const pid_t child = ::fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    ::signal(SIGXFSZ, SIG_IGN);  // write() then fails with EFBIG instead of killing the process
    constexpr rlim_t kLimitBytes = 4096;
    const rlimit limit{kLimitBytes, kLimitBytes};
    if (::setrlimit(RLIMIT_FSIZE, &limit) != 0) ::_exit(2);
    const Status st = writeFileAtomic(path, std::string(1 << 20, 'x'));
    ::_exit(!st.ok && st.reason.find(path) != std::string::npos ? 0 : 1);
  }
  int status = 0;
  ASSERT_EQ(::waitpid(child, &status, 0), child);
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 0) << "the write over the size limit did not fail with a reason";
  EXPECT_EQ(slurp(path), previous);
  EXPECT_EQ(filesIn(dir_), 1u);
}

TEST_F(FileIo, ReadRefusesNonFiles) {
  const auto dir = readTextFile(dir_.string());
  ASSERT_FALSE(dir.ok());
  EXPECT_NE(dir.error().find("directory"), std::string::npos);
  const auto device = readTextFile("/dev/null");
  ASSERT_FALSE(device.ok());
  EXPECT_NE(device.error().find("not a regular file"), std::string::npos);
  EXPECT_FALSE(readTextFile((dir_ / "missing").string()).ok());
  std::ofstream(dir_ / "big") << std::string(1000, 'x');
  const auto big = readTextFile((dir_ / "big").string(), "file", 100);
  ASSERT_FALSE(big.ok());
  EXPECT_NE(big.error().find("1000 bytes"), std::string::npos);
}
