#pragma once
// Small POSIX file helpers shared by the io module (not part of the public API).
#include <filesystem>
#include <string>
#include <string_view>

#include "veneer/util/expected.hpp"

namespace veneer::io_detail {

// Writes `bytes` to `file` (created or truncated) and fsyncs it (unless
// told not to). No rename.
Status write_file_synced(const std::filesystem::path& file, std::string_view bytes, bool sync = true);
// fsyncs a folder so that names created, renamed or removed in it are durable.
Status fsync_dir(const std::filesystem::path& folder);
// "<folder>/.<name>.tmp-<pid>-<n>": a fresh temporary name beside `target`.
std::filesystem::path temp_sibling(const std::filesystem::path& target, const char* kind = "tmp");
// The pid encoded in a name made by temp_sibling for `target`, or -1.
long temp_sibling_pid(const std::filesystem::path& target, const std::string& candidate_name,
                      const char* kind = "tmp");

}  // namespace veneer::io_detail
