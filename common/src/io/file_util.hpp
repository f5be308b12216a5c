#pragma once
// Small POSIX file helpers shared by the io module (not part of the public API).
#include <filesystem>
#include <string>
#include <string_view>

#include "veneer/util/expected.hpp"

namespace veneer::io::detail {

// A file's bytes mapped read-only (prefaulted from the page cache in one
// call), for decoders that read a whole file once: no copy into a buffer of
// our own, whose fresh pages would each cost a fault. Empty files map to an
// empty view.
class MappedFile {
 public:
  static Expected<MappedFile> open(const std::filesystem::path& file);
  MappedFile(MappedFile&& other) noexcept;
  MappedFile& operator=(MappedFile&&) = delete;
  MappedFile(const MappedFile&) = delete;
  ~MappedFile();
  std::string_view bytes() const { return {static_cast<const char*>(data_), size_}; }

 private:
  MappedFile(void* data, size_t size) : data_(data), size_(size) {}
  void* data_ = nullptr;
  size_t size_ = 0;
};

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

}  // namespace veneer::io::detail
