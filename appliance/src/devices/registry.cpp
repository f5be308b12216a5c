// register_simulated_devices(): the back-ends of appliance/src/devices/.
#include <mutex>

#include "veneerd/devices/hue_lamps.hpp"
#include "veneerd/devices/registry.hpp"
#include "veneerd/devices/simulated.hpp"
#include "veneerd/devices/simulated_camera.hpp"

namespace veneerd {

void register_simulated_devices() {
  static std::mutex mutex;
  std::lock_guard lock(mutex);
  auto& reg = DeviceRegistry::instance();
  DeviceRegistry::add<Lamps>(reg.lamps, "hue", [](const nlohmann::json& section) -> veneer::Expected<std::unique_ptr<Lamps>> {
    auto o = HueLampsOptions::from_json(section);
    if (!o) return o.error();
    auto lamps = HueLamps::create(*o);
    if (!lamps) return lamps.error();
    return std::unique_ptr<Lamps>(std::move(*lamps));
  });
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
  DeviceRegistry::add<StatusLed>(reg.leds, "none", [](const nlohmann::json&) -> veneer::Expected<std::unique_ptr<StatusLed>> {
    return std::unique_ptr<StatusLed>(std::make_unique<NoLed>());
  });
}

}  // namespace veneerd
