#include "veneerd/server.hpp"

#include <array>
#include <chrono>
#include <deque>
#include <fstream>
#include <mutex>
#include <set>
#include <thread>

#include <asio.hpp>

#include "veneer/proto/framing.hpp"
#include "veneer/util/log.hpp"
#include "veneer/v1/rig.pb.h"
#include "veneerd/api.hpp"

namespace veneerd {

namespace pb = veneer::v1;
namespace fs = std::filesystem;
using asio::ip::tcp;
using Clock = std::chrono::steady_clock;

namespace {

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
  tcp::acceptor acceptor{io};
  std::thread thread;
  uint16_t bound_port = 0;

  // I/O thread only:
  std::set<std::shared_ptr<Session>> sessions;
  std::weak_ptr<Session> controller;
  uint64_t event_seq = 0;

  mutable std::mutex stats_mutex;
  ServerStats stats;

  Impl(Rig& r, ServerOptions o) : rig(r), opt(std::move(o)) {}
  void accept();
  void on_event(const RigEvent& e);
  void on_live(std::shared_ptr<const LiveFrameData> frame);
  void update_live_rate();
  void count(uint64_t ServerStats::*field) {
    std::lock_guard lock(stats_mutex);
    ++(stats.*field);
  }
};

// One client connection. Lives on the I/O thread.
class Session : public std::enable_shared_from_this<Session> {
 public:
  Session(Server::Impl& server, tcp::socket socket)
      : srv_(server), sock_(std::move(socket)), hello_timer_(server.io), close_timer_(server.io) {
    std::error_code ec;
    auto ep = sock_.remote_endpoint(ec);
    peer_ = ec ? "?" : ep.address().to_string() + ":" + std::to_string(ep.port());
    sock_.set_option(tcp::no_delay(true), ec);
  }

  void start() {
    auto self = shared_from_this();
    hello_timer_.expires_after(std::chrono::duration_cast<Clock::duration>(
        std::chrono::duration<double>(srv_.opt.hello_timeout_s)));
    hello_timer_.async_wait([self](std::error_code ec) {
      if (!ec && !self->authed_) {
        VLOG_INFO("Server", "{}: no hello in time, closing", self->peer_);
        self->close();
      }
    });
    read();
  }

  const std::string& peer() const { return peer_; }
  bool authed() const { return authed_; }
  double live_fps() const { return live_fps_; }

  // Sends a message. Droppable messages (live frames) are skipped while the
  // queue is long; anything else overflowing the queue drops the client.
  bool send(const pb::RigMessage& m, bool droppable = false) {
    if (closed_) return false;
    if (droppable && queued_ > srv_.opt.live_queue_bytes) return false;
    auto bytes = std::make_shared<std::string>(veneer::wire::encode_delimited(m));
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
    pb::RigMessage m;
    auto* r = m.mutable_response();
    r->set_id(id);
    r->set_ok(status.ok());
    if (!status) r->set_error(status.message());
    send(m);
  }

  void offer_live(const std::shared_ptr<const LiveFrameData>& f) {
    if (!authed_ || live_fps_ <= 0) return;
    auto now = Clock::now();
    if (now - last_frame_ < std::chrono::duration<double>(0.9 / live_fps_)) return;
    pb::RigMessage m;
    auto* lf = m.mutable_frame();
    lf->set_jpeg(f->jpeg.data(), f->jpeg.size());
    lf->set_seq(f->seq);
    lf->set_ts(f->ts);
    lf->set_width(static_cast<uint32_t>(f->width));
    lf->set_height(static_cast<uint32_t>(f->height));
    if (send(m, true)) {
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
    sock_.shutdown(tcp::socket::shutdown_both, ec);
    sock_.close(ec);
    queue_.clear();
    queued_ = 0;
    fetch_.reset();
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
    VLOG_INFO("Server", "{}: connection closed", peer_);
  }

 private:
  // Sends what is queued, then closes (after a protocol error or refused hello).
  void close_after_flush(uint64_t id, const std::string& error) {
    srv_.count(&ServerStats::protocol_errors);
    VLOG_WARN("Server", "{}: {}; closing", peer_, error);
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

  void read() {
    auto self = shared_from_this();
    sock_.async_read_some(asio::buffer(rbuf_), [self](std::error_code ec, size_t n) {
      if (self->closed_) return;
      if (ec) {
        self->close();
        return;
      }
      self->in_.feed(self->rbuf_.data(), n);
      for (;;) {
        if (self->closing_ || self->closed_) return;
        pb::ClientMessage msg;
        auto r = self->in_.next(msg);
        if (r == veneer::wire::ReadResult::need_more) break;
        if (r == veneer::wire::ReadResult::error) {
          self->close_after_flush(0, "bad message stream: " + self->in_.error());
          return;
        }
        self->handle(msg);
      }
      if (!self->closing_ && !self->closed_) self->read();
    });
  }

  void write() {
    if (writing_ || queue_.empty() || closed_) return;
    writing_ = true;
    auto self = shared_from_this();
    auto bytes = queue_.front();
    asio::async_write(sock_, asio::buffer(*bytes), [self, bytes](std::error_code ec, size_t) {
      self->writing_ = false;
      if (self->closed_) return;
      if (ec) {
        self->close();
        return;
      }
      self->queued_ -= bytes->size();
      self->queue_.pop_front();
      if (self->closing_ && self->queue_.empty()) {
        self->close();
        return;
      }
      self->pump_fetch();
      self->write();
    });
  }

  // ---- requests

  void handle(const pb::ClientMessage& msg) {
    auto req = api::decode(msg);
    if (!authed_) {
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
        srv_.controller = shared_from_this();
        VLOG_INFO("Server", "{}: now controls the rig", peer_);
      }
    }
    std::visit([&](auto& body) { on(id, body); }, req->body);
  }

  void on(uint64_t id, api::Hello& h) {
    if (authed_) {
      respond(id, veneer::make_error("hello: already said"));
      return;
    }
    if (h.protocol_version != veneer::wire::kProtocolVersion) {
      close_after_flush(id, "hello: protocol version " + std::to_string(h.protocol_version) +
                                " is not supported (the rig speaks " +
                                std::to_string(veneer::wire::kProtocolVersion) + ")");
      return;
    }
    if (!same_token(h.token, srv_.opt.token)) {
      close_after_flush(id, h.token.empty() ? "hello: no access token given" : "hello: wrong access token");
      return;
    }
    authed_ = true;
    hello_timer_.cancel();
    client_name_ = h.client_name;
    VLOG_INFO("Server", "{}: hello from '{}'", peer_, client_name_);
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
    s.set_next_role(st.next_role == veneer::Role::source ? pb::ROLE_SOURCE : pb::ROLE_DESTINATION);
    s.set_free_bytes(srv_.rig.store().free_bytes());
    s.set_clients(static_cast<uint32_t>(srv_.sessions.size()));
  }

  void on(uint64_t id, api::StatusReq&) {
    pb::RigMessage m;
    auto* r = m.mutable_response();
    r->set_id(id);
    r->set_ok(true);
    fill_status(*r->mutable_status());
    send(m);
  }

  void on(uint64_t id, api::ListSetsReq&) {
    pb::RigMessage m;
    auto* r = m.mutable_response();
    r->set_id(id);
    r->set_ok(true);
    auto* list = r->mutable_sets();
    for (const auto& s : srv_.rig.store().list()) api::encode_set(s, *list->add_sets());
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
    auto files = srv_.rig.store().files(f.set_id, f.include_truth);
    if (!files) {
      respond(id, files.error());
      return;
    }
    // Open every file now: a set deleted mid-download still downloads whole.
    auto fetch = std::make_unique<Fetch>();
    fetch->request_id = id;
    fetch->set_id = f.set_id;
    fetch->chunk = f.chunk_size;
    fs::path folder = srv_.rig.store().folder(f.set_id);
    uint64_t total = 0;
    for (const auto& rel : *files) {
      auto in = std::make_unique<std::ifstream>(folder / rel, std::ios::binary);
      std::error_code ec;
      uint64_t size = fs::file_size(folder / rel, ec);
      if (!*in || ec) {
        respond(id, veneer::make_error("fetch_images: cannot read " + f.set_id + "/" + rel));
        return;
      }
      fetch->files.push_back({rel, std::move(in), size});
      total += size;
    }
    pb::RigMessage m;
    auto* r = m.mutable_response();
    r->set_id(id);
    r->set_ok(true);
    auto* started = r->mutable_fetch();
    started->set_set_id(f.set_id);
    for (const auto& rel : *files) started->add_files(rel);
    started->set_total_bytes(total);
    send(m);
    fetch_ = std::move(fetch);
    VLOG_INFO("Server", "{}: download of {} ({} files, {} bytes) started", peer_, f.set_id, files->size(), total);
    pump_fetch();
  }

  void pump_fetch() {
    while (fetch_ && !closed_ && !closing_ && queued_ < srv_.opt.fetch_queue_bytes) {
      Fetch& f = *fetch_;
      FetchFile& file = f.files[f.index];
      pb::RigMessage m;
      auto* c = m.mutable_chunk();
      c->set_request_id(f.request_id);
      c->set_set_id(f.set_id);
      c->set_file(file.rel);
      c->set_offset(f.offset);
      c->set_file_size(file.size);
      size_t want = static_cast<size_t>(std::min<uint64_t>(f.chunk, file.size - f.offset));
      std::string* data = c->mutable_data();
      data->resize(want);
      if (want > 0) file.in->read(data->data(), static_cast<std::streamsize>(want));
      if (want > 0 && static_cast<size_t>(file.in->gcount()) != want) {
        VLOG_ERROR("Server", "{}: reading {}/{} failed mid-download", peer_, f.set_id, file.rel);
        close();
        return;
      }
      f.offset += want;
      bool last = f.offset >= file.size;
      c->set_last(last);
      bool end = last && f.index + 1 == f.files.size();
      c->set_end_of_set(end);
      if (last) {
        ++f.index;
        f.offset = 0;
      }
      if (end) {
        VLOG_INFO("Server", "{}: download of {} sent", peer_, f.set_id);
        fetch_.reset();
      }
      send(m);
    }
  }

  void on(uint64_t id, api::DeleteSetReq& d) { respond(id, srv_.rig.delete_set(d.set_id)); }

  void on(uint64_t id, api::CaptureReq& c) {
    auto set_id = srv_.rig.capture(c.capture);
    if (!set_id) {
      respond(id, set_id.error());
      return;
    }
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

  struct FetchFile {
    std::string rel;
    std::unique_ptr<std::ifstream> in;
    uint64_t size = 0;
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
  tcp::socket sock_;
  asio::steady_timer hello_timer_;
  asio::steady_timer close_timer_;
  std::string peer_;
  std::string client_name_;
  std::array<char, 64 * 1024> rbuf_{};
  veneer::wire::FrameBuffer in_;
  std::deque<std::shared_ptr<const std::string>> queue_;
  size_t queued_ = 0;
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
    VLOG_INFO("Server", "{}: connected", session->peer());
    session->start();
    self->accept();
  });
}

void Server::Impl::on_event(const RigEvent& e) {
  pb::RigMessage m;
  api::encode_event(e, ++event_seq, m);
  auto copy = sessions;  // a send may close (and erase) a session
  for (const auto& s : copy) {
    if (s->authed()) s->send(m);
  }
}

void Server::Impl::on_live(std::shared_ptr<const LiveFrameData> frame) {
  auto copy = sessions;
  for (const auto& s : copy) s->offer_live(frame);
}

void Server::Impl::update_live_rate() {
  double fps = 0;
  for (const auto& s : sessions) fps = std::max(fps, s->live_fps());
  rig.set_live_fps(fps);
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
  std::error_code ec;
  auto address = asio::ip::make_address(impl_->opt.host, ec);
  if (ec) return veneer::make_error("listen address '" + impl_->opt.host + "': " + ec.message());
  tcp::endpoint ep(address, impl_->opt.port);
  auto& acc = impl_->acceptor;
  acc.open(ep.protocol(), ec);
  if (!ec) acc.set_option(tcp::acceptor::reuse_address(true), ec);
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
  VLOG_INFO("Server", "listening on {}:{}", impl_->opt.host, impl_->bound_port);
  return {};
}

void Server::stop() {
  if (!impl_->thread.joinable()) return;
  asio::post(impl_->io, [impl = impl_] {
    std::error_code ec;
    impl->acceptor.close(ec);
    auto copy = impl->sessions;
    for (const auto& s : copy) s->close();
    impl->io.stop();
  });
  impl_->thread.join();
}

uint16_t Server::port() const { return impl_->bound_port; }

ServerStats Server::stats() const {
  std::lock_guard lock(impl_->stats_mutex);
  return impl_->stats;
}

}  // namespace veneerd
