#include "veneerd/server.hpp"

#include <array>
#include <cstring>
#include <chrono>
#include <deque>
#include <fstream>
#include <mutex>
#include <optional>
#include <set>
#include <thread>

#include <asio.hpp>
#include <asio/ssl.hpp>
#include <openssl/ssl.h>
#if defined(__GLIBC__)
#include <malloc.h>
#endif

#include <google/protobuf/stubs/logging.h>

#include "veneer/proto/framing.hpp"
#include "veneer/util/log.hpp"
#include "veneer/v1/rig.pb.h"
#include "veneerd/api.hpp"
#include "veneerd/preview.hpp"

namespace veneerd {

namespace pb = veneer::v1;
namespace fs = std::filesystem;
using asio::ip::tcp;
using Clock = std::chrono::steady_clock;

namespace {

// protobuf logs an ERROR line for every string field that is not UTF-8 it
// refuses to parse; a peer could fill the log with them. The server answers
// such a request itself (refuse_invalid_utf8), so protobuf's lines go to the
// debug level.
void quiet_protobuf_log() {
  static std::once_flag once;
  std::call_once(once, [] {
    google::protobuf::SetLogHandler([](google::protobuf::LogLevel level, const char* file, int line,
                                       const std::string& message) {
      if (level >= google::protobuf::LOGLEVEL_FATAL) {
        VLOG_ERROR("Server", "protobuf {}:{}: {}", file, line, message);
      } else {
        VLOG_DEBUG("Server", "protobuf {}:{}: {}", file, line, message);
      }
    });
  });
}

bool same_token(const std::string& a, const std::string& b) {
  // Constant time in the token's length: no early exit on the first mismatch.
  unsigned char diff = a.size() == b.size() ? 0 : 1;
  for (size_t i = 0; i < a.size(); ++i) diff |= static_cast<unsigned char>(a[i] ^ (i < b.size() ? b[i] : 0));
  return diff == 0 && !b.empty();
}

}  // namespace

class Session;

struct Server::Impl : std::enable_shared_from_this<Server::Impl> {
  Rig& rig;
  ServerOptions opt;
  asio::io_context io;
  asio::ssl::context ssl_ctx{asio::ssl::context::tls_server};  // TLS 1.3 only, the rig's certificate (unused in plain TCP)
  tcp::acceptor acceptor{io};
  std::thread thread;
  uint16_t bound_port = 0;
  bool dual_stack = false;  // bound to "::" and taking IPv4 too

  // I/O thread only:
  std::set<std::shared_ptr<Session>> sessions;
  std::weak_ptr<Session> controller;
  uint64_t event_seq = 0;
  AuthThrottle throttle{opt.auth};
  asio::steady_timer auth_log_timer{io};
  bool auth_log_armed = false;
  asio::steady_timer release_timer{io};
  bool release_pending = false;

  mutable std::mutex stats_mutex;
  ServerStats stats;

  Impl(Rig& r, ServerOptions o) : rig(r), opt(std::move(o)) {}
  void accept();
  void on_event(const RigEvent& e);
  void on_live(std::shared_ptr<const LiveFrameData> frame);
  void update_live_rate();
  void wrong_token(const std::string& peer, const std::string& key, const std::string& client_name);
  void check_auth_log();
  void release_memory_soon();
  void count(uint64_t ServerStats::*field) {
    std::lock_guard lock(stats_mutex);
    ++(stats.*field);
  }
  void add(uint64_t ServerStats::*field, uint64_t n) {
    std::lock_guard lock(stats_mutex);
    stats.*field += n;
  }
};

// One client connection. Lives on the I/O thread.
class Session : public std::enable_shared_from_this<Session> {
 public:
  Session(Server::Impl& server, tcp::socket socket)
      : srv_(server), stream_(std::move(socket), server.ssl_ctx), tls_(!server.opt.plain_tcp),
        hello_timer_(server.io), close_timer_(server.io), turn_timer_(server.io) {
    std::error_code ec;
    auto ep = sock().remote_endpoint(ec);
    peer_ = ec ? "?" : ep.address().to_string() + ":" + std::to_string(ep.port());
    peer_key_ = ec ? "?" : AuthThrottle::peer_key(ep.address().to_string());
    sock().set_option(tcp::no_delay(true), ec);
  }

  void start() {
    auto self = shared_from_this();
    // The hello's 10 s run from the TCP connection: a TLS handshake that does not end counts against them.
    hello_timer_.expires_after(std::chrono::duration_cast<Clock::duration>(
        std::chrono::duration<double>(srv_.opt.hello_timeout_s)));
    hello_timer_.async_wait([self](std::error_code ec) {
      if (!ec && !self->authed_) {
        VLOG_INFO("Server", "{}: no hello in time, closing", self->peer_);
        self->close();
      }
    });
    if (!tls_) {
      read();
      return;
    }
    stream_.async_handshake(asio::ssl::stream_base::server, [self](std::error_code ec) {
      if (self->closed_) return;
      if (ec) {
        // Not TLS 1.3 (an old client, a plain-TCP client, a scanner): closed without a word.
        VLOG_DEBUG("Server", "{}: TLS handshake failed: {}", self->peer_, ec.message());
        self->srv_.count(&ServerStats::tls_handshake_failures);
        self->close();
        return;
      }
      self->read();
    });
  }

  const std::string& peer() const { return peer_; }
  bool authed() const { return authed_; }
  double live_fps() const { return live_fps_; }

  // Sends a message. Droppable messages (live frames) are skipped while the
  // queue is long; anything else overflowing the queue drops the client.
  bool send(const pb::RigMessage& m, bool droppable = false) {
    if (closed_) return false;
    if (droppable && queued_ > srv_.opt.live_queue_bytes) return false;
    return send_encoded(std::make_shared<const std::string>(veneer::wire::encode_delimited(m)), droppable);
  }
  // The same with the message already encoded (shared by every client it goes to).
  bool send_encoded(std::shared_ptr<const std::string> bytes, bool droppable = false) {
    if (closed_) return false;
    if (droppable && queued_ > srv_.opt.live_queue_bytes) return false;
    if (bytes->empty()) return false;
    if (queued_ + bytes->size() > srv_.opt.max_queue_bytes) {
      VLOG_WARN("Server", "{}: client too slow ({} bytes waiting), disconnecting", peer_, queued_);
      close();
      return false;
    }
    queued_ += bytes->size();
    queue_.push_back(std::move(bytes));
    write();
    return true;
  }

  void respond(uint64_t id, const veneer::Status& status) {
    settle_control(id, status.ok());
    pb::RigMessage m;
    auto* r = m.mutable_response();
    r->set_id(id);
    r->set_ok(status.ok());
    if (!status) r->set_error(status.message());
    send(m);
  }

  bool wants_live() const { return authed_ && live_fps_ > 0 && !closed_; }

  // `encoded` is the frame's RigMessage, encoded once for every client.
  void offer_live(const std::shared_ptr<const std::string>& encoded) {
    if (!wants_live()) return;
    auto now = Clock::now();
    if (now - last_frame_ < std::chrono::duration<double>(0.9 / live_fps_)) return;
    if (send_encoded(encoded, true)) {
      last_frame_ = now;
      srv_.count(&ServerStats::live_frames_sent);
    } else {
      srv_.count(&ServerStats::live_frames_dropped);
    }
  }

  void close() {
    if (closed_) return;
    closed_ = true;
    std::error_code ec;
    hello_timer_.cancel();
    close_timer_.cancel();
    turn_timer_.cancel();
    sock().shutdown(tcp::socket::shutdown_both, ec);
    sock().close(ec);
    const bool held_much = queued_ > (64u << 10) || fetch_ || live_fps_ > 0 || sent_bytes_ > (4u << 20);
    queue_.clear();
    queued_ = 0;
    fetch_.reset();
    if (held_much) srv_.release_memory_soon();
    auto self = shared_from_this();
    srv_.sessions.erase(self);
    if (srv_.controller.lock() == self) {
      srv_.controller.reset();
      VLOG_INFO("Server", "{}: controller left", peer_);
    }
    if (live_fps_ > 0) {
      live_fps_ = 0;
      srv_.update_live_rate();
    }
    // Connections that never said hello come and go without a line each (a
    // stream of wrong tokens is summed up by the throttle instead).
    if (authed_) {
      VLOG_INFO("Server", "{}: connection closed", peer_);
    } else {
      VLOG_DEBUG("Server", "{}: connection closed", peer_);
    }
  }

 private:
  // Sends what is queued, then closes (after a protocol error or refused
  // hello). `quiet`: logged at debug level only (wrong tokens are summed up).
  void close_after_flush(uint64_t id, const std::string& error, bool quiet = false) {
    srv_.count(&ServerStats::protocol_errors);
    if (quiet) {
      VLOG_DEBUG("Server", "{}: {}; closing", peer_, error);
    } else {
      VLOG_WARN("Server", "{}: {}; closing", peer_, error);
    }
    respond(id, veneer::make_error(error));
    closing_ = true;
    fetch_.reset();
    auto self = shared_from_this();
    close_timer_.expires_after(std::chrono::seconds(2));
    close_timer_.async_wait([self](std::error_code ec) {
      if (!ec) self->close();
    });
    if (queue_.empty()) close();
  }

  tcp::socket& sock() { return stream_.next_layer(); }

  void read() {
    auto self = shared_from_this();
    auto done = [self](std::error_code ec, size_t n) {
      if (self->closed_) return;
      if (ec) {
        self->close();
        return;
      }
      self->in_.feed(self->rbuf_.data(), n);
      self->serve_buffered();
    };
    if (tls_) {
      stream_.async_read_some(asio::buffer(rbuf_), std::move(done));
    } else {
      sock().async_read_some(asio::buffer(rbuf_), std::move(done));
    }
  }

  // Serves the whole messages received, in order, then reads on; while a
  // hello waits for its turn (wrong tokens from this address before), what
  // follows it waits too.
  void serve_buffered() {
    for (;;) {
      if (closing_ || closed_ || hello_waiting_) return;
      pb::ClientMessage msg;
      auto r = in_.next(msg);
      if (r == veneer::wire::ReadResult::need_more) break;
      if (r == veneer::wire::ReadResult::error) {
        close_after_flush(0, "bad message stream: " + in_.error());
        return;
      }
      if (r == veneer::wire::ReadResult::invalid) {
        refuse_invalid_utf8(in_.invalid());
        continue;
      }
      handle(msg);
    }
    if (!closing_ && !closed_ && !hello_waiting_) read();
  }

  void write() {
    if (writing_ || queue_.empty() || closed_) return;
    writing_ = true;
    auto self = shared_from_this();
    auto bytes = queue_.front();
    auto done = [self, bytes](std::error_code ec, size_t) {
      self->writing_ = false;
      if (self->closed_) return;
      if (ec) {
        self->close();
        return;
      }
      self->queued_ -= bytes->size();
      self->sent_bytes_ += bytes->size();
      self->queue_.pop_front();
      if (self->closing_ && self->queue_.empty()) {
        self->close();
        return;
      }
      self->pump_fetch();
      self->write();
    };
    if (tls_) {
      asio::async_write(stream_, asio::buffer(*bytes), std::move(done));
    } else {
      asio::async_write(sock(), asio::buffer(*bytes), std::move(done));
    }
  }

  // ---- requests

  // A request whose string field is not UTF-8 (proto3 cannot parse it): refused
  // like any bad field; before hello it is a refused hello.
  void refuse_invalid_utf8(const veneer::wire::InvalidUtf8& bad) {
    const std::string why = bad.field + ": not valid UTF-8 (every string field is UTF-8)";
    if (!authed_) {
      close_after_flush(bad.id, bad.field.rfind("hello.", 0) == 0
                                    ? "hello refused: " + why
                                    : "the first request must be a hello with the protocol version and token");
      return;
    }
    srv_.count(&ServerStats::protocol_errors);
    VLOG_INFO("Server", "{}: refused request {}: {}", peer_, bad.id, why);
    respond(bad.id, veneer::make_error(why));
  }

  void handle(const pb::ClientMessage& msg) {
    auto req = api::decode(msg);
    if (!authed_) {
      if (!req && msg.has_hello()) {  // a hello, but a bad one: say what was wrong with it
        close_after_flush(msg.id(), "hello refused: " + req.message());
        return;
      }
      if (!req || !std::holds_alternative<api::Hello>(req->body)) {
        close_after_flush(msg.id(), "the first request must be a hello with the protocol version and token");
        return;
      }
    }
    if (!req) {
      srv_.count(&ServerStats::protocol_errors);
      VLOG_INFO("Server", "{}: refused request {}: {}", peer_, msg.id(), req.message());
      respond(msg.id(), req.error());
      return;
    }
    const uint64_t id = req->id;
    if (api::needs_control(req->body)) {
      auto holder = srv_.controller.lock();
      if (holder && holder.get() != this) {
        respond(id, veneer::make_error(std::string(api::request_name(req->body)) + ": another client (" +
                                       holder->peer() + ") controls the rig; this connection may only watch"));
        return;
      }
      if (!holder) {
        // Taken by this request; given back if the request is refused.
        srv_.controller = shared_from_this();
        taking_control_ = id;
        VLOG_INFO("Server", "{}: now controls the rig", peer_);
      } else {
        taking_control_.reset();  // a controller using its control keeps it
      }
    }
    std::visit([&](auto& body) { on(id, body); }, req->body);
  }

  // The request `id` is answered. If it took control and was refused, control
  // goes back to being free, as if the request had not been made.
  void settle_control(uint64_t id, bool ok) {
    if (!taking_control_ || *taking_control_ != id) return;
    taking_control_.reset();
    if (ok || srv_.controller.lock().get() != this) return;
    srv_.controller.reset();
    VLOG_INFO("Server", "{}: request refused, control is free again", peer_);
  }

  void on(uint64_t id, api::Hello& h) {
    if (authed_ || hello_waiting_) {
      respond(id, veneer::make_error("hello: already said"));
      return;
    }
    if (h.protocol_version != veneer::wire::kProtocolVersion) {
      close_after_flush(id, "hello: protocol version " + std::to_string(h.protocol_version) +
                                " is not supported (the rig speaks " +
                                std::to_string(veneer::wire::kProtocolVersion) + ")");
      return;
    }
    hello_timer_.cancel();
    const auto now = Clock::now();
    auto turn = srv_.throttle.admit(peer_key_, now);
    if (!turn) {
      close_after_flush(id, "hello: too many hellos from " + peer_key_ +
                                " are waiting after wrong access tokens; try again later", true);
      return;
    }
    if (*turn <= now) {
      check_hello(id, h);
      return;
    }
    // Wrong tokens came from this address before: the answer waits for its turn.
    hello_waiting_ = true;
    turn_timer_.expires_at(*turn);
    turn_timer_.async_wait([self = shared_from_this(), id, h](std::error_code ec) {
      self->srv_.throttle.left_queue(self->peer_key_);
      if (ec || self->closed_) return;
      self->hello_waiting_ = false;
      self->check_hello(id, h);
      self->serve_buffered();
    });
  }

  void check_hello(uint64_t id, const api::Hello& h) {
    // Surrounding whitespace is not part of the token: the token file ends
    // with a newline, and a client may send the file's bytes as they are.
    const std::string token = api::trim_token(h.token);
    if (!same_token(token, srv_.opt.token)) {
      srv_.wrong_token(peer_, peer_key_, h.client_name);
      close_after_flush(id, token.empty() ? "hello: no access token given" : "hello: wrong access token", true);
      return;
    }
    srv_.throttle.succeeded(peer_key_);
    authed_ = true;
    client_name_ = h.client_name;
    VLOG_INFO("Server", "{}: hello from '{}'", peer_, client_name_);
    send_status(id);
  }

  // The reply to request `id`: ok, with the rig's status.
  void send_status(uint64_t id) {
    pb::RigMessage m;
    auto* r = m.mutable_response();
    r->set_id(id);
    r->set_ok(true);
    fill_status(*r->mutable_status());
    send(m);
  }

  void fill_status(pb::RigStatus& s) {
    RigState st = srv_.rig.state();
    s.set_protocol_version(veneer::wire::kProtocolVersion);
    s.set_rig_name(st.name);
    s.set_simulated(st.simulated);
    s.set_camera_connected(st.camera_connected);
    s.set_camera_model(st.camera_model);
    s.set_lamp_count(static_cast<uint32_t>(st.lamp_count));
    for (bool on : st.lamps_on) s.add_lamps_on(on);
    for (std::size_t i = 0; i < st.lamps.size(); ++i) {
      const LampState& l = st.lamps[i];
      auto* r = s.add_lamps();
      r->set_id(i < st.lamp_ids.size() ? st.lamp_ids[i] : std::to_string(i + 1));
      r->set_on(l.on);
      r->set_brightness(static_cast<uint32_t>(l.brightness));
      r->set_colour_mode(colour_mode_name(l.mode));
      r->set_x(l.x);
      r->set_y(l.y);
      r->set_ct(static_cast<uint32_t>(l.ct));
      r->set_hue(static_cast<uint32_t>(l.hue));
      r->set_sat(static_cast<uint32_t>(l.sat));
      r->set_reachable(l.reachable);
    }
    s.set_lamps_age_s(st.lamps_age_s);
    s.set_lamps_problem(st.lamps_problem);
    s.set_holds_lamps(st.holds_lamps);
    s.set_ready(st.camera_connected && st.lamps_problem.empty() && st.lamps_age_s >= 0);
    s.set_capturing(st.capturing);
    auto holder = srv_.controller.lock();
    s.set_you_control(holder.get() == this);
    s.set_controller_taken(holder != nullptr);
    s.set_sets_stored(static_cast<uint32_t>(srv_.rig.store().list().size()));
    s.set_next_role(st.next_role == veneer::io::Role::source ? pb::ROLE_SOURCE : pb::ROLE_DESTINATION);
    s.set_free_bytes(srv_.rig.store().free_bytes());
    s.set_clients(static_cast<uint32_t>(srv_.sessions.size()));
    // Events are numbered and sent on this thread: every event up to this seq
    // was sent before this status, every later one comes after it.
    s.set_event_seq(srv_.event_seq);
    s.set_plain_tcp(srv_.opt.plain_tcp);
  }

  void on(uint64_t id, api::StatusReq&) { send_status(id); }

  void on(uint64_t id, api::ListSetsReq& l) {
    pb::RigMessage m;
    auto* r = m.mutable_response();
    r->set_id(id);
    r->set_ok(true);
    auto* list = r->mutable_sets();
    for (const auto& s : l.trash ? srv_.rig.store().trash() : srv_.rig.store().list())
      api::encode_set(s, *list->add_sets());
    send(m);
  }

  void on(uint64_t id, api::GetManifestReq& g) {
    auto text = srv_.rig.store().manifest(g.set_id);
    if (!text) {
      respond(id, text.error());
      return;
    }
    pb::RigMessage m;
    auto* r = m.mutable_response();
    r->set_id(id);
    r->set_ok(true);
    r->mutable_manifest()->set_set_id(g.set_id);
    r->mutable_manifest()->set_json(*text);
    send(m);
  }

  void on(uint64_t id, api::FetchImagesReq& f) {
    if (fetch_) {
      respond(id, veneer::make_error("fetch_images: a download is already running on this connection"));
      return;
    }
    std::vector<std::string> skipped;
    auto files = set_files(srv_.rig.store(), f.set_id, f.include_truth, f.skip_files, &skipped);
    if (!files) {
      respond(id, files.error());
      return;
    }
    const auto resumed = resume_files(*files, f.resume_from);
    start_download("fetch_images", id, f.set_id, f.chunk_size, std::move(*files), skipped, resumed);
  }

  void on(uint64_t id, api::FetchPreviewReq& f) {
    if (fetch_) {
      respond(id, veneer::make_error("fetch_preview: a download is already running on this connection"));
      return;
    }
    auto files = preview_files(srv_.rig.store(), f.set_id);
    if (!files) {
      respond(id, files.error());
      return;
    }
    start_download("fetch_preview", id, f.set_id, f.chunk_size, std::move(*files), {});
  }

  void start_download(const char* what, uint64_t id, const std::string& set_id, size_t chunk,
                      std::vector<ServedFile> files, const std::vector<std::string>& skipped,
                      const std::vector<api::ResumeFrom>& resumed = {}) {
    // Open every file now: a set deleted mid-download still downloads whole.
    auto fetch = std::make_unique<Fetch>();
    fetch->request_id = id;
    fetch->set_id = set_id;
    fetch->chunk = chunk;
    uint64_t total = 0;
    for (auto& file : files) {
      FetchFile f{file.rel, nullptr, file.size, std::make_shared<std::string>(std::move(file.bytes)), file.start};
      if (!file.source.empty()) {
        f.in = std::make_unique<std::ifstream>(file.source, std::ios::binary);
        if (*f.in) f.in->seekg(static_cast<std::streamoff>(file.offset + file.start));
        if (!*f.in) {
          respond(id, veneer::make_error(std::string(what) + ": cannot read " + set_id + "/" + file.rel));
          return;
        }
      }
      total += file.size - file.start;
      fetch->files.push_back(std::move(f));
    }
    pb::RigMessage m;
    auto* r = m.mutable_response();
    r->set_id(id);
    r->set_ok(true);
    auto* started = r->mutable_fetch();
    started->set_set_id(set_id);
    for (const auto& f : fetch->files) started->add_files(f.rel);
    for (const auto& s : skipped) started->add_skipped_files(s);
    for (const auto& from : resumed) {
      auto* r2 = started->add_resumed();
      r2->set_file(from.file);
      r2->set_offset(from.offset);
      r2->set_crc32(from.crc32);
    }
    started->set_total_bytes(total);
    send(m);
    VLOG_INFO("Server", "{}: {} of {} ({} files, {} bytes) started", peer_, what, set_id, fetch->files.size(), total);
    if (!fetch->files.empty()) fetch->offset = fetch->files.front().start;
    fetch_ = std::move(fetch);
    pump_fetch();
  }

  void pump_fetch() {
    while (fetch_ && !closed_ && !closing_ && queued_ < srv_.opt.fetch_queue_bytes) {
      Fetch& f = *fetch_;
      FetchFile& file = f.files[f.index];
      api::ChunkHeader h;
      h.request_id = f.request_id;
      h.set_id = f.set_id;
      h.file = file.rel;
      h.offset = f.offset;
      h.file_size = file.size;
      const size_t want = static_cast<size_t>(std::min<uint64_t>(f.chunk, file.size - f.offset));
      h.last = f.offset + want >= file.size;
      h.end_of_set = h.last && f.index + 1 == f.files.size();
      auto bytes = std::make_shared<std::string>();
      const uint64_t at = f.offset;
      bool read_ok = api::encode_chunk(h, want, [&file, at](char* dst, size_t n) {
        if (!file.in) {  // made for the download
          if (at + n > file.made->size()) return false;
          std::memcpy(dst, file.made->data() + at, n);
          return true;
        }
        file.in->read(dst, static_cast<std::streamsize>(n));
        return static_cast<size_t>(file.in->gcount()) == n;
      }, *bytes);
      if (!read_ok) {
        VLOG_ERROR("Server", "{}: reading {}/{} failed mid-download", peer_, f.set_id, file.rel);
        close();
        return;
      }
      srv_.add(&ServerStats::chunk_bytes, want);
      f.offset += want;
      if (h.last) {
        ++f.index;
        f.offset = f.index < f.files.size() ? f.files[f.index].start : 0;
      }
      if (h.end_of_set) {
        VLOG_INFO("Server", "{}: download of {} sent", peer_, f.set_id);
        fetch_.reset();
        srv_.release_memory_soon();
      }
      send_encoded(std::move(bytes));
    }
  }

  void on(uint64_t id, api::DeleteSetReq& d) { respond(id, srv_.rig.delete_set(d.set_id)); }

  void on(uint64_t id, api::CaptureReq& c) {
    auto set_id = srv_.rig.capture(c.capture);
    if (!set_id) {
      respond(id, set_id.error());
      return;
    }
    settle_control(id, true);
    pb::RigMessage m;
    auto* r = m.mutable_response();
    r->set_id(id);
    r->set_ok(true);
    r->set_capture_set_id(*set_id);
    send(m);
  }

  void on(uint64_t id, api::CancelReq&) { respond(id, srv_.rig.cancel()); }

  void on(uint64_t id, api::SetLampsReq& l) {
    std::weak_ptr<Session> weak = shared_from_this();
    Server::Impl* srv = &srv_;
    srv_.rig.set_lamps(l.on, l.brightness, [weak, srv, id](veneer::Status s) {
      asio::post(srv->io, [weak, id, s] {
        if (auto self = weak.lock()) self->respond(id, s);
      });
    });
  }

  void on(uint64_t id, api::StartLiveReq& l) {
    live_fps_ = l.fps;
    last_frame_ = Clock::time_point{};
    srv_.update_live_rate();
    respond(id, {});
  }

  void on(uint64_t id, api::StopLiveReq&) {
    live_fps_ = 0;
    srv_.update_live_rate();
    respond(id, {});
  }

  void on(uint64_t id, api::PressReq& p) {
    if (!srv_.rig.options().simulated) {
      respond(id, veneer::make_error("press_button: only the simulated rig has a button to press remotely"));
      return;
    }
    respond(id, {});
    srv_.rig.press(p.long_press ? Press::long_press : Press::short_press);
  }

  void on(uint64_t id, api::MoveHandLampReq& h) { respond(id, srv_.rig.move_hand_lamp(h.position)); }
  void on(uint64_t id, api::RestoreSetReq& r) { respond(id, srv_.rig.restore_set(r.set_id)); }

  struct FetchFile {
    std::string rel;
    std::unique_ptr<std::ifstream> in;  // positioned at the range's start; null: `made` is the content
    uint64_t size = 0;
    std::shared_ptr<std::string> made;
    uint64_t start = 0;  // the first byte sent (a resumed file)
  };
  struct Fetch {
    uint64_t request_id = 0;
    std::string set_id;
    std::vector<FetchFile> files;
    size_t index = 0;
    uint64_t offset = 0;
    size_t chunk = 0;
  };

  Server::Impl& srv_;
  asio::ssl::stream<tcp::socket> stream_;  // in plain TCP only its socket is used
  const bool tls_;
  asio::steady_timer hello_timer_;
  asio::steady_timer close_timer_;
  asio::steady_timer turn_timer_;  // a hello waiting for its turn (AuthThrottle)
  std::string peer_;
  std::string peer_key_;  // the address as the throttle counts it
  bool hello_waiting_ = false;
  std::optional<uint64_t> taking_control_;  // the request that took control, until it is answered
  std::string client_name_;
  std::array<char, 64 * 1024> rbuf_{};
  veneer::wire::FrameBuffer in_;
  std::deque<std::shared_ptr<const std::string>> queue_;
  size_t queued_ = 0;
  uint64_t sent_bytes_ = 0;  // a busy connection's end is a moment to release memory
  bool writing_ = false;
  bool closing_ = false;
  bool closed_ = false;
  bool authed_ = false;
  double live_fps_ = 0;
  Clock::time_point last_frame_{};
  std::unique_ptr<Fetch> fetch_;
};

void Server::Impl::accept() {
  // Handlers hold the Impl weakly: one left in the stopped io_context (which the
  // Impl owns) must not keep the Impl alive, or neither is ever freed.
  acceptor.async_accept([weak = weak_from_this()](std::error_code ec, tcp::socket socket) {
    auto self = weak.lock();
    if (!self) return;
    if (ec) {
      if (ec != asio::error::operation_aborted) {
        VLOG_WARN("Server", "accept failed: {}", ec.message());
        self->accept();
      }
      return;
    }
    auto session = std::make_shared<Session>(*self, std::move(socket));
    self->sessions.insert(session);
    self->count(&ServerStats::connections);
    VLOG_DEBUG("Server", "{}: connected", session->peer());  // "hello from" says who, once authenticated
    session->start();
    self->accept();
  });
}

void Server::Impl::on_event(const RigEvent& e) {
  pb::RigMessage m;
  api::encode_event(e, ++event_seq, m);
  auto bytes = std::make_shared<const std::string>(veneer::wire::encode_delimited(m));
  auto copy = sessions;  // a send may close (and erase) a session
  for (const auto& s : copy) {
    if (s->authed()) s->send_encoded(bytes);
  }
}

void Server::Impl::on_live(std::shared_ptr<const LiveFrameData> frame) {
  auto copy = sessions;
  std::shared_ptr<const std::string> bytes;  // encoded once, only if someone watches
  for (const auto& s : copy) {
    if (!s->wants_live()) continue;
    if (!bytes) {
      pb::RigMessage m;
      auto* lf = m.mutable_frame();
      lf->set_jpeg(frame->jpeg.data(), frame->jpeg.size());
      lf->set_seq(frame->seq);
      lf->set_ts(frame->ts);
      lf->set_width(static_cast<uint32_t>(frame->width));
      lf->set_height(static_cast<uint32_t>(frame->height));
      bytes = std::make_shared<const std::string>(veneer::wire::encode_delimited(m));
    }
    s->offer_live(bytes);
  }
}

void Server::Impl::update_live_rate() {
  double fps = 0;
  for (const auto& s : sessions) fps = std::max(fps, s->live_fps());
  rig.set_live_fps(fps);
  if (fps == 0) release_memory_soon();
}

void Server::Impl::wrong_token(const std::string& peer, const std::string& key, const std::string& client_name) {
  count(&ServerStats::wrong_tokens);
  if (throttle.failed(key, Clock::now())) {
    const auto& a = throttle.options();
    VLOG_WARN("Server",
              "{}: wrong access token (client '{}'); more are summed up in one line; an address gets {} answers at "
              "once, then one per {} s doubling to one per {} s",
              peer, client_name, a.free_failures, a.first_delay_s, a.max_delay_s);
  }
  check_auth_log();
}

// Logs the summary of a burst of wrong tokens when it is due, and comes back
// while the burst is open.
void Server::Impl::check_auth_log() {
  if (auth_log_armed) return;
  std::optional<Clock::time_point> next;
  if (auto line = throttle.summary(Clock::now(), &next)) VLOG_WARN("Server", "{}", *line);
  if (!next) return;
  auth_log_armed = true;
  auth_log_timer.expires_at(*next);
  auth_log_timer.async_wait([weak = weak_from_this()](std::error_code ec) {
    auto self = weak.lock();
    if (!self || ec) return;
    self->auth_log_armed = false;
    self->check_auth_log();
  });
}

// Memory freed after a large transfer stays with the process: glibc keeps
// freed chunks of its arenas (one per thread that allocates: this one, the
// camera's, OpenCV's workers) for reuse, so the daemon's RSS would climb in
// steps with each new mix of downloads and live view and never come down.
// Once things go quiet, hand the free pages back.
void Server::Impl::release_memory_soon() {
#if defined(__GLIBC__)
  if (release_pending) return;
  release_pending = true;
  release_timer.expires_after(std::chrono::duration_cast<Clock::duration>(
      std::chrono::duration<double>(opt.release_memory_delay_s)));
  release_timer.async_wait([weak = weak_from_this()](std::error_code ec) {
    auto self = weak.lock();
    if (!self || ec) return;
    self->release_pending = false;
    auto t0 = Clock::now();
    ::malloc_trim(0);
    self->count(&ServerStats::memory_releases);
    VLOG_DEBUG("Server", "freed memory handed back to the system in {:.1f} ms",
               std::chrono::duration<double, std::milli>(Clock::now() - t0).count());
  });
#endif
}

Server::Server(Rig& rig, ServerOptions options) : impl_(std::make_shared<Impl>(rig, std::move(options))) {
  std::weak_ptr<Impl> weak = impl_;
  rig.on_event = [weak](const RigEvent& e) {
    if (auto impl = weak.lock())
      asio::post(impl->io, [weak, e] {
        if (auto i = weak.lock()) i->on_event(e);
      });
  };
  rig.on_live_frame = [weak](std::shared_ptr<const LiveFrameData> f) {
    if (auto impl = weak.lock())
      asio::post(impl->io, [weak, f] {
        if (auto i = weak.lock()) i->on_live(f);
      });
  };
}

Server::~Server() { stop(); }

veneer::Status Server::start() {
  quiet_protobuf_log();
  std::error_code ec;
  if (!impl_->opt.plain_tcp) {
    // TLS 1.3 and nothing older; no session tickets (every connection shows
    // the certificate, so a client always sees the fingerprint it pins).
    SSL_CTX* ctx = impl_->ssl_ctx.native_handle();
    SSL_CTX_set_min_proto_version(ctx, TLS1_3_VERSION);
    SSL_CTX_set_max_proto_version(ctx, TLS1_3_VERSION);
    SSL_CTX_set_num_tickets(ctx, 0);
    SSL_CTX_set_session_cache_mode(ctx, SSL_SESS_CACHE_OFF);
    impl_->ssl_ctx.use_certificate_chain_file(impl_->opt.tls_cert_file, ec);
    if (ec) return veneer::make_error("TLS certificate " + impl_->opt.tls_cert_file + ": " + ec.message());
    impl_->ssl_ctx.use_private_key_file(impl_->opt.tls_key_file, asio::ssl::context::pem, ec);
    if (ec) return veneer::make_error("TLS key " + impl_->opt.tls_key_file + ": " + ec.message());
  }
  auto address = asio::ip::make_address(impl_->opt.host, ec);
  if (ec) return veneer::make_error("listen address '" + impl_->opt.host + "': " + ec.message());
  tcp::endpoint ep(address, impl_->opt.port);
  auto& acc = impl_->acceptor;
  acc.open(ep.protocol(), ec);
  if (!ec) acc.set_option(tcp::acceptor::reuse_address(true), ec);
  if (!ec && address.is_v6() && address.is_unspecified()) {
    // "::" is every address: take IPv4 too, whatever net.ipv6.bindv6only says.
    std::error_code v6ec;
    acc.set_option(asio::ip::v6_only(false), v6ec);
    impl_->dual_stack = !v6ec;
    if (v6ec) VLOG_WARN("Server", "listening on [::] for IPv6 only: {}", v6ec.message());
  }
  if (!ec) acc.bind(ep, ec);
  if (!ec) acc.listen(asio::socket_base::max_listen_connections, ec);
  if (ec) {
    return veneer::make_error("cannot listen on " + impl_->opt.host + ":" + std::to_string(impl_->opt.port) + ": " +
                              ec.message());
  }
  impl_->bound_port = acc.local_endpoint().port();
  impl_->accept();
  impl_->thread = std::thread([impl = impl_] {
    for (;;) {
      try {
        impl->io.run();
        return;
      } catch (const std::exception& e) {
        // A handler threw (e.g. out of memory): log, keep serving.
        VLOG_ERROR("Server", "I/O handler failed: {}", e.what());
      }
    }
  });
  VLOG_INFO("Server", "listening on {}:{} ({})", impl_->opt.host, impl_->bound_port,
            impl_->opt.plain_tcp ? "PLAIN TCP, not encrypted: configured so" : "TLS 1.3");
  return {};
}

void Server::stop() {
  if (!impl_->thread.joinable()) return;
  asio::post(impl_->io, [impl = impl_] {
    std::error_code ec;
    impl->acceptor.close(ec);
    auto copy = impl->sessions;
    for (const auto& s : copy) s->close();
    impl->auth_log_timer.cancel();
    impl->release_timer.cancel();
    impl->io.stop();
  });
  impl_->thread.join();
}

uint16_t Server::port() const { return impl_->bound_port; }
bool Server::dual_stack() const { return impl_->dual_stack; }

ServerStats Server::stats() const {
  std::lock_guard lock(impl_->stats_mutex);
  return impl_->stats;
}

}  // namespace veneerd
