// The PTP/IP camera twin (see ptpip_twin.hpp).
//
// Wire format (ISO 15740 Annex / CIPA DC-005, little endian): every packet is
// u32 length (including these 8 bytes), u32 type, payload. The initiator opens
// the command connection (Init Command Request -> Ack with a connection
// number), then the event connection (Init Event Request with that number ->
// Ack). A transaction is Cmd Request [-> Start Data, Data..., End Data] ->
// Cmd Response on the command connection; events flow on the event connection.
#include "veneerd/devices/ptpip_twin.hpp"

#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <pthread.h>
#include <signal.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <ctime>
#include <list>
#include <ostream>
#include <sstream>
#include <map>
#include <mutex>
#include <optional>
#include <set>
#include <thread>

#include <opencv2/imgcodecs.hpp>

#include "veneer/util/log.hpp"
#include "veneerd/devices/simulated_camera.hpp"

namespace veneerd {

namespace {

constexpr const char* kLog = "PtpipTwin";

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

uint16_t get16(const uint8_t* p) { return uint16_t(p[0] | (p[1] << 8)); }
uint32_t get32(const uint8_t* p) { return uint32_t(p[0]) | (uint32_t(p[1]) << 8) | (uint32_t(p[2]) << 16) | (uint32_t(p[3]) << 24); }

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

struct Packet {
  uint32_t type = 0;
  std::vector<uint8_t> payload;
};

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

std::string ptp_date_now() {
  std::time_t t = std::time(nullptr);
  std::tm tm{};
  gmtime_r(&t, &tm);
  char buf[32];
  std::strftime(buf, sizeof buf, "%Y%m%dT%H%M%S", &tm);
  return buf;
}

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

}  // namespace

veneer::Status PtpipTwinOptions::check() const {
  in_addr a{};
  if (inet_pton(AF_INET, host.c_str(), &a) != 1)
    return veneer::make_error("PTP/IP twin: host '" + host + "' is not an IPv4 address");
  if (!shot) return veneer::make_error("PTP/IP twin: no shot source given");
  if (exposure_times.empty() || f_numbers.empty() || isos.empty())
    return veneer::make_error("PTP/IP twin: every exposure setting needs at least one offered value");
  auto has = [](const auto& v, auto x) { return std::find(v.begin(), v.end(), x) != v.end(); };
  if (!has(exposure_times, initial.exposure_time) || !has(f_numbers, initial.f_number) || !has(isos, initial.iso))
    return veneer::make_error("PTP/IP twin: the initial exposure is not among the offered values");
  return {};
}

struct PtpipTwin::Impl {
  PtpipTwinOptions opt;
  int listen_fd = -1;
  int wake[2] = {-1, -1};
  uint16_t port = 0;
  std::thread acceptor;

  mutable std::mutex mu;  // everything below
  bool stopping = false, on = true;
  std::set<int> open_fds;  // sockets being served (only these may be shut down)
  struct Worker {
    std::thread thread;
    std::shared_ptr<std::atomic<bool>> done;
  };
  std::list<Worker> workers;
  std::shared_ptr<Connection> current;
  uint32_t next_connection = 1;
  PtpipExposure exposure;
  uint32_t enabled_streams = 0;
  std::map<uint32_t, Object> card;
  uint32_t next_handle = 1;
  std::vector<PtpipFile> files;
  std::vector<std::pair<uint16_t, uint32_t>> writes;
  PtpipTwinStats stats;
  int drop_capture_in = 0, drop_download_in = 0;  // countdowns; 0 = none
  bool drop_capture_off = false, drop_download_off = false;

  // --- sockets ------------------------------------------------------------
  void shutdown_locked(int fd) {
    if (fd >= 0 && open_fds.count(fd)) ::shutdown(fd, SHUT_RDWR);
  }
  void drop_locked(Connection* c, bool stay_off, const char* why) {
    if (!c) return;
    if (stay_off) on = false;
    ++stats.drops;
    VLOG_INFO(kLog, "dropping connection {} ({}){}", c->id, why, stay_off ? "; switched off" : "");
    shutdown_locked(c->cmd_fd);
    std::lock_guard el(c->evt_mu);
    shutdown_locked(c->evt_fd);
  }

  void accept_loop() {
    for (;;) {
      pollfd p[2] = {{listen_fd, POLLIN, 0}, {wake[0], POLLIN, 0}};
      int r = ::poll(p, 2, -1);
      if (r < 0 && errno == EINTR) continue;
      if (r < 0 || (p[1].revents & POLLIN)) return;
      if (!(p[0].revents & POLLIN)) continue;
      int fd = ::accept4(listen_fd, nullptr, nullptr, SOCK_CLOEXEC);
      if (fd < 0) continue;
      int one = 1;
      ::setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
      std::lock_guard lock(mu);
      if (stopping) {
        ::close(fd);
        return;
      }
      // Reap finished connection threads.
      for (auto it = workers.begin(); it != workers.end();) {
        if (it->done->load()) {
          it->thread.join();
          it = workers.erase(it);
        } else {
          ++it;
        }
      }
      open_fds.insert(fd);
      auto done = std::make_shared<std::atomic<bool>>(false);
      workers.push_back({std::thread([this, fd, done] {
                           serve(fd);
                           {
                             std::lock_guard l(mu);
                             open_fds.erase(fd);
                           }
                           ::close(fd);
                           done->store(true);
                         }),
                         done});
    }
  }

  void serve(int fd) {
    auto first = read_packet(fd);
    if (!first) return;
    if (first->type == kInitCommandRequest) return command_connection(fd, first->payload);
    if (first->type == kInitEventRequest) return event_connection(fd, first->payload);
    VLOG_WARN(kLog, "a connection opened with packet type {}, not an Init Command/Event Request; closing it",
              first->type);
  }

  void init_fail(int fd, const char* why) {
    VLOG_INFO(kLog, "refusing a connection: {}", why);
    Out o;
    o.u32(0x0000200F);  // the reason: access denied
    write_packet(fd, kInitFail, o.bytes());
  }

  void command_connection(int fd, const std::vector<uint8_t>& request) {
    if (request.size() < 16 + 2) {
      VLOG_WARN(kLog, "Init Command Request of {} bytes is too short for a GUID and a name", request.size());
      return;
    }
    std::string host;
    for (size_t i = 16; i + 1 < request.size(); i += 2) {
      uint16_t c = get16(&request[i]);
      if (c == 0) break;
      host += c < 128 ? char(c) : '?';
    }
    auto conn = std::make_shared<Connection>();
    conn->cmd_fd = fd;
    {
      std::lock_guard lock(mu);
      if (!on) {
        ++stats.refused;
        init_fail(fd, "the camera is switched off");
        return;
      }
      conn->id = next_connection++;
      if (current) drop_locked(current.get(), false, "replaced by a new initiator");
      current = conn;
      ++stats.connections;
    }
    VLOG_INFO(kLog, "initiator '{}' connected (connection {})", host, conn->id);
    Out ack;
    ack.u32(conn->id);
    const char guid[17] = "VENEER-TWIN-0001";
    for (int i = 0; i < 16; ++i) ack.u8(uint8_t(guid[i]));
    for (char c : opt.friendly_name) ack.u16(static_cast<unsigned char>(c));
    ack.u16(0);
    ack.u32(0x00010000);  // protocol version 1.0
    bool alive = write_packet(fd, kInitCommandAck, ack.bytes());
    while (alive) {
      auto p = read_packet(fd);
      if (!p) break;
      switch (p->type) {
        case kCmdRequest:
          alive = transaction(*conn, p->payload);
          break;
        case kPing:
          alive = write_packet(fd, kPong, nullptr, 0);
          break;
        case kCancel:
          VLOG_DEBUG(kLog, "Cancel Transaction received; nothing is in flight");
          break;
        default:
          VLOG_WARN(kLog, "unexpected packet type {} on the command connection; ignored", p->type);
      }
    }
    std::lock_guard lock(mu);
    if (current == conn) {
      current.reset();
      std::lock_guard el(conn->evt_mu);
      shutdown_locked(conn->evt_fd);
    }
    VLOG_INFO(kLog, "connection {} closed", conn->id);
  }

  void event_connection(int fd, const std::vector<uint8_t>& request) {
    if (request.size() < 4) return;
    uint32_t id = get32(request.data());
    std::shared_ptr<Connection> conn;
    {
      std::lock_guard lock(mu);
      if (!on) {
        ++stats.refused;
        init_fail(fd, "the camera is switched off");
        return;
      }
      if (!current || current->id != id) {
        init_fail(fd, "Init Event Request names no open command connection");
        return;
      }
      conn = current;
      std::lock_guard el(conn->evt_mu);
      conn->evt_fd = fd;
      if (!write_packet(fd, kInitEventAck, nullptr, 0)) return;
    }
    while (auto p = read_packet(fd)) {
      if (p->type == kPing) {
        std::lock_guard el(conn->evt_mu);
        write_packet(fd, kPong, nullptr, 0);
      }
    }
    std::lock_guard el(conn->evt_mu);
    if (conn->evt_fd == fd) conn->evt_fd = -1;
  }

  bool send_event(Connection& c, uint16_t code, uint32_t tid, const std::vector<uint32_t>& params) {
    Out o;
    o.u16(code).u32(tid);
    for (auto p : params) o.u32(p);
    std::lock_guard el(c.evt_mu);
    if (c.evt_fd < 0) return false;
    return write_packet(c.evt_fd, kEvent, o.bytes());
  }

  // Start Data, Data..., End Data. With `stop_after` < n only that many bytes
  // go out (the unplug halfway through a download).
  static bool send_data(int fd, uint32_t tid, const uint8_t* p, size_t n, size_t stop_after = SIZE_MAX) {
    Out start;
    start.u32(tid).u64(n);
    if (!write_packet(fd, kStartData, start.bytes())) return false;
    size_t sent = 0;
    do {
      size_t k = std::min(kDataChunk, n - sent);
      bool cut = sent + k > stop_after;
      if (cut) k = stop_after - sent;
      bool last = !cut && sent + k == n;
      std::vector<uint8_t> b(4 + k);
      b[0] = uint8_t(tid), b[1] = uint8_t(tid >> 8), b[2] = uint8_t(tid >> 16), b[3] = uint8_t(tid >> 24);
      if (k) std::memcpy(b.data() + 4, p + sent, k);
      if (!write_packet(fd, last ? kEndData : kData, b) || cut) return false;
      sent += k;
    } while (sent < n);
    return true;
  }

  static bool send_response(int fd, uint16_t code, uint32_t tid, const std::vector<uint32_t>& params) {
    Out o;
    o.u16(code).u32(tid);
    for (auto p : params) o.u32(p);
    return write_packet(fd, kCmdResponse, o.bytes());
  }

  // The data phase the initiator sends (SetDevicePropValue).
  static std::optional<std::vector<uint8_t>> receive_data(int fd, uint32_t tid) {
    auto start = read_packet(fd);
    if (!start || start->type != kStartData || start->payload.size() < 8 || get32(start->payload.data()) != tid) {
      VLOG_WARN(kLog, "expected a Start Data packet for transaction {}", tid);
      return std::nullopt;
    }
    uint64_t total = get32(&start->payload[4]) | (start->payload.size() >= 12 ? uint64_t(get32(&start->payload[8])) << 32 : 0);
    if (total > kMaxPacket) return std::nullopt;
    std::vector<uint8_t> data;
    for (;;) {
      auto p = read_packet(fd);
      if (!p || (p->type != kData && p->type != kEndData) || p->payload.size() < 4) return std::nullopt;
      data.insert(data.end(), p->payload.begin() + 4, p->payload.end());
      if (data.size() > total) return std::nullopt;
      if (p->type == kEndData) break;
    }
    if (data.size() != total) {
      VLOG_WARN(kLog, "data phase of transaction {} carried {} bytes, announced {}", tid, data.size(), total);
      return std::nullopt;
    }
    return data;
  }

  // --- transactions -------------------------------------------------------
  bool transaction(Connection& c, const std::vector<uint8_t>& req) {
    if (req.size() < 10) {
      VLOG_WARN(kLog, "Cmd Request of {} bytes is too short", req.size());
      return false;
    }
    const uint32_t dataphase = get32(&req[0]);
    const uint16_t code = get16(&req[4]);
    const uint32_t tid = get32(&req[6]);
    std::vector<uint32_t> params;
    for (size_t i = 10; i + 4 <= req.size() && params.size() < 5; i += 4) params.push_back(get32(&req[i]));
    auto param = [&](size_t i) { return i < params.size() ? params[i] : 0u; };
    std::vector<uint8_t> in;
    if (dataphase == 2) {
      auto d = receive_data(c.cmd_fd, tid);
      if (!d) return false;
      in = std::move(*d);
    }
    VLOG_DEBUG(kLog, "op 0x{:04x} tid {} params {}", code, tid, params.size());

    if (code != op::get_device_info && code != op::open_session && !c.session_open)
      return send_response(c.cmd_fd, rc::session_not_open, tid, {});

    Reply r;
    switch (code) {
      case op::get_device_info:
        r.has_data = true;
        r.data = device_info();
        break;
      case op::open_session:
        if (param(0) == 0) r.code = rc::invalid_parameter;
        else if (c.session_open) r.code = rc::session_already_open;
        else {
          c.session_open = true;
          std::lock_guard lock(mu);
          ++stats.sessions;
        }
        break;
      case op::close_session:
        c.session_open = false;
        break;
      case op::get_storage_ids:
        r.has_data = true;
        r.data = Out().array32({kStorage}).bytes();
        break;
      case op::get_storage_info:
        if (param(0) != kStorage) r.code = rc::invalid_storage_id;
        else {
          r.has_data = true;
          Out o;
          o.u16(0x0004).u16(0x0002).u16(0x0000);  // removable RAM, generic hierarchical, read-write
          o.u64(32ull << 30).u64(31ull << 30).u32(0xFFFFFFFF).str("SD card").str("VENEER");
          r.data = std::move(o.bytes());
        }
        break;
      case op::get_num_objects:
      case op::get_object_handles: {
        std::vector<uint32_t> handles;
        r.code = list_objects(param(0), param(1), param(2), handles);
        if (r.code != rc::ok) break;
        if (code == op::get_num_objects) {
          r.params = {uint32_t(handles.size())};
        } else {
          r.has_data = true;
          r.data = Out().array32(handles).bytes();
        }
        break;
      }
      case op::get_object_info:
        r.code = object_info(param(0), r.data);
        r.has_data = r.code == rc::ok;
        break;
      case op::get_object:
        return get_object(c, tid, param(0));
      case op::delete_object:
        r.code = delete_object(param(0));
        break;
      case op::initiate_capture:
        return capture(c, tid, param(0), param(1));
      case op::get_device_prop_desc:
      case op::get_device_prop_value: {
        std::lock_guard lock(mu);
        r.code = property(param(0), code == op::get_device_prop_desc, r.data);
        r.has_data = r.code == rc::ok;
        break;
      }
      case op::set_device_prop_value: {
        r.code = set_property(uint16_t(param(0)), in);
        if (r.code == rc::ok) send_event(c, ev::device_prop_changed, 0xFFFFFFFF, {param(0)});
        break;
      }
      case op::get_stream_info:
        if (!opt.preview) r.code = rc::operation_not_supported;
        else if (param(0) != 1) r.code = rc::invalid_parameter;
        else {
          Out o;  // DatasetSize, TimeResolution, FrameHeaderSize, FrameMaxSize, PacketHeaderSize, PacketMaxSize, PacketAlignment
          o.u64(36).u64(1000000).u32(0).u32(16u << 20).u32(0).u32(16u << 20).u32(0);
          r.has_data = true;
          r.data = std::move(o.bytes());
        }
        break;
      case op::get_stream: {
        if (!opt.preview) {
          r.code = rc::operation_not_supported;
          break;
        }
        PtpipExposure e;
        {
          std::lock_guard lock(mu);
          e = exposure;
        }
        auto frame = opt.preview(e);
        if (!frame) {
          VLOG_WARN(kLog, "live-view frame failed: {}", frame.message());
          r.code = rc::general_error;
          break;
        }
        {
          std::lock_guard lock(mu);
          ++stats.stream_frames;
        }
        r.has_data = true;
        r.data = std::move(*frame);
        break;
      }
      default:
        VLOG_DEBUG(kLog, "operation 0x{:04x} is not supported", code);
        r.code = rc::operation_not_supported;
    }
    if (r.has_data && !send_data(c.cmd_fd, tid, r.data.data(), r.data.size())) return false;
    return send_response(c.cmd_fd, r.code, tid, r.params);
  }

  std::vector<uint8_t> device_info() const {
    std::vector<uint16_t> ops{op::get_device_info,    op::open_session,          op::close_session,
                              op::get_storage_ids,    op::get_storage_info,      op::get_num_objects,
                              op::get_object_handles, op::get_object_info,       op::get_object,
                              op::delete_object,      op::initiate_capture,      op::get_device_prop_desc,
                              op::get_device_prop_value, op::set_device_prop_value};
    std::vector<uint16_t> props{prop::f_number, prop::focus_mode, prop::exposure_time, prop::program,
                                prop::exposure_index};
    if (opt.preview) {
      ops.push_back(op::get_stream_info);
      ops.push_back(op::get_stream);
      props.push_back(prop::supported_streams);
      props.push_back(prop::enabled_streams);
    }
    Out o;
    o.u16(100).u32(0).u16(0).str("").u16(0);  // PTP 1.00, no vendor extension
    o.array16(ops);
    o.array16(std::vector<uint16_t>{ev::object_added, ev::device_prop_changed, ev::capture_complete});
    o.array16(props);
    o.array16(std::vector<uint16_t>{kFormatJpeg});
    o.array16(std::vector<uint16_t>{kFormatJpeg, kFormatAssociation});
    o.str(opt.manufacturer).str(opt.model).str("1.0").str(opt.serial);
    return std::move(o.bytes());
  }

  uint16_t list_objects(uint32_t storage, uint32_t format, uint32_t parent, std::vector<uint32_t>& out) {
    if (storage != kAll && storage != kStorage) return rc::invalid_storage_id;
    std::lock_guard lock(mu);
    if (parent != 0 && parent != kAll) {
      auto it = card.find(parent);
      if (it == card.end() || it->second.format != kFormatAssociation) return rc::invalid_parent;
    }
    for (const auto& [h, o] : card) {
      if (format != 0 && o.format != format) continue;
      if (parent == kAll && o.parent != 0) continue;
      if (parent != 0 && parent != kAll && o.parent != parent) continue;
      out.push_back(h);
    }
    return rc::ok;
  }

  uint16_t object_info(uint32_t handle, std::vector<uint8_t>& data) {
    std::lock_guard lock(mu);
    auto it = card.find(handle);
    if (it == card.end()) return rc::invalid_object_handle;
    const Object& ob = it->second;
    bool folder = ob.format == kFormatAssociation;
    Out o;
    o.u32(kStorage).u16(ob.format).u16(0).u32(ob.bytes ? uint32_t(ob.bytes->size()) : 0);
    o.u16(0).u32(0).u32(0).u32(0);  // no thumbnail
    o.u32(uint32_t(ob.width)).u32(uint32_t(ob.height)).u32(folder ? 0 : 24);
    o.u32(ob.parent).u16(folder ? 1 : 0).u32(0).u32(0);  // generic folder
    o.str(ob.name).str(ob.date).str(ob.date).str("");
    data = std::move(o.bytes());
    return rc::ok;
  }

  bool get_object(Connection& c, uint32_t tid, uint32_t handle) {
    std::shared_ptr<const std::vector<unsigned char>> bytes;
    size_t file = SIZE_MAX;
    bool drop = false, off = false;
    {
      std::lock_guard lock(mu);
      auto it = card.find(handle);
      if (it != card.end() && it->second.bytes) {
        bytes = it->second.bytes;
        file = it->second.file;
        if (drop_download_in > 0 && --drop_download_in == 0) {
          drop = true;
          off = drop_download_off;
        }
      }
    }
    if (!bytes) return send_response(c.cmd_fd, rc::invalid_object_handle, tid, {});
    if (drop) {
      send_data(c.cmd_fd, tid, bytes->data(), bytes->size(), bytes->size() / 2);
      std::lock_guard lock(mu);
      drop_locked(&c, off, "unplugged halfway through a download");
      return false;
    }
    if (!send_data(c.cmd_fd, tid, bytes->data(), bytes->size())) return false;
    {
      std::lock_guard lock(mu);
      ++stats.downloads;
      if (file < files.size()) ++files[file].downloads;
    }
    return send_response(c.cmd_fd, rc::ok, tid, {});
  }

  uint16_t delete_object(uint32_t handle) {
    std::lock_guard lock(mu);
    std::vector<uint32_t> gone;
    if (handle == kAll) {
      for (const auto& [h, o] : card)
        if (o.format != kFormatAssociation) gone.push_back(h);
    } else {
      auto it = card.find(handle);
      if (it == card.end()) return rc::invalid_object_handle;
      if (it->second.format == kFormatAssociation) return rc::object_write_protected;
      gone.push_back(handle);
    }
    for (uint32_t h : gone) {
      auto it = card.find(h);
      if (it->second.file < files.size()) files[it->second.file].deleted = true;
      card.erase(it);
      ++stats.deletes;
    }
    return rc::ok;
  }

  bool capture(Connection& c, uint32_t tid, uint32_t storage, uint32_t format) {
    if (storage != 0 && storage != kStorage) return send_response(c.cmd_fd, rc::invalid_storage_id, tid, {});
    if (format != 0 && format != kFormatJpeg) return send_response(c.cmd_fd, rc::invalid_object_format, tid, {});
    uint64_t shot = 0;
    PtpipExposure e;
    bool drop = false, off = false;
    {
      std::lock_guard lock(mu);
      shot = ++stats.captures;
      e = exposure;
      if (drop_capture_in > 0 && --drop_capture_in == 0) {
        drop = true;
        off = drop_capture_off;
      }
    }
    // The response comes at once; the shot is announced by events when it is
    // on the card (the initiator waits for those without a deadline).
    if (!send_response(c.cmd_fd, rc::ok, tid, {})) return false;
    if (drop) {
      std::lock_guard lock(mu);
      drop_locked(&c, off, "unplugged while exposing");
      return false;
    }
    auto jpeg = opt.shot(e, shot);
    if (!jpeg || jpeg->empty()) {
      // A camera that cannot deliver would leave the initiator waiting for
      // ObjectAdded forever; dropping the connection ends that wait.
      VLOG_ERROR(kLog, "shot {} could not be produced ({}); dropping the connection",
                 shot, jpeg ? std::string("empty image") : jpeg.message());
      std::lock_guard lock(mu);
      drop_locked(&c, false, "the shot source failed");
      return false;
    }
    uint32_t handle = 0;
    {
      std::lock_guard lock(mu);
      Object ob;
      ob.handle = handle = next_handle++;
      ob.parent = 2;  // DCIM/100VENER
      ob.format = kFormatJpeg;
      char name[32];
      std::snprintf(name, sizeof name, "IMG_%04u.JPG", unsigned(files.size() % 9999 + 1));
      ob.name = name;
      ob.date = ptp_date_now();
      auto size = jpeg_size(*jpeg);
      ob.width = size.first;
      ob.height = size.second;
      ob.bytes = std::make_shared<const std::vector<unsigned char>>(std::move(*jpeg));
      ob.file = files.size();
      PtpipFile f;
      f.handle = handle;
      f.name = ob.name;
      f.bytes = *ob.bytes;
      f.exposure = e;
      files.push_back(std::move(f));
      card.emplace(handle, std::move(ob));
    }
    VLOG_DEBUG(kLog, "shot {} on the card as handle {}", shot, handle);
    send_event(c, ev::object_added, tid, {handle});
    send_event(c, ev::capture_complete, tid, {});
    return true;
  }

  // GetDevicePropDesc (desc = true) or GetDevicePropValue.
  uint16_t property(uint32_t code, bool desc, std::vector<uint8_t>& data) const {
    Out o;
    auto enum16 = [&](uint16_t c, uint16_t value, uint16_t dflt, const std::vector<uint16_t>& offered) {
      if (!desc) return void(o.u16(value));
      o.u16(c).u16(dtc::uint16).u8(1).u16(dflt).u16(value).u8(2).u16(uint16_t(offered.size()));  // enumeration
      for (auto v : offered) o.u16(v);
    };
    auto enum32 = [&](uint16_t c, uint32_t value, uint32_t dflt, const std::vector<uint32_t>& offered) {
      if (!desc) return void(o.u32(value));
      o.u16(c).u16(dtc::uint32).u8(1).u32(dflt).u32(value).u8(2).u16(uint16_t(offered.size()));
      for (auto v : offered) o.u32(v);
    };
    switch (code) {
      case prop::exposure_time:
        enum32(prop::exposure_time, exposure.exposure_time, opt.initial.exposure_time, opt.exposure_times);
        break;
      case prop::f_number:
        enum16(prop::f_number, exposure.f_number, opt.initial.f_number, opt.f_numbers);
        break;
      case prop::exposure_index:
        enum16(prop::exposure_index, exposure.iso, opt.initial.iso, opt.isos);
        break;
      case prop::program:
        enum16(prop::program, exposure.program, opt.initial.program, {1, 2, 3, 4});
        break;
      case prop::focus_mode:
        enum16(prop::focus_mode, exposure.focus, opt.initial.focus, {1, 2});
        break;
      case prop::supported_streams:
      case prop::enabled_streams: {
        if (!opt.preview) return rc::device_prop_not_supported;
        bool supported = code == prop::supported_streams;
        uint32_t value = supported ? 1u : enabled_streams;  // bit 0: video
        if (!desc) {
          o.u32(value);
          break;
        }
        o.u16(uint16_t(code)).u16(dtc::uint32).u8(supported ? 0 : 1).u32(supported ? 1u : 0u).u32(value).u8(0);
        break;
      }
      default:
        return rc::device_prop_not_supported;
    }
    data = std::move(o.bytes());
    return rc::ok;
  }

  uint16_t set_property(uint16_t code, const std::vector<uint8_t>& in) {
    auto u16ok = [&] { return in.size() == 2; };
    auto u32ok = [&] { return in.size() == 4; };
    auto in_set = [](const auto& v, auto x) { return std::find(v.begin(), v.end(), x) != v.end(); };
    std::lock_guard lock(mu);
    uint32_t value = 0;
    switch (code) {
      case prop::exposure_time:
        if (!u32ok()) return rc::invalid_prop_format;
        value = get32(in.data());
        if (!in_set(opt.exposure_times, value)) return rc::invalid_prop_value;
        exposure.exposure_time = value;
        break;
      case prop::f_number:
      case prop::exposure_index:
      case prop::program:
      case prop::focus_mode: {
        if (!u16ok()) return rc::invalid_prop_format;
        uint16_t v = get16(in.data());
        value = v;
        if (code == prop::f_number) {
          if (!in_set(opt.f_numbers, v)) return rc::invalid_prop_value;
          exposure.f_number = v;
        } else if (code == prop::exposure_index) {
          if (!in_set(opt.isos, v)) return rc::invalid_prop_value;
          exposure.iso = v;
        } else if (code == prop::program) {
          if (v < 1 || v > 4) return rc::invalid_prop_value;
          exposure.program = v;
        } else {
          if (v < 1 || v > 2) return rc::invalid_prop_value;
          exposure.focus = v;
        }
        break;
      }
      case prop::enabled_streams:
        if (!opt.preview) return rc::device_prop_not_supported;
        if (!u32ok()) return rc::invalid_prop_format;
        value = get32(in.data());
        if (value > 1) return rc::invalid_prop_value;
        enabled_streams = value;
        break;
      case prop::supported_streams:
        return opt.preview ? rc::access_denied : rc::device_prop_not_supported;
      default:
        return rc::device_prop_not_supported;
    }
    writes.emplace_back(code, value);
    ++stats.property_sets;
    VLOG_DEBUG(kLog, "property 0x{:04x} = {}", code, value);
    return rc::ok;
  }
};

PtpipTwin::PtpipTwin(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}

veneer::Expected<std::unique_ptr<PtpipTwin>> PtpipTwin::start(PtpipTwinOptions options) {
  if (auto s = options.check(); !s) return s.error();
  auto impl = std::make_unique<Impl>();
  impl->opt = std::move(options);
  impl->exposure = impl->opt.initial;
  // The card: DCIM/100VENER, as a camera formats it.
  Object dcim;
  dcim.handle = 1;
  dcim.format = kFormatAssociation;
  dcim.name = "DCIM";
  dcim.date = ptp_date_now();
  Object folder = dcim;
  folder.handle = 2;
  folder.parent = 1;
  folder.name = "100VENER";
  impl->card.emplace(1, dcim);
  impl->card.emplace(2, folder);
  impl->next_handle = 3;

  int fd = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  if (fd < 0) return veneer::make_error(std::string("PTP/IP twin: socket: ") + std::strerror(errno));
  int one = 1;
  ::setsockopt(fd, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_port = htons(impl->opt.port);
  inet_pton(AF_INET, impl->opt.host.c_str(), &a.sin_addr);
  if (::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) < 0 || ::listen(fd, 8) < 0) {
    std::string e = std::strerror(errno);
    ::close(fd);
    return veneer::make_error("PTP/IP twin: cannot listen on " + impl->opt.host + ":" + std::to_string(impl->opt.port) +
                              ": " + e);
  }
  socklen_t len = sizeof a;
  ::getsockname(fd, reinterpret_cast<sockaddr*>(&a), &len);
  impl->listen_fd = fd;
  impl->port = ntohs(a.sin_port);
  if (::pipe2(impl->wake, O_CLOEXEC) < 0) {
    ::close(fd);
    return veneer::make_error(std::string("PTP/IP twin: pipe: ") + std::strerror(errno));
  }
  Impl* raw = impl.get();
  impl->acceptor = std::thread([raw] { raw->accept_loop(); });
  VLOG_INFO(kLog, "PTP/IP twin '{}' listening on {}:{}", raw->opt.model, raw->opt.host, raw->port);
  return std::unique_ptr<PtpipTwin>(new PtpipTwin(std::move(impl)));
}

PtpipTwin::~PtpipTwin() {
  Impl& m = *impl_;
  {
    std::lock_guard lock(m.mu);
    m.stopping = true;
    for (int fd : m.open_fds) ::shutdown(fd, SHUT_RDWR);
  }
  char b = 1;
  if (::write(m.wake[1], &b, 1) < 0) { /* the acceptor also stops on close below */ }
  if (m.acceptor.joinable()) m.acceptor.join();
  std::list<Impl::Worker> workers;
  {
    std::lock_guard lock(m.mu);
    for (int fd : m.open_fds) ::shutdown(fd, SHUT_RDWR);
    workers.swap(m.workers);
  }
  for (auto& w : workers) w.thread.join();
  ::close(m.listen_fd);
  ::close(m.wake[0]);
  ::close(m.wake[1]);
}

uint16_t PtpipTwin::port() const { return impl_->port; }

std::string PtpipTwin::gphoto2_port() const {
  return "ptpip:" + impl_->opt.host + ":" + std::to_string(impl_->port) + ":" + std::to_string(impl_->port);
}

PtpipExposure PtpipTwin::exposure() const {
  std::lock_guard lock(impl_->mu);
  return impl_->exposure;
}

std::vector<PtpipFile> PtpipTwin::files() const {
  std::lock_guard lock(impl_->mu);
  return impl_->files;
}

std::vector<std::string> PtpipTwin::files_on_card() const {
  std::lock_guard lock(impl_->mu);
  std::vector<std::string> out;
  for (const auto& [h, o] : impl_->card)
    if (o.format != kFormatAssociation) out.push_back(o.name);
  return out;
}

std::vector<std::pair<uint16_t, uint32_t>> PtpipTwin::property_writes() const {
  std::lock_guard lock(impl_->mu);
  return impl_->writes;
}

PtpipTwinStats PtpipTwin::stats() const {
  std::lock_guard lock(impl_->mu);
  return impl_->stats;
}

void PtpipTwin::drop_at(DropAt where, int k, bool stay_off) {
  std::lock_guard lock(impl_->mu);
  if (where == DropAt::capture) {
    impl_->drop_capture_in = std::max(k, 0);
    impl_->drop_capture_off = stay_off;
  } else {
    impl_->drop_download_in = std::max(k, 0);
    impl_->drop_download_off = stay_off;
  }
}

void PtpipTwin::drop_now() {
  std::lock_guard lock(impl_->mu);
  impl_->drop_locked(impl_->current.get(), false, "asked to");
}

void PtpipTwin::set_on(bool on) {
  std::lock_guard lock(impl_->mu);
  impl_->on = on;
  if (!on) impl_->drop_locked(impl_->current.get(), true, "switched off");
}

bool PtpipTwin::is_on() const {
  std::lock_guard lock(impl_->mu);
  return impl_->on;
}

// --- the simulator as a shot source ------------------------------------------

PtpipShotSource simulated_shot_source(std::shared_ptr<SimulatedCamera> camera, int quality) {
  quality = std::clamp(quality, 1, 100);
  return [camera, quality](const PtpipExposure& e, uint64_t) -> veneer::Expected<std::vector<unsigned char>> {
    if (auto s = camera->set_exposure({e.shutter_s(), e.aperture(), e.iso}); !s) return s.error();
    auto still = camera->capture();
    if (!still) return still.error();
    // Linear float BGR -> 8-bit sRGB, as a camera's JPEG engine delivers it.
    static const std::vector<uint8_t> lut = [] {
      std::vector<uint8_t> t(4096);
      for (int i = 0; i < 4096; ++i) {
        double v = i / 4095.0;
        double s = v <= 0.0031308 ? 12.92 * v : 1.055 * std::pow(v, 1 / 2.4) - 0.055;
        t[i] = uint8_t(std::lround(255.0 * s));
      }
      return t;
    }();
    cv::Mat linear = still->linear;
    if (linear.type() != CV_32FC3) linear.convertTo(linear, CV_32FC3);
    cv::Mat bgr8(linear.size(), CV_8UC3);
    for (int y = 0; y < linear.rows; ++y) {
      const auto* in = linear.ptr<cv::Vec3f>(y);
      auto* out = bgr8.ptr<cv::Vec3b>(y);
      for (int x = 0; x < linear.cols; ++x)
        for (int ch = 0; ch < 3; ++ch) out[x][ch] = lut[size_t(std::clamp(in[x][ch], 0.0f, 1.0f) * 4095.0f + 0.5f)];
    }
    std::vector<unsigned char> jpeg;
    if (!cv::imencode(".jpg", bgr8, jpeg, {cv::IMWRITE_JPEG_QUALITY, quality}))
      return veneer::make_error("PTP/IP twin: JPEG encoding of the simulated shot failed");
    return jpeg;
  };
}

PtpipPreviewSource simulated_preview_source(std::shared_ptr<SimulatedCamera> camera) {
  return [camera](const PtpipExposure&) { return camera->preview(); };
}

// --- `veneerd ptpip-twin` ------------------------------------------------------

int ptpip_twin_command(const std::vector<std::string>& args, std::ostream& out, std::ostream& err) {
  const char* usage =
      "usage: veneerd ptpip-twin --bridge HOST:PORT --key KEY --lamps ID,ID,... [--scene NAME]\n"
      "                          [--size WxH] [--listen HOST:PORT]\n"
      "A PTP/IP camera on the network for libgphoto2 (and veneerd's gphoto2 camera with\n"
      "\"port\": \"ptpip:HOST:PORT\"): each shot renders the simulated scene lit by the lamps\n"
      "the Hue bridge reports on (lamps in ring order). Live view through PTP streams.\n"
      "  --bridge   the Hue bridge (or emulator), host:port\n"
      "  --key      its user key\n"
      "  --lamps    Hue light ids in ring order, comma-separated\n"
      "  --scene    simulator scene (default bull)\n"
      "  --size     still and live-view size (default 1024x680)\n"
      "  --listen   IPv4 address and port to serve on (default 127.0.0.1:15740)\n"
      "Runs until SIGINT or SIGTERM.\n";
  nlohmann::json section = {{"scene", "bull"}};
  std::string listen = "127.0.0.1:15740";
  for (size_t i = 1; i < args.size(); ++i) {
    const std::string& a = args[i];
    if (a == "--help" || a == "-h") {
      out << usage;
      return 0;
    }
    if (i + 1 >= args.size() || a.rfind("--", 0) != 0) {
      err << "veneerd ptpip-twin: '" << a << "' " << (a.rfind("--", 0) == 0 ? "needs a value" : "is not an option")
          << "\n" << usage;
      return 2;
    }
    const std::string& v = args[++i];
    if (a == "--bridge") section["bridge"] = v;
    else if (a == "--key") section["key"] = v;
    else if (a == "--scene") section["scene"] = v;
    else if (a == "--listen") listen = v;
    else if (a == "--lamps") {
      nlohmann::json ids = nlohmann::json::array();
      std::stringstream in(v);
      for (std::string id; std::getline(in, id, ',');)
        if (!id.empty()) ids.push_back(id);
      section["lamps"] = ids;
    } else if (a == "--size") {
      int w = 0, h = 0;
      char x = 0;
      std::stringstream in(v);
      if (!(in >> w >> x >> h) || (x != 'x' && x != 'X')) {
        err << "veneerd ptpip-twin: --size '" << v << "': expected WxH, e.g. 1024x680\n";
        return 2;
      }
      section["size"] = {w, h};
      section["preview_size"] = {w, h};
    } else {
      err << "veneerd ptpip-twin: unknown option '" << a << "'\n" << usage;
      return 2;
    }
  }
  auto sim = SimulatedCameraOptions::from_json(section);
  if (!sim) {
    err << "veneerd ptpip-twin: " << sim.message() << "\n";
    return 2;
  }
  PtpipTwinOptions o;
  size_t colon = listen.rfind(':');
  int port = colon == std::string::npos ? -1 : std::atoi(listen.c_str() + colon + 1);
  if (colon == std::string::npos || port <= 0 || port > 65535) {
    err << "veneerd ptpip-twin: --listen '" << listen << "': expected HOST:PORT, e.g. 127.0.0.1:15740\n";
    return 2;
  }
  o.host = listen.substr(0, colon);
  o.port = uint16_t(port);
  auto camera = SimulatedCamera::create(*sim);
  if (!camera) {
    err << "veneerd ptpip-twin: " << camera.message() << "\n";
    return 1;
  }
  std::shared_ptr<SimulatedCamera> renderer(std::move(*camera));
  o.shot = simulated_shot_source(renderer);
  o.preview = simulated_preview_source(renderer);
  // The twin's threads inherit this mask; the signals are taken by sigwait below.
  sigset_t stop;
  sigemptyset(&stop);
  sigaddset(&stop, SIGINT);
  sigaddset(&stop, SIGTERM);
  pthread_sigmask(SIG_BLOCK, &stop, nullptr);
  auto twin = PtpipTwin::start(o);
  if (!twin) {
    err << "veneerd ptpip-twin: " << twin.message() << "\n";
    return 1;
  }
  out << "PTP/IP camera twin on " << o.host << ":" << (*twin)->port() << " (libgphoto2 port "
      << (*twin)->gphoto2_port() << "), scene " << sim->scene << "; Ctrl-C stops it" << std::endl;
  int sig = 0;
  sigwait(&stop, &sig);
  auto st = (*twin)->stats();
  out << "stopped: " << st.connections << " connection(s), " << st.captures << " capture(s), " << st.downloads
      << " download(s), " << st.stream_frames << " live-view frame(s)" << std::endl;
  return 0;
}

}  // namespace veneerd
