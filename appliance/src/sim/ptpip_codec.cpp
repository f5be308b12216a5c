// PTP/IP packet framing and small codecs (see ptpip_codec.hpp).
#include "ptpip_codec.hpp"

#include <sys/socket.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <ctime>

#include "veneer/util/log.hpp"
#include "veneer/util/utc_time.hpp"

namespace veneerd::ptpip {

bool read_exact(int fd, void* buf, size_t n) {
  auto* p = static_cast<uint8_t*>(buf);
  while (n > 0) {
    ssize_t r = ::recv(fd, p, n, 0);
    if (r < 0 && errno == EINTR) continue;
    if (r <= 0) return false;
    p += r;
    n -= size_t(r);
  }
  return true;
}

bool write_all(int fd, const void* buf, size_t n) {
  const auto* p = static_cast<const uint8_t*>(buf);
  while (n > 0) {
    ssize_t r = ::send(fd, p, n, MSG_NOSIGNAL);
    if (r < 0 && errno == EINTR) continue;
    if (r <= 0) return false;
    p += r;
    n -= size_t(r);
  }
  return true;
}

// One packet; nullopt at the end of the stream or on a malformed length.
std::optional<Packet> read_packet(int fd) {
  uint8_t h[8];
  if (!read_exact(fd, h, sizeof h)) return std::nullopt;
  uint32_t len = get32(h);
  if (len < 8 || len > kMaxPacket) {
    VLOG_WARN(kLog, "packet length {} from the initiator is outside 8..{}; dropping the connection", len, kMaxPacket);
    return std::nullopt;
  }
  Packet p;
  p.type = get32(h + 4);
  p.payload.resize(len - 8);
  if (!p.payload.empty() && !read_exact(fd, p.payload.data(), p.payload.size())) return std::nullopt;
  return p;
}

bool write_packet(int fd, uint32_t type, const uint8_t* payload, size_t n) {
  std::vector<uint8_t> b;
  b.reserve(8 + n);
  Out h;
  h.u32(uint32_t(8 + n)).u32(type);
  b = std::move(h.bytes());
  b.insert(b.end(), payload, payload + n);
  return write_all(fd, b.data(), b.size());
}

bool write_packet(int fd, uint32_t type, const std::vector<uint8_t>& payload) {
  return write_packet(fd, type, payload.data(), payload.size());
}

std::string ptp_date_now() { return veneer::utc_now("%Y%m%dT%H%M%S"); }

// Width and height from a JPEG's frame header; 0, 0 when there is none.
std::pair<int, int> jpeg_size(const std::vector<unsigned char>& d) {
  size_t i = 2;
  if (d.size() < 4 || d[0] != 0xFF || d[1] != 0xD8) return {0, 0};
  while (i + 9 < d.size()) {
    if (d[i] != 0xFF) return {0, 0};
    uint8_t m = d[i + 1];
    if (m == 0xFF) {
      ++i;
      continue;
    }
    size_t len = (size_t(d[i + 2]) << 8) | d[i + 3];
    if (m >= 0xC0 && m <= 0xCF && m != 0xC4 && m != 0xC8 && m != 0xCC)
      return {(d[i + 7] << 8) | d[i + 8], (d[i + 5] << 8) | d[i + 6]};
    if (len < 2) return {0, 0};
    i += 2 + len;
  }
  return {0, 0};
}

}  // namespace veneerd::ptpip
