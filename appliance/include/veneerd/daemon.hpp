#pragma once
// veneerd assembled: devices (simulated or from a config file), the set store,
// the rig and the API server. main.cpp is argument parsing around this; the
// integration tests use it to run a whole rig in their own process when they
// need to reach into the simulated devices (fault injection).
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "veneer/dnssd/dnssd.hpp"
#include "veneer/util/expected.hpp"
#include "veneerd/config.hpp"
#include "veneerd/rig.hpp"
#include "veneerd/server.hpp"
#include "veneerd/store.hpp"

namespace veneerd {

class SimulatedRig;
class SimulatedCamera;
class FaultPlan;

struct DaemonOptions {
  bool simulate = false;
  std::filesystem::path config_file;      // real rigs (ignored with simulate)
  // Overrides of the config (empty = keep):
  std::string listen;                     // "host:port"
  std::filesystem::path store;
  std::filesystem::path token_file;
  bool plain_tcp = false;                 // serve the API in plain TCP (also "plain_tcp" in the config)
  // Simulated rig:
  std::vector<std::string> scenes{"bull", "stone"};
  cv::Size size{1024, 680};               // still size [px]
  cv::Size preview_size{0, 0};            // live-view size [px]; 0 = same as size
  std::string preview_motion;             // live view in motion: a `veneer simulate --motion` SPEC; empty = still
  int preview_motion_frames = 60;         // ... played back and forth over this many frames
  double noise_sigma = 0.002;
  int hue_latency_ms = 5;                 // emulator's per-request latency
  bool hue_rate_limits = true;
  // Quicker lamps for long runs (the soak): the lamps' own pace [commands/s]
  // (0 = Hue's 8/s; above 10 wants hue_rate_limits off) and the emulator's
  // delay before a change shows (-1 = 50 ms; the lamps settle 30 ms longer).
  double hue_light_rate = 0;
  int hue_apply_delay_ms = -1;
  // Faults the simulated devices and the store take (veneerd/sim/fault_plan.hpp
  // SPEC, e.g. "bridge.503=0.02,camera.gone=0.01,store.eio=0.01,seed=7"); empty = none.
  std::string faults;
  // Advertise the API as _veneer._tcp (DNS-SD, through avahi-daemon) when it
  // listens beyond loopback. Without avahi-daemon: one log line, no failure.
  bool advertise = true;
};

// Reads the token from `file`, creating it (32 random bytes as hex, mode 0600)
// when it does not exist.
veneer::Expected<std::string> ensure_token(const std::filesystem::path& file);
// The rig's TLS identity (key and certificate, made at first start, 0600):
// its fingerprint. For `veneerd --fingerprint`.
veneer::Expected<std::string> ensure_tls_identity(const Config& config);
// Reads a token file (whitespace trimmed).
veneer::Expected<std::string> read_token(const std::filesystem::path& file);

class Daemon {
 public:
  static veneer::Expected<std::unique_ptr<Daemon>> create(const DaemonOptions& options);
  ~Daemon();

  veneer::Status start();
  void stop();

  uint16_t port() const;
  // The DNS-SD name the rig advertises under ("" when it does not advertise).
  std::string advertised_name() const;
  const std::string& token() const { return token_; }
  // The certificate's fingerprint (veneer/proto/tls.hpp); "" in plain TCP.
  const std::string& fingerprint() const { return fingerprint_; }
  const Config& config() const { return config_; }
  Rig& rig() { return *rig_; }
  Store& store() { return *store_; }
  Server& server() { return *server_; }
  // The simulated devices (null for a real rig).
  SimulatedRig* simulated() { return sim_.get(); }
  SimulatedCamera* simulated_camera();
  // The fault plan the simulated rig runs with (null without --faults).
  std::shared_ptr<FaultPlan> faults() { return faults_; }

 private:
  Daemon() = default;
  Config config_;
  std::string token_;
  std::shared_ptr<FaultPlan> faults_;
  bool faults_reported_ = false;
  std::string fingerprint_;
  std::unique_ptr<SimulatedRig> sim_;
  std::unique_ptr<Store> store_;
  std::unique_ptr<Rig> rig_;
  std::unique_ptr<Server> server_;
  Camera* camera_ = nullptr;  // owned by rig_
  bool advertise_ = true;
  std::unique_ptr<veneer::dnssd::Advertiser> advertiser_;
};

// Whether `host` (a --listen host) is reachable only from this machine.
bool loopback_only(const std::string& host);

}  // namespace veneerd
