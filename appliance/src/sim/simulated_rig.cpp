#include "veneerd/sim/simulated_rig.hpp"

#include <algorithm>

#include "veneer/sim/simulator.hpp"
#include "veneer/util/log.hpp"

namespace veneerd {

using json = nlohmann::json;

veneer::Expected<std::unique_ptr<SimulatedRig>> SimulatedRig::start(const SimulatedRigOptions& options) {
  if (options.scenes.empty()) return veneer::make_error("simulated rig: no scenes given");
  auto known = veneer::sim::scene_names();
  for (const auto& s : options.scenes) {
    if (std::find(known.begin(), known.end(), s) == known.end()) {
      std::string list;
      for (const auto& n : known) {
        if (!list.empty()) list += ", ";
        list += n;
      }
      return veneer::make_error("simulated rig: unknown scene '" + s + "' (known: " + list + ")");
    }
  }
  if (options.lamps < 1 || options.lamps > 64)
    return veneer::make_error("simulated rig: lamps must be 1..64, got " + std::to_string(options.lamps));
  std::unique_ptr<SimulatedRig> rig(new SimulatedRig());
  rig->options_ = options;
  const HueEmulatorOptions eo{.lamps = options.lamps, .key = options.key, .apply_delay_ms = options.apply_delay_ms,
                              .latency_ms = options.latency_ms, .enforce_limits = options.rate_limits};
  rig->bridge_ = std::make_unique<HueBridgeEmulator>(eo);
  if (auto st = rig->bridge_->start(options.host, options.port); !st) return st.error();
  rig->context_.bridge = rig->bridge_->address();
  rig->context_.key = options.key;
  for (int i = 1; i <= options.lamps; ++i) rig->context_.lamp_ids.push_back(std::to_string(i));
  rig->context_.scenes = options.scenes;
  VLOG_INFO("Rig", "simulated rig: bridge emulator at {}, {} lamps, scenes {} / {}", rig->context_.bridge,
            options.lamps, rig->destination_scene(), rig->source_scene());
  return rig;
}

SimulatedRig::~SimulatedRig() {
  if (bridge_) bridge_->stop();
}

HueBridgeEmulator& SimulatedRig::bridge() { return *bridge_; }
const SimulatedRigOptions& SimulatedRig::options() const { return options_; }
const SimulatedRigContext& SimulatedRig::context() const { return context_; }
const std::vector<std::string>& SimulatedRig::scenes() const { return context_.scenes; }
std::string SimulatedRig::destination_scene() const { return context_.scenes.front(); }
std::string SimulatedRig::source_scene() const {
  return context_.scenes.size() > 1 ? context_.scenes[1] : context_.scenes.front();
}
std::string SimulatedRig::scene_for(veneer::io::Role role) const {
  return role == veneer::io::Role::source ? source_scene() : destination_scene();
}

json SimulatedRig::lamps_config() const {
  hw::HueLampsOptions o;
  o.bridge = context_.bridge;
  o.key = context_.key;
  o.lamps = context_.lamp_ids;
  o.group = std::string(1, '1');  // the emulator's "Ring" room holds exactly the ring lamps
  o.settle_ms = options_.settle_ms;
  o.light_rate = options_.light_rate;
  o.timeout_ms = options_.timeout_ms;
  return o.to_json();
}

json SimulatedRig::camera_config() const {
  auto lamps = hw::HueLampsOptions::from_json(lamps_config());
  const SimulatedCameraOptions c{.bridge = lamps ? *lamps : hw::HueLampsOptions{},
                                 .scene = destination_scene(),
                                 .preview_scene = source_scene(),
                                 .size = options_.size,
                                 .preview_size = options_.preview_size,
                                 .noise_sigma = options_.noise_sigma,
                                 .preview_motion = options_.preview_motion,
                                 .preview_motion_frames = options_.preview_motion_frames,
                                 .raw = options_.raw};
  return c.to_json();
}

json SimulatedRig::devices_config() const {
  json lamps = lamps_config();
  lamps["backend"] = "hue";
  json camera = camera_config();
  camera["backend"] = "simulated";
  return json{{"lamps", lamps},
              {"camera", camera},
              {"trigger", {{"backend", "simulated"}}},
              {"led", {{"backend", "simulated"}}}};
}

veneer::Expected<std::unique_ptr<hw::HueLamps>> SimulatedRig::make_lamps() const {
  auto o = hw::HueLampsOptions::from_json(lamps_config());
  if (!o) return o.error();
  return hw::HueLamps::create(*o);
}

veneer::Expected<std::unique_ptr<SimulatedCamera>> SimulatedRig::make_camera() const {
  auto o = SimulatedCameraOptions::from_json(camera_config());
  if (!o) return o.error();
  return SimulatedCamera::create(*o);
}

}  // namespace veneerd
