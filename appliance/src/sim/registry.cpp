// register_simulated_devices(): the simulated back-ends of appliance/src/sim/.
// (The simulated rig's lamps are the real "hue" back-end talking to the bridge
// emulator: register_hardware_devices() registers it.)
#include <mutex>

#include "veneerd/devices/registry.hpp"
#include "veneerd/sim/simulated.hpp"
#include "veneerd/sim/simulated_camera.hpp"

namespace veneerd {

void register_simulated_devices() {
  static std::mutex mutex;
  std::lock_guard lock(mutex);
  auto& reg = DeviceRegistry::instance();
  DeviceRegistry::add<Camera>(reg.cameras, "simulated", [](const nlohmann::json& section) -> veneer::Expected<std::unique_ptr<Camera>> {
    auto o = SimulatedCameraOptions::from_json(section);
    if (!o) return o.error();
    auto camera = SimulatedCamera::create(*o);
    if (!camera) return camera.error();
    return std::unique_ptr<Camera>(std::move(*camera));
  });
  DeviceRegistry::add<Trigger>(reg.triggers, "simulated", [](const nlohmann::json&) -> veneer::Expected<std::unique_ptr<Trigger>> {
    return std::unique_ptr<Trigger>(std::make_unique<SimulatedTrigger>());
  });
  DeviceRegistry::add<StatusLed>(reg.leds, "simulated", [](const nlohmann::json&) -> veneer::Expected<std::unique_ptr<StatusLed>> {
    return std::unique_ptr<StatusLed>(std::make_unique<SimulatedLed>());
  });
}

}  // namespace veneerd
