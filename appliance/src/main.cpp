// veneerd — the rig daemon.
//   veneerd --simulate [--scenes bull,stone] [--listen 127.0.0.1:7878] [--store DIR] [--size 1024x680]
//   veneerd --config /etc/veneer/veneerd.json
//   veneerd --check-hardware [--config FILE]
//   veneerd --fingerprint [--config FILE | --store DIR]   (the TLS certificate's fingerprint; made if missing)
//   veneerd ptpip-twin --bridge HOST:PORT --key KEY --lamps 1,2,3   (a PTP/IP camera twin)
#include <csignal>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <sstream>

#include <sys/resource.h>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "veneer/util/cpu_check.hpp"
#include "veneer/util/log.hpp"
#include "veneerd/daemon.hpp"
#include "veneerd/sim/ptpip_twin.hpp"
#include "veneerd/hw/hue_setup.hpp"
#include "veneerd/hw/sd_notify.hpp"
#if __has_include("veneerd/hw/check.hpp")
#include "veneerd/hw/check.hpp"
#define VENEERD_HAVE_HW_CHECK 1
#endif

namespace {

bool parse_size(const std::string& text, cv::Size& out) {
  int w = 0, h = 0;
  char x = 0, extra = 0;
  std::istringstream in(text);
  if (!(in >> w >> x >> h) || (x != 'x' && x != 'X') || (in >> extra) || w < 16 || h < 16 || w > 8192 || h > 8192) {
    return false;
  }
  out = {w, h};
  return true;
}

std::vector<std::string> split(const std::string& text) {
  std::vector<std::string> out;
  std::string item;
  std::istringstream in(text);
  while (std::getline(in, item, ',')) {
    if (!item.empty()) out.push_back(item);
  }
  return out;
}

}  // namespace

int main(int argc, char** argv) {
  // `veneerd hue discover|pair|lamps|flash ...`: setting up the Hue bridge.
  if (argc > 1 && std::string(argv[1]) == "hue") {
    return veneerd::hw::hue_command({argv + 1, argv + argc}, std::cout, std::cerr);
  }
  // `veneerd ptpip-twin ...`: a PTP/IP camera twin serving simulator renders.
  if (argc > 1 && std::string(argv[1]) == "ptpip-twin") {
    return veneerd::ptpip_twin_command({argv + 1, argv + argc}, std::cout, std::cerr);
  }
  CLI::App app{"veneerd — the Veneer capture rig daemon (camera, ring of lamps, button; protobuf API on TCP)"};
  app.set_version_flag("--version", std::string("veneerd ") + VENEER_VERSION);
  veneerd::DaemonOptions o;
  bool check_hardware = false;
  std::string config, scenes = "bull,stone", size = "1024x680", preview_size, listen, store, token_file, log_spec;
  unsigned long long max_file_bytes = 0;
  app.add_flag("--simulate", o.simulate, "run the whole rig simulated in this process (Hue bridge emulator, camera, button)");
  app.add_option("--config", config, "config file of a real rig (JSON)");
  app.add_flag("--check-hardware", check_hardware, "probe the configured hardware and exit");
  app.add_option("--scenes", scenes, "simulated rig: destination,source scene names")->capture_default_str();
  app.add_option("--size", size, "simulated rig: still size WxH")->capture_default_str();
  app.add_option("--preview-size", preview_size,
                 "simulated rig: live-view size WxH (default: --size, at most 1024 px wide as a DSLR's live view)");
  app.add_option("--preview-motion", o.preview_motion,
                 "simulated rig: the live view moves, a SPEC as `veneer simulate --motion` takes (shift=DX:DY, rotate, "
                 "scale, turn, lamp=sweep), e.g. shift=30:0,rotate=5,lamp=sweep");
  app.add_option("--preview-motion-frames", o.preview_motion_frames,
                 "simulated rig: the motion is played back and forth over this many live frames")
      ->capture_default_str();
  app.add_option("--noise", o.noise_sigma, "simulated rig: sensor noise (fraction of full scale)")->capture_default_str();
  app.add_option("--hue-latency-ms", o.hue_latency_ms, "simulated rig: bridge emulator latency per request [ms]")
      ->capture_default_str();
  app.add_option("--faults", o.faults,
                 "simulated rig: inject faults, a SPEC such as bridge.503=0.02,camera.gone=0.01,store.eio=0.01,seed=7 "
                 "(appliance/include/veneerd/sim/fault_plan.hpp lists them)");
  app.add_option("--hue-light-rate", o.hue_light_rate,
                 "simulated rig: light commands per second the lamps allow themselves (default Hue's 8; up to 50 "
                 "with --no-rate-limits)");
  app.add_option("--hue-apply-delay-ms", o.hue_apply_delay_ms,
                 "simulated rig: a lamp change shows this long after the bridge's ack (default 50) [ms]");
  bool no_limits = false;
  app.add_flag("--no-rate-limits", no_limits, "simulated rig: the bridge emulator does not enforce Hue's rate limits");
  app.add_option("--listen", listen, "address to serve the API on, host:port (default 127.0.0.1:7878)");
  app.add_option("--store", store, "folder for the captured sets (and the token)");
  app.add_option("--token-file", token_file, "access token file (default <store>/token, created 0600)");
  bool fingerprint = false;
  app.add_flag("--fingerprint", fingerprint,
               "print the fingerprint (SHA-256) of the rig's TLS certificate and exit (the key and certificate are "
               "made in the store on first use)");
  app.add_flag("--plain-tcp", o.plain_tcp,
               "serve the API in plain TCP, without TLS: the token and every photo readable on the network (also "
               "\"plain_tcp\": true in the config)");
  bool no_advertise = false;
  app.add_flag("--no-advertise", no_advertise, "do not advertise the API on the LAN as _veneer._tcp (DNS-SD)");
  app.add_option("--log", log_spec, "log levels, e.g. 'debug' or 'Camera=debug,Lamps=warn'");
  app.add_option("--max-file-bytes", max_file_bytes, "largest file the daemon may write (RLIMIT_FSIZE; for tests)");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  }
  if (!log_spec.empty()) veneer::log::set_levels(log_spec);
  auto fail = [](const std::string& what, int code = 1) {
    std::cerr << "veneerd: " << what << "\n";
    return code;
  };

  if (check_hardware) {
#ifdef VENEERD_HAVE_HW_CHECK
    nlohmann::json doc = nlohmann::json::object();
    if (!config.empty()) {
      std::ifstream in(config);
      if (!in) return fail(config + ": cannot open config file");
      doc = nlohmann::json::parse(in, nullptr, false, true);
      if (doc.is_discarded()) return fail(config + ": not valid JSON");
    }
    return veneerd::check_hardware(std::cout, doc);
#else
    return fail("--check-hardware: this build has no hardware back-ends", 2);
#endif
  }
  if (fingerprint) {
    veneerd::Config c;
    if (!config.empty()) {
      auto loaded = veneerd::load_config(config);
      if (!loaded) return fail(loaded.message());
      c = std::move(*loaded);
    } else if (o.simulate) {
      c.name = "veneer-simulated-rig";
    }
    if (!store.empty()) c.store = store;
    auto fp = veneerd::ensure_tls_identity(c);
    if (!fp) return fail(fp.message());
    std::printf("%s\n", fp->c_str());
    return 0;
  }
  if (!o.simulate && config.empty()) return fail("give --simulate or --config FILE (see --help)", 2);
  o.config_file = config;
  o.scenes = split(scenes);
  if (o.scenes.empty()) return fail("--scenes: no scene named", 2);
  if (!parse_size(size, o.size)) return fail("--size '" + size + "': expected WxH, e.g. 256x170", 2);
  if (!preview_size.empty() && !parse_size(preview_size, o.preview_size)) {
    return fail("--preview-size '" + preview_size + "': expected WxH", 2);
  }
  o.hue_rate_limits = !no_limits;
  o.advertise = !no_advertise;
  o.listen = listen.empty() && o.simulate ? "127.0.0.1:7878" : listen;
  o.store = store.empty() && o.simulate ? "veneer-sets" : store;
  o.token_file = token_file;

  // Signals: a write beyond the file-size limit fails with EFBIG instead of
  // killing us; a vanished peer is an error code, not SIGPIPE.
  std::signal(SIGPIPE, SIG_IGN);
  std::signal(SIGXFSZ, SIG_IGN);
  if (max_file_bytes > 0) {
    struct rlimit lim {static_cast<rlim_t>(max_file_bytes), static_cast<rlim_t>(max_file_bytes)};
    if (::setrlimit(RLIMIT_FSIZE, &lim) != 0) return fail("--max-file-bytes: setrlimit failed");
  }
  sigset_t stop_signals;
  sigemptyset(&stop_signals);
  sigaddset(&stop_signals, SIGINT);
  sigaddset(&stop_signals, SIGTERM);
  pthread_sigmask(SIG_BLOCK, &stop_signals, nullptr);  // every thread made from here on inherits it

  auto daemon = veneerd::Daemon::create(o);
  if (!daemon) return fail(daemon.message());
  if (auto s = (*daemon)->start(); !s) return fail(s.message());
  const auto& c = (*daemon)->config();
  std::printf("veneerd: listening on %s:%u, store %s, token %s\n", c.listen_host.c_str(),
              static_cast<unsigned>((*daemon)->port()), c.store.c_str(), c.token_path().c_str());
  if (c.plain_tcp) {
    std::printf("veneerd: PLAIN TCP (configured so): the API is not encrypted\n");
  } else {
    std::printf("veneerd: TLS 1.3, certificate fingerprint (SHA-256) %s\n", (*daemon)->fingerprint().c_str());
  }
  std::fflush(stdout);

  // systemd (Type=notify, WatchdogSec): ready now, then a ping at half the
  // watchdog interval for as long as the daemon runs. Outside systemd these
  // are no-ops.
  veneerd::hw::sd_ready();
  const auto watchdog = veneerd::hw::sd_watchdog_interval();
  int sig = 0;
  if (watchdog) {
    const auto half = *watchdog / 2;
    struct timespec wait {static_cast<time_t>(half.count() / 1000000), static_cast<long>(half.count() % 1000000) * 1000};
    while ((sig = sigtimedwait(&stop_signals, nullptr, &wait)) < 0) veneerd::hw::sd_watchdog();
  } else {
    sigwait(&stop_signals, &sig);
  }
  veneerd::hw::sd_stopping();
  VLOG_INFO("Rig", "signal {}: stopping", sig);
  (*daemon)->stop();
  return 0;
}
