#pragma once
// PTP/IP as the camera twin speaks it (ISO 15740 Annex / CIPA DC-005, little
// endian): packet framing, the operation/response/event/property codes, a
// dataset writer, and what the twin keeps per object and per connection.
// Private to appliance/src/sim/ (ptpip_*.cpp).
#include <cstddef>
#include <cstdint>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <utility>
#include <vector>
#include <algorithm>

namespace veneerd::ptpip {

inline constexpr const char* kLog = "PtpipTwin";
// PTP/IP packet types.
enum PacketType : uint32_t {
  kInitCommandRequest = 1,
  kInitCommandAck = 2,
  kInitEventRequest = 3,
  kInitEventAck = 4,
  kInitFail = 5,
  kCmdRequest = 6,
  kCmdResponse = 7,
  kEvent = 8,
  kStartData = 9,
  kData = 10,
  kCancel = 11,
  kEndData = 12,
  kPing = 13,
  kPong = 14,
};

// PTP operation, response, event, property, type and format codes (ISO 15740).
namespace op {
constexpr uint16_t get_device_info = 0x1001, open_session = 0x1002, close_session = 0x1003,
                   get_storage_ids = 0x1004, get_storage_info = 0x1005, get_num_objects = 0x1006,
                   get_object_handles = 0x1007, get_object_info = 0x1008, get_object = 0x1009,
                   delete_object = 0x100B, initiate_capture = 0x100E, get_device_prop_desc = 0x1014,
                   get_device_prop_value = 0x1015, set_device_prop_value = 0x1016, get_stream_info = 0x1024,
                   get_stream = 0x1025;
}
namespace rc {
constexpr uint16_t ok = 0x2001, general_error = 0x2002, session_not_open = 0x2003, operation_not_supported = 0x2005,
                   invalid_storage_id = 0x2008, invalid_object_handle = 0x2009, device_prop_not_supported = 0x200A,
                   invalid_object_format = 0x200B, object_write_protected = 0x200D, access_denied = 0x200F,
                   invalid_parent = 0x201A, invalid_prop_format = 0x201B, invalid_prop_value = 0x201C,
                   invalid_parameter = 0x201D, session_already_open = 0x201E;
}
namespace ev {
constexpr uint16_t object_added = 0x4002, device_prop_changed = 0x4006, capture_complete = 0x400D;
}
namespace prop {
constexpr uint16_t f_number = 0x5007, focus_mode = 0x500A, exposure_time = 0x500D, program = 0x500E,
                   exposure_index = 0x500F, supported_streams = 0x5020, enabled_streams = 0x5021;
}
namespace dtc {
constexpr uint16_t uint16 = 0x0004, uint32 = 0x0006;
}
constexpr uint16_t kFormatAssociation = 0x3001, kFormatJpeg = 0x3801;
constexpr uint32_t kStorage = 0x00010001;
constexpr uint32_t kAll = 0xFFFFFFFF;
constexpr uint32_t kMaxPacket = 64u << 20;   // larger is not a packet we would accept
constexpr size_t kDataChunk = 256u << 10;    // bytes per Data packet of a data phase

// Little-endian dataset writer.
class Out {
 public:
  Out& u8(uint8_t v) {
    b_.push_back(v);
    return *this;
  }
  Out& u16(uint16_t v) { return u8(uint8_t(v)).u8(uint8_t(v >> 8)); }
  Out& u32(uint32_t v) { return u16(uint16_t(v)).u16(uint16_t(v >> 16)); }
  Out& u64(uint64_t v) { return u32(uint32_t(v)).u32(uint32_t(v >> 32)); }
  // PTP string: u8 count of UCS-2 units including the terminating 0; "" is a lone 0.
  Out& str(const std::string& s) {
    if (s.empty()) return u8(0);
    size_t n = std::min<size_t>(s.size(), 254);
    u8(uint8_t(n + 1));
    for (size_t i = 0; i < n; ++i) u16(static_cast<unsigned char>(s[i]));
    return u16(0);
  }
  template <class T>
  Out& array16(const std::vector<T>& v) {
    u32(uint32_t(v.size()));
    for (auto x : v) u16(uint16_t(x));
    return *this;
  }
  Out& array32(const std::vector<uint32_t>& v) {
    u32(uint32_t(v.size()));
    for (auto x : v) u32(x);
    return *this;
  }
  std::vector<uint8_t>& bytes() { return b_; }

 private:
  std::vector<uint8_t> b_;
};

inline uint16_t get16(const uint8_t* p) { return uint16_t(p[0] | (p[1] << 8)); }
inline uint32_t get32(const uint8_t* p) { return uint32_t(p[0]) | (uint32_t(p[1]) << 8) | (uint32_t(p[2]) << 16) | (uint32_t(p[3]) << 24); }



struct Packet {
  uint32_t type = 0;
  std::vector<uint8_t> payload;
};






struct Object {
  uint32_t handle = 0, parent = 0;  // parent 0 = the storage's root
  uint16_t format = kFormatJpeg;
  std::string name, date;
  std::shared_ptr<const std::vector<unsigned char>> bytes;
  int width = 0, height = 0;
  size_t file = SIZE_MAX;  // index into the files ever taken
};

// One initiator's connection pair.
struct Connection {
  uint32_t id = 0;
  int cmd_fd = -1;
  std::mutex evt_mu;  // evt_fd and writes to it
  int evt_fd = -1;
  bool session_open = false;  // used by the command thread only
};

struct Reply {
  uint16_t code = rc::ok;
  std::vector<uint32_t> params;
  bool has_data = false;
  std::vector<uint8_t> data;
  std::shared_ptr<const std::vector<unsigned char>> object;  // GetObject: served as is
};

bool read_exact(int fd, void* buf, size_t n);
bool write_all(int fd, const void* buf, size_t n);
// One packet; nullopt at the end of the stream or on a malformed length.
std::optional<Packet> read_packet(int fd);
bool write_packet(int fd, uint32_t type, const uint8_t* payload, size_t n);
bool write_packet(int fd, uint32_t type, const std::vector<uint8_t>& payload);
std::string ptp_date_now();
// Width and height from a JPEG's frame header; 0, 0 when there is none.
std::pair<int, int> jpeg_size(const std::vector<unsigned char>& d);

}  // namespace veneerd::ptpip
