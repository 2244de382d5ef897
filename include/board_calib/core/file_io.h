// File writing that never leaves a truncated file behind, and file reading that refuses what
// is not a regular file. Every result, session, rig, snippet and report file goes through here.
#pragma once

#include <board_calib/core/types.h>

#include <string>

namespace board_calib {

/// Larger than any session, result or rig file (a 200-view session is ~20 MB).
constexpr size_t kMaxTextFileBytes = size_t(1) << 28;

/// Writes `text` to `path` atomically: a temporary file in the same folder is written,
/// flushed and fsync'ed, then renamed over `path` (and the folder fsync'ed). On any failure
/// (no such folder, read-only, disk full, file-size limit, `path` a directory) the previous
/// file is left untouched, the temporary removed, and the reason names the path and the error.
Status writeFileAtomic(const std::string& path, const std::string& text);

/// Creates `dir` and its parents when missing. Fails when it cannot, or when `dir` exists but
/// is not a folder, with a reason "cannot create the <what> '<dir>': <why>".
Status createFolder(const std::string& dir, const std::string& what = "folder");

/// Reads a whole regular file. Refuses directories, devices and files larger than
/// `max_bytes`, with a reason naming the path: "cannot read <what> '<path>': <why>".
Expected<std::string> readTextFile(const std::string& path, const std::string& what = "file",
                                   size_t max_bytes = kMaxTextFileBytes);

}  // namespace board_calib
