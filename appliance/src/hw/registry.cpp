// register_hardware_devices(): the real-hardware back-ends of appliance/src/hw/.
#include <mutex>

#include "veneerd/hw/hue_lamps.hpp"
#include "veneerd/devices/registry.hpp"
#include "veneerd/hw/check.hpp"
#include "veneerd/hw/gphoto2.hpp"
#include "veneerd/hw/gpio.hpp"
#include "veneerd/hw/uvc.hpp"

namespace veneerd {

void register_hardware_devices() {
  static std::mutex mutex;
  std::lock_guard lock(mutex);
  auto& reg = DeviceRegistry::instance();
  DeviceRegistry::add<Lamps>(reg.lamps, "hue", [](const nlohmann::json& s) -> veneer::Expected<std::unique_ptr<Lamps>> {
    auto o = hw::HueLampsOptions::from_json(s);
    if (!o) return o.error();
    auto lamps = hw::HueLamps::create(*o);
    if (!lamps) return lamps.error();
    return std::unique_ptr<Lamps>(std::move(*lamps));
  });
  DeviceRegistry::add<Camera>(reg.cameras, "gphoto2", [](const nlohmann::json& s) -> veneer::Expected<std::unique_ptr<Camera>> {
    auto o = hw::parse_gphoto2_options(s, "camera");
    if (!o) return o.error();
    // A network camera has no USB arrivals to watch: a lost connection is reopened on use.
    auto hotplug = hw::is_network_port(o->port) ? nullptr : hw::make_libusb_hotplug();
    auto cam = std::make_unique<hw::Gphoto2Camera>(hw::make_libgphoto2_api(), std::move(hotplug), *o);
    // A camera that is not there yet is not fatal: it is opened when it arrives.
    return std::unique_ptr<Camera>(std::move(cam));
  });
  DeviceRegistry::add<Camera>(reg.cameras, "uvc", [](const nlohmann::json& s) -> veneer::Expected<std::unique_ptr<Camera>> {
    auto o = hw::parse_uvc_options(s, "camera");
    if (!o) return o.error();
    return std::unique_ptr<Camera>(std::make_unique<hw::UvcCamera>(*o));
  });
  DeviceRegistry::add<Trigger>(reg.triggers, "gpio", [](const nlohmann::json& s) -> veneer::Expected<std::unique_ptr<Trigger>> {
    if (auto v = validate_device_section("trigger", s); !v) return v.error();
    auto line = hw::parse_gpio_line(s, "trigger", "button_line");
    auto timing = hw::parse_gpio_timing(s, "trigger");
    auto t = hw::GpioTrigger::open(*line, *timing);
    if (!t) return t.error();
    if (auto st = (*t)->start(); !st) return st.error();
    return std::unique_ptr<Trigger>(std::move(*t));
  });
  DeviceRegistry::add<StatusLed>(reg.leds, "gpio", [](const nlohmann::json& s) -> veneer::Expected<std::unique_ptr<StatusLed>> {
    nlohmann::json section = s;
    // An LED lights when the line is high unless the config says otherwise.
    if (!section.contains("active_low")) section["active_low"] = false;
    auto line = hw::parse_gpio_line(section, "led", "led_line");
    if (!line) return line.error();
    auto led = hw::GpioLed::open(*line);
    if (!led) return led.error();
    if (auto st = (*led)->start(); !st) return st.error();
    return std::unique_ptr<StatusLed>(std::move(*led));
  });
  // A rig without a status LED.
  DeviceRegistry::add<StatusLed>(reg.leds, "none", [](const nlohmann::json&) -> veneer::Expected<std::unique_ptr<StatusLed>> {
    return std::unique_ptr<StatusLed>(std::make_unique<NoLed>());
  });
}

}  // namespace veneerd
