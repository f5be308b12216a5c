#include "veneer/io/file_crc.hpp"

#include <cerrno>
#include <cstring>
#include <vector>

#include <fcntl.h>
#include <unistd.h>

#include <libdeflate.h>

namespace veneer::io {

uint32_t crc32(std::string_view bytes, uint32_t crc) {
  return static_cast<uint32_t>(libdeflate_crc32(crc, bytes.data(), bytes.size()));
}

Expected<uint32_t> file_crc32(const std::filesystem::path& path, uint64_t offset, uint64_t length) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return make_error(path.string() + ": cannot open: " + std::strerror(errno));
  std::vector<char> buf(1 << 20);
  uint32_t crc = 0;
  uint64_t done = 0;
  while (done < length) {
    const size_t want = static_cast<size_t>(std::min<uint64_t>(buf.size(), length - done));
    const ssize_t n = ::pread(fd, buf.data(), want, static_cast<off_t>(offset + done));
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      const std::string why = n < 0 ? std::strerror(errno) : "shorter than " + std::to_string(offset + length) + " bytes";
      ::close(fd);
      return make_error(path.string() + ": cannot read: " + why);
    }
    crc = crc32(std::string_view(buf.data(), static_cast<size_t>(n)), crc);
    done += static_cast<uint64_t>(n);
  }
  ::close(fd);
  return crc;
}

}  // namespace veneer::io
