#include <board_calib/core/file_io.h>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>

namespace board_calib {
namespace {

std::string errnoText(int error) { return std::strerror(error); }

// Folder and file name of a path ("result.yaml" -> "." and "result.yaml").
std::pair<std::string, std::string> splitPath(const std::string& path) {
  const size_t slash = path.find_last_of('/');
  if (slash == std::string::npos) return {".", path};
  return {slash == 0 ? "/" : path.substr(0, slash), path.substr(slash + 1)};
}

Status writeAll(int fd, const std::string& text) {
  const char* p = text.data();
  size_t left = text.size();
  while (left > 0) {
    const ssize_t n = ::write(fd, p, left);
    if (n < 0) {
      if (errno == EINTR) continue;
      return Status::failure(errnoText(errno));
    }
    p += n;
    left -= static_cast<size_t>(n);
  }
  return Status::success();
}

}  // namespace

Status createFolder(const std::string& dir, const std::string& what) {
  std::error_code error;
  std::filesystem::create_directories(dir, error);
  if (!error && std::filesystem::is_directory(dir, error)) return Status::success();
  return Status::failure("cannot create the " + what + " '" + dir +
                         "': " + (error ? error.message() : "not a folder"));
}

Status writeFileAtomic(const std::string& path, const std::string& text) {
  const auto fail = [&](const std::string& why) {
    return Status::failure("cannot write '" + path + "': " + why);
  };
  if (path.empty()) return Status::failure("cannot write a file with an empty path");
  const auto [folder, name] = splitPath(path);
  if (name.empty()) return fail("the path names a folder");
  struct stat target_stat {};
  if (::stat(path.c_str(), &target_stat) == 0 && S_ISDIR(target_stat.st_mode))
    return fail("it is a directory");

  // A unique hidden name in the same folder, so the rename stays on one file system.
  static std::atomic<unsigned> counter{0};
  std::string temp;
  int fd = -1;
  constexpr int kNameAttempts = 100;
  for (int attempt = 0; attempt < kNameAttempts && fd < 0; ++attempt) {
    temp = folder + "/." + name + ".tmp." + std::to_string(::getpid()) + "." +
           std::to_string(counter++);
    fd = ::open(temp.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0666);  // umask applies
    if (fd < 0 && errno != EEXIST) return fail(errnoText(errno));
  }
  if (fd < 0) return fail("no free temporary name");
  Status written = writeAll(fd, text);
  if (written && ::fsync(fd) != 0) written = Status::failure(errnoText(errno));
  if (::close(fd) != 0 && written) written = Status::failure(errnoText(errno));
  if (written && ::rename(temp.c_str(), path.c_str()) != 0)
    written = Status::failure(errnoText(errno));
  if (!written) {
    ::unlink(temp.c_str());
    return fail(written.reason);
  }
  // The rename itself is durable once the folder is synced; failing that loses nothing already
  // there.
  const int dir_fd = ::open(folder.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (dir_fd >= 0) {
    ::fsync(dir_fd);
    ::close(dir_fd);
  }
  return Status::success();
}

Expected<std::string> readTextFile(const std::string& path, const std::string& what,
                                   size_t max_bytes) {
  using Result = Expected<std::string>;
  const std::string prefix = "cannot read " + what + " '" + path + "': ";
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) return Result::failure(prefix + errnoText(errno));
  if (S_ISDIR(st.st_mode)) return Result::failure(prefix + "it is a directory");
  if (!S_ISREG(st.st_mode)) return Result::failure(prefix + "not a regular file");
  if (static_cast<uint64_t>(st.st_size) > max_bytes)
    return Result::failure(prefix + std::to_string(st.st_size) + " bytes, more than the " +
                           std::to_string(max_bytes) + " accepted");
  try {
    std::ifstream in(path, std::ios::binary);
    if (!in) return Result::failure(prefix + errnoText(errno));
    std::ostringstream buffer;
    buffer << in.rdbuf();
    if (in.bad()) return Result::failure(prefix + "read error");
    return buffer.str();
  } catch (const std::exception& e) {
    return Result::failure(prefix + e.what());
  }
}

}  // namespace board_calib
