// The PTP/IP twin's server: it accepts initiators, pairs their command and
// event connections, and runs each transaction (Cmd Request [-> data phase]
// -> Cmd Response), dispatching to the camera (ptpip_camera.cpp).
#include "ptpip_twin_impl.hpp"

#include <fcntl.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

#include "veneer/util/log.hpp"

namespace veneerd {

using namespace ptpip;

void PtpipTwin::Impl::shutdown_locked(int fd) {
  if (fd >= 0 && open_fds.count(fd)) ::shutdown(fd, SHUT_RDWR);
}

void PtpipTwin::Impl::drop_locked(Connection* c, bool stay_off, const char* why) {
  if (!c) return;
  if (stay_off) on = false;
  ++stats.drops;
  VLOG_INFO(kLog, "dropping connection {} ({}){}", c->id, why, stay_off ? "; switched off" : "");
  shutdown_locked(c->cmd_fd);
  std::lock_guard el(c->evt_mu);
  shutdown_locked(c->evt_fd);
}

void PtpipTwin::Impl::accept_loop() {
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

void PtpipTwin::Impl::serve(int fd) {
  auto first = read_packet(fd);
  if (!first) return;
  if (first->type == kInitCommandRequest) return command_connection(fd, first->payload);
  if (first->type == kInitEventRequest) return event_connection(fd, first->payload);
  VLOG_WARN(kLog, "a connection opened with packet type {}, not an Init Command/Event Request; closing it",
            first->type);
}

void PtpipTwin::Impl::init_fail(int fd, const char* why) {
  VLOG_INFO(kLog, "refusing a connection: {}", why);
  Out o;
  o.u32(0x0000200F);  // the reason: access denied
  write_packet(fd, kInitFail, o.bytes());
}

void PtpipTwin::Impl::command_connection(int fd, const std::vector<uint8_t>& request) {
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

void PtpipTwin::Impl::event_connection(int fd, const std::vector<uint8_t>& request) {
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

bool PtpipTwin::Impl::send_event(Connection& c, uint16_t code, uint32_t tid, const std::vector<uint32_t>& params) {
  Out o;
  o.u16(code).u32(tid);
  for (auto p : params) o.u32(p);
  std::lock_guard el(c.evt_mu);
  if (c.evt_fd < 0) return false;
  return write_packet(c.evt_fd, kEvent, o.bytes());
}

// Start Data, Data..., End Data. With `stop_after` < n only that many bytes
// go out (the unplug halfway through a download).
bool PtpipTwin::Impl::send_data(int fd, uint32_t tid, const uint8_t* p, size_t n, size_t stop_after) {
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

bool PtpipTwin::Impl::send_response(int fd, uint16_t code, uint32_t tid, const std::vector<uint32_t>& params) {
  Out o;
  o.u16(code).u32(tid);
  for (auto p : params) o.u32(p);
  return write_packet(fd, kCmdResponse, o.bytes());
}

// The data phase the initiator sends (SetDevicePropValue).
std::optional<std::vector<uint8_t>> PtpipTwin::Impl::receive_data(int fd, uint32_t tid) {
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

bool PtpipTwin::Impl::transaction(Connection& c, const std::vector<uint8_t>& req) {
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

}  // namespace veneerd
