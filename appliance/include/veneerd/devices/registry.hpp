#pragma once
// Device back-ends are picked by name from the config file. Each back-end
// registers a factory; its config section (JSON object) is passed through.
//   lamps:   "hue"
//   camera:  "simulated", "gphoto2", "uvc"
//   trigger: "simulated", "gpio";   led: "simulated", "gpio", "none"
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "veneer/util/expected.hpp"
#include "veneerd/devices/camera.hpp"
#include "veneerd/devices/lamps.hpp"
#include "veneerd/devices/trigger.hpp"

namespace veneerd {

// Shared state the simulated devices need (which scene the camera sees, the
// bridge emulator's address, ...). Real back-ends ignore it.
struct SimulatedRigContext;

template <class Device>
using Factory = std::function<veneer::Expected<std::unique_ptr<Device>>(const nlohmann::json& section)>;

struct DeviceRegistry {
  std::vector<std::pair<std::string, Factory<Lamps>>> lamps;
  std::vector<std::pair<std::string, Factory<Camera>>> cameras;
  std::vector<std::pair<std::string, Factory<Trigger>>> triggers;
  std::vector<std::pair<std::string, Factory<StatusLed>>> leds;

  static DeviceRegistry& instance() {
    static DeviceRegistry r;
    return r;
  }
  // Adds a factory under `name` unless one is registered already (registration may run twice).
  template <class Device>
  static void add(std::vector<std::pair<std::string, Factory<Device>>>& list, const std::string& name,
                  Factory<Device> factory) {
    for (const auto& entry : list)
      if (entry.first == name) return;
    list.emplace_back(name, std::move(factory));
  }
  // Looks `name` up in `list`; the error lists the names that exist.
  template <class Device>
  static veneer::Expected<std::unique_ptr<Device>> make(
      const std::vector<std::pair<std::string, Factory<Device>>>& list, const std::string& kind,
      const std::string& name, const nlohmann::json& section) {
    std::string known;
    for (const auto& [n, f] : list) {
      if (n == name) return f(section);
      known += (known.empty() ? "" : ", ") + n;
    }
    return veneer::make_error("unknown " + kind + " backend '" + name + "' (known: " + known + ")");
  }
};

// Explicit registration (static archives drop self-registering objects).
void register_simulated_devices();  // appliance/src/sim/ (simulated camera, trigger, LED)
void register_hardware_devices();   // appliance/src/hw/ (hue, gphoto2, uvc, gpio, LED "none")

}  // namespace veneerd
