#include "file_util.hpp"

#include <atomic>
#include <cerrno>
#include <cstring>

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

namespace veneer::io::detail {
namespace fs = std::filesystem;

namespace {
std::string errno_text(int err) { return std::strerror(err); }
}  // namespace

Expected<MappedFile> MappedFile::open(const fs::path& file) {
  const int fd = ::open(file.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) {
    const int err = errno;
    if (err == ENOENT) return make_error(file.string() + ": file not found");
    return make_error(file.string() + ": cannot open: " + errno_text(err));
  }
  struct stat st {};
  if (::fstat(fd, &st) != 0 || !S_ISREG(st.st_mode)) {
    ::close(fd);
    return make_error(file.string() + (S_ISDIR(st.st_mode) ? ": is a folder, expected a file" : ": not a regular file"));
  }
  const size_t size = static_cast<size_t>(st.st_size);
  if (size == 0) {
    ::close(fd);
    return MappedFile(nullptr, 0);
  }
  void* data = ::mmap(nullptr, size, PROT_READ, MAP_PRIVATE | MAP_POPULATE, fd, 0);
  const int err = errno;
  ::close(fd);
  if (data == MAP_FAILED) return make_error(file.string() + ": cannot map: " + errno_text(err));
  return MappedFile(data, size);
}

MappedFile::MappedFile(MappedFile&& other) noexcept : data_(other.data_), size_(other.size_) {
  other.data_ = nullptr;
  other.size_ = 0;
}

MappedFile::~MappedFile() {
  if (data_) ::munmap(data_, size_);
}

Status write_file_synced(const fs::path& file, std::string_view bytes, bool sync) {
  int fd = ::open(file.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) return make_error(file.string() + ": cannot create: " + errno_text(errno));
  size_t done = 0;
  while (done < bytes.size()) {
    ssize_t n = ::write(fd, bytes.data() + done, bytes.size() - done);
    if (n < 0) {
      if (errno == EINTR) continue;
      int err = errno;
      ::close(fd);
      return make_error(file.string() + ": write failed after " + std::to_string(done) + " bytes: " +
                        errno_text(err));
    }
    done += static_cast<size_t>(n);
  }
  if (sync && ::fsync(fd) != 0) {
    int err = errno;
    ::close(fd);
    return make_error(file.string() + ": fsync failed: " + errno_text(err));
  }
  if (::close(fd) != 0) return make_error(file.string() + ": close failed: " + errno_text(errno));
  return Status::success();
}

Status fsync_dir(const fs::path& folder) {
  fs::path dir = folder.empty() ? fs::path(".") : folder;
  int fd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (fd < 0) return make_error(dir.string() + ": cannot open folder to sync: " + errno_text(errno));
  int rc = ::fsync(fd);
  int err = errno;
  ::close(fd);
  // Some file systems do not support fsync on folders; that is not a failure of ours.
  if (rc != 0 && err != EINVAL && err != EROFS) return make_error(dir.string() + ": fsync failed: " + errno_text(err));
  return Status::success();
}

fs::path temp_sibling(const fs::path& target, const char* kind) {
  static std::atomic<unsigned> counter{0};
  fs::path parent = target.parent_path();
  // Built by appends: gcc 12 -O3 misreports operator+ chains here (-Wrestrict).
  std::string name(".");
  name.append(target.filename().string()).append(".").append(kind).append("-");
  name.append(std::to_string(::getpid())).append("-").append(std::to_string(counter.fetch_add(1)));
  return parent / name;
}

long temp_sibling_pid(const fs::path& target, const std::string& candidate, const char* kind) {
  std::string prefix(".");
  prefix.append(target.filename().string()).append(".").append(kind).append("-");
  if (candidate.rfind(prefix, 0) != 0) return -1;
  std::string rest = candidate.substr(prefix.size());
  size_t dash = rest.find('-');
  if (dash == std::string::npos || dash == 0 || dash > 12) return -1;
  long pid = 0;
  for (size_t i = 0; i < dash; ++i) {
    if (rest[i] < '0' || rest[i] > '9') return -1;
    pid = pid * 10 + (rest[i] - '0');
  }
  return pid;
}

}  // namespace veneer::io::detail
