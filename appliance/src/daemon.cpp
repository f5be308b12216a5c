#include "veneerd/daemon.hpp"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <fstream>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include "veneer/proto/discovery.hpp"
#include "veneer/proto/tls.hpp"
#include "veneer/sim/simulator.hpp"
#include "veneer/util/log.hpp"
#include "veneer/util/token_file.hpp"
#include "veneerd/devices/registry.hpp"
#include "veneerd/sim/fault_plan.hpp"
#include "veneerd/sim/simulated_camera.hpp"
#include "veneerd/sim/simulated_rig.hpp"

namespace veneerd {

namespace fs = std::filesystem;

constexpr int kLiveViewMaxWidth = 1024;  // the simulated camera's live view, at most (px)
using veneer::make_error;


veneer::Expected<std::string> ensure_token(const fs::path& file) {
  std::error_code ec;
  if (fs::exists(file, ec)) {
    struct stat st {};
    if (::stat(file.c_str(), &st) == 0 && (st.st_mode & 077) != 0) {
      VLOG_WARN("Server", "{} is readable by others (mode {:o}); it should be 0600", file.string(), st.st_mode & 0777);
    }
    return veneer::read_token_file(file);
  }
  if (!file.parent_path().empty()) fs::create_directories(file.parent_path(), ec);
  unsigned char raw[32];
  int rfd = ::open("/dev/urandom", O_RDONLY | O_CLOEXEC);
  if (rfd < 0 || ::read(rfd, raw, sizeof raw) != static_cast<ssize_t>(sizeof raw)) {
    if (rfd >= 0) ::close(rfd);
    return make_error("cannot read /dev/urandom to make an access token");
  }
  ::close(rfd);
  static const char* hex = "0123456789abcdef";
  std::string token;
  for (unsigned char b : raw) {
    token += hex[b >> 4];
    token += hex[b & 15];
  }
  int fd = ::open(file.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0600);
  if (fd < 0) return make_error(file.string() + ": cannot create the token file: " + std::strerror(errno));
  std::string line = token + "\n";
  bool ok = ::write(fd, line.data(), line.size()) == static_cast<ssize_t>(line.size()) && ::fsync(fd) == 0;
  ::close(fd);
  if (!ok) {
    ::unlink(file.c_str());
    return make_error(file.string() + ": cannot write the token file");
  }
  VLOG_INFO("Server", "new access token written to {}", file.string());
  return token;
}

veneer::Expected<std::string> ensure_tls_identity(const Config& c) {
  auto id = veneer::tls::ensure_identity(c.tls_key_path(), c.tls_cert_path(), c.name);
  if (!id) return make_error("TLS identity: " + id.message());
  if (id->created) {
    VLOG_INFO("Server", "new TLS key and self-signed certificate written to {} and {}", c.tls_key_path().string(),
              c.tls_cert_path().string());
  } else {
    struct stat st {};
    if (::stat(c.tls_key_path().c_str(), &st) == 0 && (st.st_mode & 077) != 0) {
      VLOG_WARN("Server", "{} is readable by others (mode {:o}); it should be 0600", c.tls_key_path().string(),
                st.st_mode & 0777);
    }
  }
  return id->fingerprint;
}

namespace {

template <class Device>
veneer::Expected<std::unique_ptr<Device>> build(const std::vector<std::pair<std::string, Factory<Device>>>& list,
                                                const char* kind, const DeviceConfig& dc) {
  auto dev = DeviceRegistry::make(list, kind, dc.backend, dc.section);
  if (!dev) return make_error(std::string(kind) + " (backend '" + dc.backend + "'): " + dev.message());
  return dev;
}

}  // namespace

SimulatedCamera* Daemon::simulated_camera() { return as_simulated(camera_); }

veneer::Expected<std::unique_ptr<Daemon>> Daemon::create(const DaemonOptions& o) {
  std::unique_ptr<Daemon> d(new Daemon());
  register_simulated_devices();
  register_hardware_devices();
  if (!o.faults.empty()) {
    if (!o.simulate) return make_error("--faults: only the simulated rig (--simulate) takes injected faults");
    auto plan = FaultPlan::parse(o.faults);
    if (!plan) return plan.error();
    d->faults_ = std::make_shared<FaultPlan>(std::move(*plan));
  }

  if (o.simulate) {
    SimulatedRigOptions so;
    so.scenes = o.scenes;
    so.size = o.size;
    // A DSLR's live view is a small picture of the still's framing (about
    // 1024 px wide); the twin's is the stills' size up to that width, so a
    // full-resolution rig does not render a second full-size live view.
    so.preview_size = o.preview_size;
    if (so.preview_size.area() <= 0) {
      so.preview_size = o.size;
      if (o.size.width > kLiveViewMaxWidth)
        so.preview_size = {kLiveViewMaxWidth, std::max(2, 2 * static_cast<int>(std::lround(0.5 * o.size.height *
                                                                                          kLiveViewMaxWidth / o.size.width)))};
    }
    so.preview_motion = o.preview_motion;
    so.preview_motion_frames = o.preview_motion_frames;
    so.noise_sigma = o.noise_sigma;
    so.latency_ms = o.hue_latency_ms;
    so.rate_limits = o.hue_rate_limits;
    if (o.hue_light_rate > 0) so.light_rate = o.hue_light_rate;
    if (o.hue_apply_delay_ms >= 0) {
      so.apply_delay_ms = o.hue_apply_delay_ms;
      so.settle_ms = o.hue_apply_delay_ms + 30;
    }
    auto sim = SimulatedRig::start(so);
    if (!sim) return make_error("simulated rig: " + sim.message());
    d->sim_ = std::move(*sim);
    nlohmann::json devices = d->sim_->devices_config();
    Config& c = d->config_;
    c.name = "veneer-simulated-rig";
    c.store = "veneer-sets";
    c.lamps = {devices["lamps"].value("backend", "hue"), devices["lamps"]};
    c.camera = {devices["camera"].value("backend", "simulated"), devices["camera"]};
    c.trigger = {devices["trigger"].value("backend", "simulated"), devices["trigger"]};
    c.led = {devices["led"].value("backend", "simulated"), devices["led"]};
    c.lamp_ids = d->sim_->context().lamp_ids;
    c.settle_ms = so.settle_ms;
    // 1/30 s, f/8, ISO 100: the simulated camera's well-exposed shot.
    c.exposure.shutter_s = 1.0 / 30;
    c.exposure.aperture = 8;
    c.exposure.iso = 100;
  } else {
    if (o.config_file.empty()) return make_error("no config file given (--config FILE), and not --simulate");
    auto cfg = load_config(o.config_file);
    if (!cfg) return cfg.error();
    d->config_ = std::move(*cfg);
  }
  Config& c = d->config_;
  if (!o.listen.empty()) {
    if (auto s = parse_listen(o.listen, c.listen_host, c.listen_port); !s) return s.error();
  }
  if (!o.store.empty()) c.store = o.store;
  if (!o.token_file.empty()) c.token_file = o.token_file;
  if (o.plain_tcp) c.plain_tcp = true;
  d->advertise_ = o.advertise;

  auto store = Store::open(c.store);
  if (!store) return store.error();
  d->store_ = std::move(*store);
  if (d->faults_) {
    std::shared_ptr<FaultPlan> plan = d->faults_;
    d->store_->set_write_faults([plan](const fs::path&) {
      WriteFault f;
      if (plan->draw(Fault::store_slow)) f.delay = std::chrono::milliseconds(plan->sizes().store_slow_ms);
      if (plan->draw(Fault::store_enospc)) {
        f.error = ENOSPC;
      } else if (plan->draw(Fault::store_eio)) {
        f.error = EIO;
      }
      return f;
    });
  }
  auto token = ensure_token(c.token_path());
  if (!token) return token.error();
  d->token_ = *token;
  if (!c.plain_tcp) {
    auto fp = ensure_tls_identity(c);
    if (!fp) return fp.error();
    d->fingerprint_ = *fp;
  }

  auto& reg = DeviceRegistry::instance();
  RigDevices dev;
  auto lamps = build(reg.lamps, "lamps", c.lamps);
  if (!lamps) return lamps.error();
  dev.lamps = std::move(*lamps);
  auto camera = build(reg.cameras, "camera", c.camera);
  if (!camera) return camera.error();
  dev.camera = std::move(*camera);
  d->camera_ = dev.camera.get();
  if (d->faults_) {
    d->sim_->bridge().set_fault_plan(d->faults_);
    if (auto* sc = as_simulated(d->camera_)) sc->set_fault_plan(d->faults_);
    VLOG_WARN("Rig", "simulated rig with injected faults: {}", d->faults_->spec());
  }
  if (c.trigger.backend != "none") {
    auto trigger = build(reg.triggers, "trigger", c.trigger);
    if (!trigger) return trigger.error();
    dev.trigger = std::move(*trigger);
  }
  if (c.led.backend != "none") {
    auto led = build(reg.leds, "led", c.led);
    if (!led) return led.error();
    dev.led = std::move(*led);
  }

  RigOptions ro;
  ro.name = c.name;
  ro.lamp_ids = c.lamp_ids;
  ro.lamp_positions = c.lamp_positions;
  const int count = dev.lamps->count();
  if (ro.lamp_positions.empty()) {
    auto ring = thesis_ring_positions();
    if (count > static_cast<int>(ring.size())) {
      return make_error("lamps: " + std::to_string(count) + " lamps but no lamps.positions_m in the config (the "
                        "default thesis ring has " + std::to_string(ring.size()) + " positions)");
    }
    ro.lamp_positions.assign(ring.begin(), ring.begin() + count);
  }
  if (static_cast<int>(ro.lamp_positions.size()) != count) {
    return make_error("lamps: the back-end has " + std::to_string(count) + " lamps but " +
                      std::to_string(ro.lamp_positions.size()) + " positions are configured");
  }
  ro.exposure = c.exposure;
  ro.ambient_warning = c.ambient_warning;
  ro.settle_ms = c.settle_ms;
  ro.owner_state_file = c.store / "lamps-owner.json";
  if (d->sim_) {
    ro.simulated = true;
    SimulatedRig* sim = d->sim_.get();
    Camera* cam = d->camera_;
    ro.sim.scenes = {sim->destination_scene(), sim->source_scene()};
    ro.sim.select_scene = [sim, cam](veneer::io::Role role, const std::string&) {
      if (auto* sc = as_simulated(cam)) {
        if (auto s = sc->set_scene(sim->scene_for(role)); !s) VLOG_WARN("Camera", "{}", s.message());
      }
    };
    ro.sim.move_hand_lamp = [cam](const cv::Vec3d& p) {
      if (auto* sc = as_simulated(cam)) sc->set_hand_lamp(p);
    };
    ro.sim.finish_set = [cam](veneer::io::ImageSet& set) {
      auto* sc = as_simulated(cam);
      if (!sc) return;
      veneer::io::CameraInfo info = sc->camera_info();
      set.camera.model = info.model.empty() ? set.camera.model : info.model;
      set.camera.focal_px = info.focal_px;
      set.camera.cx = info.cx;
      set.camera.cy = info.cy;
      // A rig lamp at full white gives irradiance 1 at the origin; the
      // camera's gain puts that in image units.
      const float g = static_cast<float>(sc->gain());
      for (auto& light : set.lights) light.intensity = cv::Vec3f(g, g, g);
      if (auto truth = sc->truth(); truth) {
        set.truth = std::move(*truth);
      } else {
        VLOG_WARN("Camera", "{}: no ground truth: {}", set.id, truth.message());
      }
    };
  }
  d->rig_ = std::make_unique<Rig>(std::move(dev), *d->store_, std::move(ro));

  ServerOptions so;
  so.host = c.listen_host;
  so.port = c.listen_port;
  so.token = d->token_;
  so.plain_tcp = c.plain_tcp;
  so.tls_key_file = c.tls_key_path().string();
  so.tls_cert_file = c.tls_cert_path().string();
  d->server_ = std::make_unique<Server>(*d->rig_, so);
  return d;
}

bool loopback_only(const std::string& host) {
  return host == "localhost" || host == "::1" || host.rfind("127.", 0) == 0;
}

veneer::Status Daemon::start() {
  if (auto s = server_->start(); !s) return s;
  if (config_.plain_tcp) {
    VLOG_WARN("Server", "the API is served in PLAIN TCP (configured so): no encryption, the access token and every "
              "photo readable on the network; clients connect with --plain-tcp");
  } else {
    VLOG_INFO("Server", "TLS 1.3; certificate fingerprint (SHA-256) {}", fingerprint_);
  }
  rig_->start();
  if (!advertise_) {
  } else if (loopback_only(config_.listen_host)) {
    VLOG_INFO("Server", "DNS-SD: not advertised (listening on {} only)", config_.listen_host);
  } else if (auto reach = veneer::dnssd::reach_of(config_.listen_host, server_->dual_stack()); !reach) {
    VLOG_WARN("Server", "DNS-SD: not advertising: listening on {}: {}", config_.listen_host, reach.message());
  } else {
    // Advertised only where the API listens (issue 37): a rig bound to one
    // address is announced on that address's interface and family alone.
    veneer::dnssd::Advertisement ad;
    ad.name = config_.name;
    ad.type = veneer::wire::kServiceType;
    ad.port = port();
    ad.txt = veneer::wire::rig_txt(config_.name, veneer::wire::software_version(), fingerprint_);
    ad.reach = *reach;
    auto a = veneer::dnssd::Advertiser::start(ad);
    if (a) {
      advertiser_ = std::move(*a);
      VLOG_INFO("Server", "DNS-SD: advertising '{}' as {} on port {} ({})", ad.name, ad.type, ad.port,
                ad.reach.describe());
    } else {
      VLOG_WARN("Server", "DNS-SD: not advertising {}: {}", ad.type, a.message());
    }
  }
  return {};
}

std::string Daemon::advertised_name() const { return advertiser_ ? advertiser_->name() : ""; }

void Daemon::stop() {
  advertiser_.reset();
  if (rig_) rig_->stop();
  if (server_) server_->stop();
  if (faults_ && !faults_reported_) {
    faults_reported_ = true;
    VLOG_INFO("Rig", "injected faults: {}", faults_->counts_json());
  }
}

uint16_t Daemon::port() const { return server_ ? server_->port() : 0; }

Daemon::~Daemon() { stop(); }

}  // namespace veneerd
