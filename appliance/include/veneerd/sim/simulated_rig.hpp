#pragma once
// The whole simulated device set in one call, for `veneerd --simulate` and the
// integration tests: starts a Hue bridge emulator on loopback with 7 lamps and
// hands out the config sections that point the real "hue" lamps backend and the
// "simulated" camera at it.
//
//   auto rig = veneerd::SimulatedRig::start({.scenes = {"bull", "stone"}});
//   if (!rig) fail(rig.message());
//   nlohmann::json devices = (*rig)->devices_config();
//   // devices["lamps"]   = {"backend": "hue", "bridge": "127.0.0.1:<port>", "key": .., "lamps": ["1".."7"], ..}
//   // devices["camera"]  = {"backend": "simulated", <hue section>, "scene": "bull", "preview_scene": "stone", ..}
//   // devices["trigger"] = {"backend": "simulated"},  devices["led"] = {"backend": "simulated"}
//   // then build each through DeviceRegistry (register_simulated_devices() and
//   // register_hardware_devices() first: the lamps are the real "hue" back-end),
//   // e.g. DeviceRegistry::make(reg.lamps, "lamps", "hue", devices["lamps"]).
//   // Before a capture of role R: as_simulated(camera)->set_scene((*rig)->scene_for(R)).
//
// The emulator lives as long as the SimulatedRig object; destroy the devices
// first (they only talk HTTP to it, so a late request just fails).
#include <memory>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>

#include "veneer/io/imageset.hpp"
#include "veneer/util/expected.hpp"
#include "veneerd/sim/hue_emulator.hpp"
#include "veneerd/hw/hue_lamps.hpp"
#include "veneerd/devices/registry.hpp"
#include "veneerd/sim/simulated.hpp"
#include "veneerd/sim/simulated_camera.hpp"

namespace veneerd {

struct SimulatedRigOptions {
  // Scenes the camera can show: [0] is photographed as the destination,
  // [1] (or [0] when only one) as the source and shown by live view.
  std::vector<std::string> scenes{"bull", "stone"};
  int lamps = 7;                       // thesis rig: 7 lamps fitted
  std::string key = "veneer-sim";      // bridge user
  cv::Size size{1024, 680};            // still size [px]
  cv::Size preview_size{1024, 680};    // live-view size [px]
  std::string preview_motion;          // live view in motion: a `simulate --motion` SPEC (SimulatedCameraOptions)
  int preview_motion_frames = 60;      // ... played back and forth over this many frames
  double noise_sigma = 0.002;          // sensor noise
  bool raw = true;                     // the camera also delivers a DNG of each still (SimulatedCameraOptions::raw)
  int apply_delay_ms = 50;             // emulator: change visible this long after the ack
  int latency_ms = 5;                  // emulator: per-request latency
  bool rate_limits = true;             // emulator enforces 10 light/s, 1 group/s, 3 in flight
  int settle_ms = 80;                  // lamps wait this after the ack (covers apply_delay_ms)
  double light_rate = 8.0;             // light commands per second the lamps allow themselves (HueLampsOptions)
  int timeout_ms = 2000;               // per Hue command, retries included
  std::string host = "127.0.0.1";      // emulator listen address
  uint16_t port = 0;                   // 0 = any free port
};

// Shared state of the simulated devices (registry.hpp forward-declares it).
struct SimulatedRigContext {
  std::string bridge;                  // "127.0.0.1:<port>"
  std::string key;
  std::vector<std::string> lamp_ids;   // "1".."N", ring order
  std::vector<std::string> scenes;
};

class SimulatedRig {
 public:
  static veneer::Expected<std::unique_ptr<SimulatedRig>> start(const SimulatedRigOptions& options = {});
  ~SimulatedRig();

  HueBridgeEmulator& bridge();
  const SimulatedRigOptions& options() const;
  const SimulatedRigContext& context() const;

  const std::vector<std::string>& scenes() const;
  std::string destination_scene() const;         // scenes[0]
  std::string source_scene() const;              // scenes[1] or scenes[0]
  std::string scene_for(veneer::io::Role role) const;  // source -> source_scene(), else destination

  nlohmann::json lamps_config() const;    // section for lamps backend "hue"
  nlohmann::json camera_config() const;   // section for camera backend "simulated"
  // {"lamps": {"backend":"hue",...}, "camera": {"backend":"simulated",...},
  //  "trigger": {"backend":"simulated"}, "led": {"backend":"simulated"}}
  nlohmann::json devices_config() const;

  // Conveniences that build the devices directly (same code as the registry).
  veneer::Expected<std::unique_ptr<hw::HueLamps>> make_lamps() const;
  veneer::Expected<std::unique_ptr<SimulatedCamera>> make_camera() const;

 private:
  SimulatedRig() = default;
  SimulatedRigOptions options_;
  SimulatedRigContext context_;
  std::unique_ptr<HueBridgeEmulator> bridge_;
};

}  // namespace veneerd
