#include "veneer/rig/client.hpp"

#include <array>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <condition_variable>
#include <cstring>
#include <deque>
#include <fstream>
#include <map>
#include <mutex>
#include <thread>

#include <fcntl.h>
#include <unistd.h>

#include <asio.hpp>
#include <asio/ssl.hpp>
#include <openssl/ssl.h>
#include <openssl/x509.h>

#include "veneer/proto/framing.hpp"
#include "veneer/proto/tls.hpp"
#include "veneer/util/log.hpp"
#include "veneer/util/token_file.hpp"
#include "veneer/v1/rig.pb.h"

namespace veneer::rig {

namespace pb = veneer::v1;
namespace fs = std::filesystem;
using asio::ip::tcp;
using Clock = std::chrono::steady_clock;

Expected<Endpoint> Endpoint::parse(const std::string& text) {
  Endpoint e;
  std::string host = text;
  const auto colon = text.rfind(':');
  const auto bracket = text.find(']');
  const bool has_port = colon != std::string::npos &&
                        (bracket == std::string::npos ? text.find(':') == colon : colon > bracket);
  if (has_port) {
    host = text.substr(0, colon);
    std::string digits = text.substr(colon + 1);
    if (digits.empty() || digits.size() > 5 || digits.find_first_not_of("0123456789") != std::string::npos ||
        std::stol(digits) > 65535 || std::stol(digits) == 0) {
      return make_error("rig address '" + text + "': '" + digits + "' is not a port number");
    }
    e.port = static_cast<uint16_t>(std::stol(digits));
  }
  if (host.size() > 2 && host.front() == '[' && host.back() == ']') host = host.substr(1, host.size() - 2);
  if (!host.empty()) e.host = host;
  return e;
}

Expected<std::string> read_token_file(const fs::path& file) { return veneer::read_token_file(file); }

const char* event_name(Event::Kind kind) {
  switch (kind) {
    case Event::Kind::button_pressed: return "button_pressed";
    case Event::Kind::capture_started: return "capture_started";
    case Event::Kind::shot_taken: return "shot_taken";
    case Event::Kind::set_stored: return "set_stored";
    case Event::Kind::capture_failed: return "capture_failed";
    case Event::Kind::lamp_state: return "lamp_state";
    case Event::Kind::camera_connected: return "camera_connected";
    case Event::Kind::camera_lost: return "camera_lost";
    case Event::Kind::set_deleted: return "set_deleted";
    case Event::Kind::set_restored: return "set_restored";
  }
  return "?";
}

std::string describe(const Event& e) {
  std::string s = event_name(e.kind);
  switch (e.kind) {
    case Event::Kind::button_pressed: s += e.long_press ? " long" : " short"; break;
    case Event::Kind::capture_started:
      s += " " + e.set_id + " " + io::role_name(e.role) + " '" + e.object + "' " + std::to_string(e.n) + " shots";
      break;
    case Event::Kind::shot_taken: {
      char eta[32];
      std::snprintf(eta, sizeof eta, "%.1f", e.eta_s);
      s += " " + e.set_id + " " + std::to_string(e.k) + "/" + std::to_string(e.n) + " eta " + eta + " s";
      break;
    }
    case Event::Kind::set_stored:
      s += " " + e.set_id;
      for (const auto& w : e.warnings) s += " [warning: " + w + "]";
      break;
    case Event::Kind::capture_failed: s += " " + e.set_id + (e.cancelled ? " cancelled" : ": " + e.reason); break;
    case Event::Kind::lamp_state: {
      s += " ";
      for (bool on : e.lamps_on) s += on ? '1' : '0';
      s += " bri " + std::to_string(e.brightness);
      break;
    }
    case Event::Kind::camera_connected: s += " " + e.camera_model; break;
    case Event::Kind::camera_lost: s += " " + e.reason; break;
    case Event::Kind::set_deleted:
    case Event::Kind::set_restored: s += " " + e.set_id; break;
  }
  return s;
}

namespace {

io::Role from_wire(int role) {
  return role == pb::ROLE_DESTINATION ? io::Role::destination : role == pb::ROLE_SOURCE ? io::Role::source : io::Role::unknown;
}
pb::Role to_wire(io::Role role) {
  return role == io::Role::destination ? pb::ROLE_DESTINATION : role == io::Role::source ? pb::ROLE_SOURCE : pb::ROLE_UNSPECIFIED;
}

RigStatus convert(const pb::RigStatus& s) {
  RigStatus r;
  r.name = s.rig_name();
  r.simulated = s.simulated();
  r.camera_connected = s.camera_connected();
  r.camera_model = s.camera_model();
  r.lamp_count = static_cast<int>(s.lamp_count());
  r.lamps_on.assign(s.lamps_on().begin(), s.lamps_on().end());
  for (const auto& l : s.lamps()) {
    LampReading x;
    x.id = l.id();
    x.on = l.on();
    x.brightness = static_cast<int>(l.brightness());
    x.colour_mode = l.colour_mode();
    x.x = l.x();
    x.y = l.y();
    x.ct = static_cast<int>(l.ct());
    x.hue = static_cast<int>(l.hue());
    x.sat = static_cast<int>(l.sat());
    x.reachable = l.reachable();
    r.lamps.push_back(std::move(x));
  }
  r.lamps_age_s = s.lamps_age_s();
  r.lamps_problem = s.lamps_problem();
  r.holds_lamps = s.holds_lamps();
  r.ready = s.ready();
  r.event_seq = s.event_seq();
  r.capturing = s.capturing();
  r.you_control = s.you_control();
  r.controller_taken = s.controller_taken();
  r.sets_stored = static_cast<int>(s.sets_stored());
  r.next_role = from_wire(s.next_role());
  r.free_bytes = s.free_bytes();
  r.clients = static_cast<int>(s.clients());
  r.plain_tcp = s.plain_tcp();
  return r;
}

Event convert(const pb::Event& w) {
  Event e;
  e.seq = w.seq();
  switch (w.kind_case()) {
    case pb::Event::kButtonPressed:
      e.kind = Event::Kind::button_pressed;
      e.long_press = w.button_pressed().long_press();
      break;
    case pb::Event::kCaptureStarted:
      e.kind = Event::Kind::capture_started;
      e.set_id = w.capture_started().set_id();
      e.role = from_wire(w.capture_started().role());
      e.object = w.capture_started().object();
      e.n = static_cast<int>(w.capture_started().shots());
      break;
    case pb::Event::kShotTaken:
      e.kind = Event::Kind::shot_taken;
      e.set_id = w.shot_taken().set_id();
      e.k = static_cast<int>(w.shot_taken().k());
      e.n = static_cast<int>(w.shot_taken().n());
      e.eta_s = w.shot_taken().eta_s();
      break;
    case pb::Event::kSetStored:
      e.kind = Event::Kind::set_stored;
      e.set_id = w.set_stored().id();
      e.warnings.assign(w.set_stored().warnings().begin(), w.set_stored().warnings().end());
      break;
    case pb::Event::kCaptureFailed:
      e.kind = Event::Kind::capture_failed;
      e.set_id = w.capture_failed().set_id();
      e.reason = w.capture_failed().reason();
      e.cancelled = w.capture_failed().cancelled();
      break;
    case pb::Event::kLampState:
      e.kind = Event::Kind::lamp_state;
      e.lamps_on.assign(w.lamp_state().on().begin(), w.lamp_state().on().end());
      e.brightness = static_cast<int>(w.lamp_state().brightness());
      break;
    case pb::Event::kCameraConnected:
      e.kind = Event::Kind::camera_connected;
      e.camera_model = w.camera_connected().model();
      break;
    case pb::Event::kCameraLost:
      e.kind = Event::Kind::camera_lost;
      e.reason = w.camera_lost().reason();
      break;
    case pb::Event::kSetDeleted:
      e.kind = Event::Kind::set_deleted;
      e.set_id = w.set_deleted().id();
      break;
    case pb::Event::kSetRestored:
      e.kind = Event::Kind::set_restored;
      e.set_id = w.set_restored().id();
      break;
    case pb::Event::KIND_NOT_SET:
      break;
  }
  return e;
}

// A file path sent by the rig must stay inside the set folder.
bool safe_relative(const std::string& rel) {
  if (rel.empty() || rel.size() > 200 || rel.front() == '/') return false;
  for (char ch : rel) {
    bool ok = (ch >= 'a' && ch <= 'z') || (ch >= 'A' && ch <= 'Z') || (ch >= '0' && ch <= '9') || ch == '-' ||
              ch == '_' || ch == '.' || ch == '/';
    if (!ok) return false;
  }
  for (const auto& part : fs::path(rel)) {
    if (part == ".." || part == "." || part.empty()) return false;
  }
  return true;
}

}  // namespace

// ------------------------------------------------------------------ Impl

struct Client::Impl {
  struct Download {
    fs::path temp;
    std::map<std::string, uint64_t> expected;  // file -> size, from FetchStarted
    std::map<std::string, uint64_t> received;  // file -> bytes written
    std::map<std::string, uint64_t> resume_at;  // file -> the offset the rig may resume it from (its .part's size)
    std::string current;
    int fd = -1;
    uint64_t total = 0, got = 0;
    bool done = false;
    bool abandoned = false;
    std::string error;
    Clock::time_point last_activity = Clock::now();
    const Progress* progress = nullptr;
  };

  Client* owner = nullptr;
  asio::io_context io;  // run by `reader` once connected: every read and write of the connection happens there
  asio::ssl::context ssl_ctx{asio::ssl::context::tls_client};
  asio::ssl::stream<tcp::socket> stream{io, ssl_ctx};  // in plain TCP only its socket is used
  bool tls = true;
  std::string fingerprint;  // the rig's certificate's (empty in plain TCP)
  std::thread reader;

  // I/O thread only:
  std::deque<std::string> out_queue;
  bool writing = false;
  veneer::wire::FrameBuffer in;
  std::array<char, 64 * 1024> buf;
  std::string end_reason = "connection closed by the rig";  // what an end of stream means (a refusal seen sets it)

  std::mutex mutex;  // guards everything below
  std::condition_variable cv;
  std::map<uint64_t, std::optional<pb::Response>> pending;
  std::map<uint64_t, std::shared_ptr<Download>> downloads;
  std::deque<Event> events;
  bool closed = false;
  std::string close_reason;
  std::atomic<uint64_t> next_id{1};
  ConnectOptions options;
  RigStatus hello;

  ~Impl() { shutdown("client closed"); }

  tcp::socket& sock() { return stream.next_layer(); }

  void shutdown(const std::string& why) {
    {
      std::lock_guard lock(mutex);
      if (!closed) {
        closed = true;
        close_reason = why;
      }
    }
    std::error_code ec;
    if (reader.joinable() && reader.get_id() != std::this_thread::get_id()) {
      // The socket belongs to the I/O thread: closed there, which ends its read and its run.
      asio::post(io, [this] {
        std::error_code e;
        sock().shutdown(tcp::socket::shutdown_both, e);
        sock().close(e);
      });
      reader.join();
    } else {
      sock().shutdown(tcp::socket::shutdown_both, ec);  // on the I/O thread (a callback closed the client), or never started
    }
    sock().close(ec);
    cv.notify_all();
  }

  // Queues a message for the I/O thread to write; a write that fails closes
  // the connection, which every waiting request then reports.
  Status send(const pb::ClientMessage& m) {
    std::string bytes = veneer::wire::encode_delimited(m);
    {
      std::lock_guard lock(mutex);
      if (closed) return make_error("rig connection closed: " + close_reason);
    }
    asio::post(io, [this, b = std::move(bytes)]() mutable {
      out_queue.push_back(std::move(b));
      write_next();
    });
    return {};
  }

  void write_next() {
    if (writing || out_queue.empty()) return;
    writing = true;
    auto done = [this](std::error_code ec, size_t) {
      writing = false;
      if (ec) {
        std::error_code e;
        sock().close(e);  // the read then ends with the reason
        return;
      }
      out_queue.pop_front();
      write_next();
    };
    if (tls) {
      asio::async_write(stream, asio::buffer(out_queue.front()), std::move(done));
    } else {
      asio::async_write(sock(), asio::buffer(out_queue.front()), std::move(done));
    }
  }

  // Sends a request and waits for its response.
  Expected<pb::Response> request(pb::ClientMessage& m, uint64_t id = 0) {
    if (id == 0) id = next_id++;
    m.set_id(id);
    {
      std::lock_guard lock(mutex);
      if (closed) return make_error("rig connection closed: " + close_reason);
      pending[id];
    }
    if (auto s = send(m); !s) {
      std::lock_guard lock(mutex);
      pending.erase(id);
      return s.error();
    }
    std::unique_lock lock(mutex);
    auto deadline = Clock::now() + std::chrono::duration_cast<Clock::duration>(
                                       std::chrono::duration<double>(options.request_timeout_s));
    bool got = cv.wait_until(lock, deadline, [&] { return pending[id].has_value() || closed; });
    std::optional<pb::Response> response = std::move(pending[id]);
    pending.erase(id);
    if (!response) {
      if (closed) return make_error("rig connection closed: " + close_reason);
      if (!got) return make_error("the rig did not answer within " + std::to_string(options.request_timeout_s) + " s");
      return make_error("no response");
    }
    if (!response->ok()) return make_error(response->error().empty() ? "the rig refused the request" : response->error());
    return std::move(*response);
  }

  // The read loop, as asio handlers on the I/O thread.
  void start_read() {
    auto done = [this](std::error_code ec, size_t n) { on_read(ec, n); };
    if (tls) {
      stream.async_read_some(asio::buffer(buf), std::move(done));
    } else {
      sock().async_read_some(asio::buffer(buf), std::move(done));
    }
  }

  void on_read(std::error_code ec, size_t n) {
    std::string& why = end_reason;
    if (ec) {
      // A TCP end without TLS's close_notify is how the rig closes too: the messages read were whole and authenticated.
      finish(ec != asio::error::eof && ec != asio::ssl::error::stream_truncated ? "connection lost: " + ec.message() : why);
      return;
    }
    in.feed(buf.data(), n);
    for (;;) {
      pb::RigMessage m;
      auto r = in.next(m);
      if (r == veneer::wire::ReadResult::need_more) break;
      if (r == veneer::wire::ReadResult::invalid) {
        finish("bad data from the rig: " + in.invalid().field + " is not valid UTF-8");
        return;
      }
      if (r == veneer::wire::ReadResult::error) {
        finish("bad data from the rig: " + in.error());
        return;
      }
      bool closed_now = false;
      {  // once closed (close() from another thread), nothing more is delivered, even what is already read
        std::lock_guard lock(mutex);
        closed_now = closed;
      }
      if (closed_now) {
        finish(why);
        return;
      }
      dispatch(m, why);
    }
    start_read();
  }

  // The connection ended (on the I/O thread): waiters are told why, once.
  void finish(const std::string& why) {
    std::error_code ec;
    sock().close(ec);
    std::string reason;
    {
      std::lock_guard lock(mutex);
      if (!closed) {
        closed = true;
        close_reason = why;
      }
      reason = close_reason;
      for (auto& [id, d] : downloads) {
        if (!d->done && d->error.empty()) d->error = "rig connection closed during the download: " + close_reason;
      }
    }
    cv.notify_all();
    if (owner->on_disconnect) owner->on_disconnect(reason);
  }

  void dispatch(pb::RigMessage& m, std::string& why) {
    switch (m.body_case()) {
      case pb::RigMessage::kResponse: {
        std::lock_guard lock(mutex);
        auto it = pending.find(m.response().id());
        if (it != pending.end()) {
          it->second = std::move(*m.mutable_response());
        } else if (!m.response().ok()) {
          why = "the rig said: " + m.response().error();  // e.g. before it closes the connection
          VLOG_WARN("Rig", "{}", why);
        }
        cv.notify_all();
        break;
      }
      case pb::RigMessage::kEvent: {
        Event e = convert(m.event());
        {
          std::lock_guard lock(mutex);
          events.push_back(e);
          while (events.size() > 4096) events.pop_front();
        }
        cv.notify_all();
        if (owner->on_event) owner->on_event(e);
        break;
      }
      case pb::RigMessage::kChunk: on_chunk(*m.mutable_chunk()); break;
      case pb::RigMessage::kFrame: {
        if (!owner->on_live_frame) break;
        LiveFrame f;
        const auto& w = m.frame();
        f.jpeg.assign(w.jpeg().begin(), w.jpeg().end());
        f.seq = w.seq();
        f.ts = w.ts();
        f.width = static_cast<int>(w.width());
        f.height = static_cast<int>(w.height());
        owner->on_live_frame(f);
        break;
      }
      case pb::RigMessage::BODY_NOT_SET: break;
    }
  }

  void on_chunk(pb::ImageChunk& c) {
    std::shared_ptr<Download> d;
    {
      std::lock_guard lock(mutex);
      auto it = downloads.find(c.request_id());
      if (it == downloads.end()) return;
      d = it->second;
    }
    auto fail = [&](const std::string& what) {
      std::lock_guard lock(mutex);
      if (d->error.empty()) d->error = what;
      if (d->fd >= 0) ::close(d->fd);
      d->fd = -1;
      cv.notify_all();
    };
    if (d->abandoned || !d->error.empty() || d->done) return;
    d->last_activity = Clock::now();
    const std::string& rel = c.file();
    if (!safe_relative(rel)) return fail("the rig sent a file name outside the set: '" + rel.substr(0, 60) + "'");
    if (rel != d->current) {
      if (d->fd >= 0) return fail("the rig switched files before finishing " + d->current);
      if (d->received.count(rel)) return fail("the rig sent " + rel + " twice");
      // Into <rel>.part, renamed to <rel> once whole: a resumed pull takes
      // every file without the suffix as complete, and continues a .part
      // from its end when the rig agrees its bytes are the rig's (a file's
      // first chunk is at 0, or at the offset asked in resume_from; the
      // chunks may arrive before FetchStarted is read).
      const auto resume = d->resume_at.find(rel);
      const uint64_t from = c.offset();
      if (from != 0 && (resume == d->resume_at.end() || resume->second != from))
        return fail(rel + ": first chunk at offset " + std::to_string(from) + ", which was not asked");
      fs::path target = d->temp / (rel + ".part");
      std::error_code ec;
      fs::create_directories(target.parent_path(), ec);
      d->fd = ::open(target.c_str(), O_WRONLY | O_CREAT | (from == 0 ? O_TRUNC : 0) | O_CLOEXEC, 0644);
      if (d->fd < 0) return fail(target.string() + ": cannot create: " + std::strerror(errno));
      if (from > 0 && (::ftruncate(d->fd, static_cast<off_t>(from)) != 0 ||
                       ::lseek(d->fd, static_cast<off_t>(from), SEEK_SET) != static_cast<off_t>(from)))
        return fail(target.string() + ": cannot continue at byte " + std::to_string(from) + ": " + std::strerror(errno));
      d->current = rel;
      d->received[rel] = from;
    }
    if (c.offset() != d->received[rel]) return fail(rel + ": chunk at offset " + std::to_string(c.offset()) + ", expected " + std::to_string(d->received[rel]));
    const std::string& data = c.data();
    size_t done = 0;
    while (done < data.size()) {
      ssize_t n = ::write(d->fd, data.data() + done, data.size() - done);
      if (n < 0) {
        if (errno == EINTR) continue;
        return fail((d->temp / rel).string() + ": write failed: " + std::strerror(errno));
      }
      done += static_cast<size_t>(n);
    }
    d->received[rel] += data.size();
    d->got += data.size();
    if (d->progress) d->progress->report(d->total > 0 ? static_cast<double>(d->got) / d->total : 0, rel);
    if (c.last()) {
      if (::fsync(d->fd) != 0 || ::close(d->fd) != 0) {
        d->fd = -1;
        return fail((d->temp / rel).string() + ": cannot sync");
      }
      d->fd = -1;
      d->current.clear();
      if (c.file_size() != d->received[rel]) return fail(rel + ": received " + std::to_string(d->received[rel]) + " of " + std::to_string(c.file_size()) + " bytes");
      const fs::path whole = d->temp / rel;
      if (::rename((whole.string() + ".part").c_str(), whole.c_str()) != 0)
        return fail(whole.string() + ": cannot rename into place: " + std::strerror(errno));
    }
    if (c.end_of_set()) {
      std::lock_guard lock(mutex);
      if (!closed) {
        d->done = true;
      } else if (d->error.empty()) {  // closed while this chunk was handled: the set is not taken as whole
        d->error = "rig connection closed during the download: " + close_reason;
      }
      cv.notify_all();
    }
  }
};

// ------------------------------------------------------------------ Client

Client::Client() : impl_(std::make_unique<Impl>()) { impl_->owner = this; }

Client::~Client() { close(); }

void Client::close() {
  if (impl_) impl_->shutdown("client closed");
}

std::string Endpoint::pin_name() const {
  return (host.find(':') != std::string::npos ? "[" + host + "]" : host) + ":" + std::to_string(port);
}

namespace {

// The rig's certificate, as seen in the handshake: its fingerprint ("" if none was sent).
std::string peer_fingerprint(SSL* ssl) {
  X509* cert = SSL_get1_peer_certificate(ssl);
  if (!cert) return "";
  std::string fp;
  int n = i2d_X509(cert, nullptr);
  if (n > 0) {
    std::string der(static_cast<size_t>(n), '\0');
    auto* p = reinterpret_cast<unsigned char*>(der.data());
    i2d_X509(cert, &p);
    fp = tls::fingerprint_of_der(reinterpret_cast<const unsigned char*>(der.data()), der.size());
  }
  X509_free(cert);
  return fp;
}

}  // namespace

// Whether `seen` is the rig's pinned fingerprint (proto/README.md, "Pinning"):
// the fingerprint given, else the known-rigs file's, else the first use's
// answer. Nothing has been sent to the rig yet.
Status Client::check_pin(const Endpoint& endpoint, const std::string& seen, bool loopback) {
  const ConnectOptions& o = impl_->options;
  const std::string rig = endpoint.pin_name();
  const std::string where = "rig " + endpoint.str();
  if (seen.empty()) return make_error(where + ": the rig sent no certificate");
  std::string expected, source;
  if (!o.fingerprint.empty()) {
    auto fp = tls::parse_fingerprint(o.fingerprint);
    if (!fp) return make_error(where + ": " + fp.message());
    expected = *fp;
    source = "the fingerprint given";
  }
  std::string known;
  if (!o.known_rigs.empty()) {
    auto k = tls::known_fingerprint(o.known_rigs, rig);
    if (!k) return make_error(where + ": " + k.message());
    known = *k;
    if (expected.empty() && !known.empty()) {
      expected = known;
      source = "pinned in " + o.known_rigs.string();
    }
  }
  if (!expected.empty()) {
    if (expected != seen) {
      return make_error(where + ": the rig's certificate is not the pinned one: expected fingerprint " + expected +
                        " (" + source + "), the rig presented " + seen +
                        "; nothing was sent. Someone may be intercepting the connection. If the rig's key was "
                        "replaced on purpose, check the new fingerprint with `veneerd --fingerprint` on the rig and "
                        "pin it (veneer rig --fingerprint NEW)");
    }
    if (!o.known_rigs.empty() && known != seen) {  // the fingerprint given, checked: pinned from now on
      if (auto s = tls::remember_fingerprint(o.known_rigs, rig, seen); !s) return make_error(where + ": " + s.message());
      if (!known.empty()) VLOG_WARN("Rig", "{}: pinned fingerprint replaced by the one given, {}", rig, seen);
    }
    return {};
  }
  if (o.confirm_first_use) {
    if (!o.confirm_first_use(rig, seen)) {
      return make_error(where + ": certificate fingerprint " + seen + " not accepted; nothing was sent");
    }
    if (!o.known_rigs.empty()) {
      if (auto s = tls::remember_fingerprint(o.known_rigs, rig, seen); !s) return make_error(where + ": " + s.message());
    }
    return {};
  }
  if (loopback && o.trust_loopback) return {};
  return make_error(where + ": certificate fingerprint " + seen +
                    " is not pinned (no fingerprint given, none known for " + rig +
                    "); compare it with `veneerd --fingerprint` on the rig and pass it; nothing was sent");
}

Expected<std::unique_ptr<Client>> Client::connect(const Endpoint& endpoint, const std::string& token,
                                                  const ConnectOptions& options) {
  std::unique_ptr<Client> client(new Client());
  Impl& d = *client->impl_;
  d.options = options;
  d.tls = !options.plain_tcp;
  const auto timeout = std::chrono::duration_cast<std::chrono::milliseconds>(
      std::chrono::duration<double>(options.connect_timeout_s));
  std::error_code ec;
  tcp::resolver resolver(d.io);
  auto results = resolver.resolve(endpoint.host, std::to_string(endpoint.port), ec);
  if (ec) return make_error("rig " + endpoint.str() + ": cannot resolve: " + ec.message());
  std::error_code connect_ec = asio::error::timed_out;
  asio::async_connect(d.sock(), results, [&](std::error_code e, const tcp::endpoint&) { connect_ec = e; });
  d.io.run_for(timeout);
  if (connect_ec) {
    d.sock().close(ec);
    return make_error("rig " + endpoint.str() + ": cannot connect: " + connect_ec.message());
  }
  d.sock().set_option(tcp::no_delay(true), ec);
  const auto remote = d.sock().remote_endpoint(ec);
  const bool loopback = !ec && remote.address().is_loopback();

  if (d.tls) {
    // TLS 1.3 only; the certificate is checked by its pinned fingerprint
    // (check_pin), not by a CA: a rig's certificate is self-signed. No SNI, no ALPN.
    SSL_CTX* ctx = d.ssl_ctx.native_handle();
    SSL_CTX_set_min_proto_version(ctx, TLS1_3_VERSION);
    SSL_CTX_set_max_proto_version(ctx, TLS1_3_VERSION);
    d.ssl_ctx.set_verify_mode(asio::ssl::verify_none);
    std::error_code hs_ec = asio::error::timed_out;
    d.io.restart();
    d.stream.async_handshake(asio::ssl::stream_base::client, [&](std::error_code e) { hs_ec = e; });
    d.io.run_for(timeout);
    if (hs_ec) {
      d.sock().close(ec);
      return make_error("rig " + endpoint.str() + ": TLS 1.3 handshake failed: " + hs_ec.message() +
                        " (a rig configured for plain TCP? then connect with --plain-tcp, knowing that the token "
                        "and the photos cross the network in clear)");
    }
    d.fingerprint = peer_fingerprint(d.stream.native_handle());
    if (auto s = client->check_pin(endpoint, d.fingerprint, loopback); !s) {
      d.sock().close(ec);
      return s.error();
    }
  }
  d.io.restart();
  d.reader = std::thread([&d] {
    d.start_read();
    d.io.run();
  });

  // The token goes only now: inside the tunnel, to the pinned rig.
  pb::ClientMessage m;
  auto* h = m.mutable_hello();
  h->set_protocol_version(veneer::wire::kProtocolVersion);
  h->set_token(token);
  h->set_client_name(options.client_name);
  auto r = d.request(m);
  if (!r) {
    std::string why = r.message();
    if (!d.tls && why.find("closed by the rig") != std::string::npos) {
      why += " (a rig serving TLS closes a plain-TCP hello without a word: connect without --plain-tcp)";
    }
    return make_error("rig " + endpoint.str() + ": " + why);
  }
  d.hello = convert(r->status());
  return client;
}

const std::string& Client::fingerprint() const { return impl_->fingerprint; }

bool Client::connected() const {
  std::lock_guard lock(impl_->mutex);
  return !impl_->closed;
}

const RigStatus& Client::hello_status() const { return impl_->hello; }

Expected<RigStatus> Client::status() {
  pb::ClientMessage m;
  m.mutable_status();
  auto r = impl_->request(m);
  if (!r) return r.error();
  return convert(r->status());
}

Expected<std::vector<SetSummary>> Client::list_sets() { return list(false); }

Expected<std::vector<SetSummary>> Client::list_trash() { return list(true); }

Expected<std::vector<SetSummary>> Client::list(bool trash) {
  pb::ClientMessage m;
  m.mutable_list_sets()->set_trash(trash);
  auto r = impl_->request(m);
  if (!r) return r.error();
  std::vector<SetSummary> out;
  for (const auto& s : r->sets().sets()) {
    SetSummary x;
    x.id = s.id();
    x.role = from_wire(s.role());
    x.object = s.object();
    x.created = s.created();
    x.size = cv::Size(static_cast<int>(s.width()), static_cast<int>(s.height()));
    x.lights = static_cast<int>(s.lights());
    x.warnings.assign(s.warnings().begin(), s.warnings().end());
    x.has_truth = s.has_truth();
    x.bytes = s.bytes();
    x.scene = s.scene();
    x.deleted = s.deleted();
    out.push_back(std::move(x));
  }
  return out;
}

Expected<std::string> Client::manifest(const std::string& set_id) {
  pb::ClientMessage m;
  m.mutable_get_manifest()->set_set_id(set_id);
  auto r = impl_->request(m);
  if (!r) return r.error();
  return r->manifest().json();
}

Expected<Client::Fetched> Client::fetch_into(const std::string& set_id, bool preview, bool include_truth,
                                             const std::vector<std::string>& skip,
                                             const std::vector<Partial>& partial, const fs::path& dir,
                                             const Progress& progress) {
  Impl& d = *impl_;
  auto dl = std::make_shared<Impl::Download>();
  dl->temp = dir;
  dl->progress = &progress;
  auto abandon = [&] {  // what was written stays: files whole, the one being written as its .part (a pull resumes from them)
    std::lock_guard lock(d.mutex);
    dl->abandoned = true;
    if (dl->fd >= 0) {
      ::fdatasync(dl->fd);
      ::close(dl->fd);
    }
    dl->fd = -1;
  };

  const uint64_t id = d.next_id++;
  {
    std::lock_guard lock(d.mutex);
    for (const auto& p : partial) dl->resume_at[p.file] = p.size;
    d.downloads[id] = dl;
  }
  struct Unregister {
    Impl& d;
    uint64_t id;
    ~Unregister() {
      std::lock_guard lock(d.mutex);
      d.downloads.erase(id);
    }
  } unregister{d, id};

  pb::ClientMessage m;
  if (preview) {
    m.mutable_fetch_preview()->set_set_id(set_id);
  } else {
    auto* f = m.mutable_fetch_images();
    f->set_set_id(set_id);
    f->set_include_truth(include_truth);
    for (const auto& s : skip) f->add_skip_files(s);
    for (const auto& p : partial) {
      auto* r = f->add_resume_from();
      r->set_file(p.file);
      r->set_offset(p.size);
      r->set_crc32(p.crc32);
    }
  }
  auto r = d.request(m, id);
  if (!r) {
    abandon();
    return r.error();
  }
  Fetched out;
  {
    std::lock_guard lock(d.mutex);
    for (const auto& file : r->fetch().files()) {
      dl->expected[file] = 0;
      out.files.push_back(file);
    }
    out.skipped.assign(r->fetch().skipped_files().begin(), r->fetch().skipped_files().end());
    for (const auto& from : r->fetch().resumed()) {
      // Only a resume the client asked for, from where its .part ends.
      auto asked = std::find_if(partial.begin(), partial.end(), [&](const Partial& p) { return p.file == from.file(); });
      if (asked == partial.end() || asked->size != from.offset() || asked->crc32 != from.crc32()) {
        dl->error = "the rig resumed " + from.file() + " from byte " + std::to_string(from.offset()) + ", which was not asked";
        break;
      }
      out.resumed.push_back(from.file());
    }
    dl->total = r->fetch().total_bytes();
  }

  std::unique_lock lock(d.mutex);
  const auto stall = std::chrono::duration<double>(d.options.request_timeout_s);
  for (;;) {
    if (dl->done || !dl->error.empty()) break;
    if (progress.cancelled()) {
      lock.unlock();
      abandon();
      return make_error("cancelled");
    }
    if (Clock::now() - dl->last_activity > stall) {
      dl->error = "the rig sent nothing for " + std::to_string(d.options.request_timeout_s) + " s";
      break;
    }
    if (d.closed && !dl->done) {
      if (dl->error.empty()) dl->error = "rig connection closed during the download: " + d.close_reason;
      break;
    }
    d.cv.wait_for(lock, std::chrono::milliseconds(100));
  }
  std::string error = dl->error;
  lock.unlock();
  if (error.empty()) {
    for (const auto& [file, size] : dl->expected) {
      if (!dl->received.count(file)) error = "the rig did not send " + file;
    }
  }
  if (!error.empty()) {
    abandon();
    return make_error(error);
  }
  return out;
}

Status Client::delete_set(const std::string& set_id) {
  pb::ClientMessage m;
  m.mutable_delete_set()->set_set_id(set_id);
  auto r = impl_->request(m);
  if (!r) return r.error();
  return {};
}

Status Client::restore_set(const std::string& set_id) {
  pb::ClientMessage m;
  m.mutable_restore_set()->set_set_id(set_id);
  auto r = impl_->request(m);
  if (!r) return r.error();
  return {};
}

Expected<std::string> Client::capture(const CaptureOptions& o) {
  pb::ClientMessage m;
  auto* c = m.mutable_capture();
  c->set_role(to_wire(o.role));
  c->set_object(o.object);
  c->mutable_exposure()->set_shutter_s(o.shutter_s);
  c->mutable_exposure()->set_aperture(o.aperture);
  c->mutable_exposure()->set_iso(static_cast<uint32_t>(std::max(0, o.iso)));
  auto r = impl_->request(m);
  if (!r) return r.error();
  return r->capture_set_id();
}

namespace {
Status simple(Client::Impl& d, pb::ClientMessage& m) {
  auto r = d.request(m);
  if (!r) return r.error();
  return {};
}
}  // namespace

Status Client::cancel_capture() {
  pb::ClientMessage m;
  m.mutable_cancel_capture();
  return simple(*impl_, m);
}

Status Client::set_lamps(const std::vector<bool>& on, int brightness) {
  pb::ClientMessage m;
  auto* l = m.mutable_set_lamps();
  for (bool b : on) l->add_on(b);
  l->set_brightness(static_cast<uint32_t>(std::clamp(brightness, 1, 254)));
  return simple(*impl_, m);
}

Status Client::start_live_view(double fps) {
  pb::ClientMessage m;
  m.mutable_start_live_view()->set_fps(fps);
  return simple(*impl_, m);
}

Status Client::stop_live_view() {
  pb::ClientMessage m;
  m.mutable_stop_live_view();
  return simple(*impl_, m);
}

Status Client::press_button(bool long_press) {
  pb::ClientMessage m;
  m.mutable_press_button()->set_long_press(long_press);
  return simple(*impl_, m);
}

Status Client::move_hand_lamp(const cv::Vec3d& p) {
  pb::ClientMessage m;
  auto* pos = m.mutable_move_hand_lamp()->mutable_position();
  pos->set_x(p[0]);
  pos->set_y(p[1]);
  pos->set_z(p[2]);
  return simple(*impl_, m);
}

Expected<Event> Client::wait_event(const std::function<bool(const Event&)>& match, double timeout_s) {
  Impl& d = *impl_;
  std::unique_lock lock(d.mutex);
  auto deadline = Clock::now() + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(timeout_s));
  for (;;) {
    while (!d.events.empty()) {
      Event e = std::move(d.events.front());
      d.events.pop_front();
      if (match(e)) return e;
    }
    if (d.closed) return make_error("rig connection closed: " + d.close_reason);
    if (d.cv.wait_until(lock, deadline) == std::cv_status::timeout && d.events.empty()) {
      return make_error("no such event from the rig within " + std::to_string(timeout_s) + " s");
    }
  }
}

}  // namespace veneer::rig
