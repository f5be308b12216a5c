// Config validation of the hardware sections and --check-hardware on a
// machine without the hardware (this one).
#include <gtest/gtest.h>

#include <sstream>

#include "veneerd/sim/hue_emulator.hpp"
#include "veneerd/devices/registry.hpp"
#include "veneerd/hw/check.hpp"
#include "veneerd/hw/hue_setup.hpp"

namespace veneerd {
namespace {

using nlohmann::json;

std::string error_of(const json& doc) {
  auto s = validate_hardware_config(doc);
  return s.ok() ? "" : s.message();
}

TEST(HardwareConfig, OneClearMessagePerMistake) {
  EXPECT_EQ(error_of(json::parse(R"({"camera":{"backend":"gphoto2"},"trigger":{"backend":"gpio","line":"GPIO17"},
                                     "led":{"backend":"gpio","line":"GPIO27"}})")), "");
  EXPECT_EQ(error_of(json::parse(R"({"camera":{"backend":"canon"}})")),
            "camera.backend: unknown backend 'canon' (known: simulated, gphoto2, uvc)");
  EXPECT_EQ(error_of(json::parse(R"({"trigger":{"line":"GPIO17"}})")),
            "trigger.backend: missing (one of simulated, gpio)");
  EXPECT_NE(error_of(json::parse(R"({"trigger":{"backend":"gpio"}})")).find("trigger.line: missing"), std::string::npos);
  EXPECT_NE(error_of(json::parse(R"({"led":{"backend":"gpio","chip":"gpiochip0","line":4096}})")).find("led.line: offset 4096 out of range"),
            std::string::npos);
  EXPECT_NE(error_of(json::parse(R"({"camera":{"backend":"uvc","device":[1]}})")).find("camera.device"), std::string::npos);
  EXPECT_NE(error_of(json::parse(R"({"camera":{"backend":"gphoto2","shutter":"1/60"}})")).find("unknown field 'shutter'"),
            std::string::npos);
}

TEST(HardwareConfig, SharedGpioBlockFillsSections) {
  // config.cpp's "gpio": {"chip", "button_line", "led_line"} feeds the back-ends.
  json doc = json::parse(R"({"trigger":{"backend":"gpio"},"led":{"backend":"gpio"},
                             "gpio":{"chip":"gpiochip0","button_line":17,"led_line":27}})");
  EXPECT_EQ(error_of(doc), "");
  doc["gpio"]["button_line"] = 2000;
  EXPECT_NE(error_of(doc).find("trigger.button_line: offset 2000 out of range"), std::string::npos) << error_of(doc);
}

TEST(HardwareConfig, RegistryFactoriesRejectBadSections) {
  register_hardware_devices();
  auto& reg = DeviceRegistry::instance();
  auto t = DeviceRegistry::make(reg.triggers, "trigger", "gpio", json{{"backend", "gpio"}});
  ASSERT_FALSE(t.ok());
  EXPECT_NE(t.message().find("trigger.line: missing"), std::string::npos) << t.message();
  auto c = DeviceRegistry::make(reg.cameras, "camera", "uvc", json{{"backend", "uvc"}, {"device", "/dev/video-none"}});
  ASSERT_TRUE(c.ok()) << c.message();  // made; opening is what fails
  EXPECT_FALSE((*c)->open().ok());
  auto g = DeviceRegistry::make(reg.cameras, "camera", "gphoto2", json{{"backend", "gphoto2"}});
  ASSERT_TRUE(g.ok()) << g.message();
  EXPECT_EQ((*g)->name(), "gphoto2");
}

TEST(CheckHardware, MachineWithoutHardwareListsWhatIsMissing) {
  HueEmulatorOptions o;
  o.apply_delay_ms = 0;
  o.enforce_limits = false;
  HueBridgeEmulator emu(o);
  ASSERT_TRUE(emu.start().ok());
  emu.press_link_button();
  auto key = hw::pair_once(emu.address());
  ASSERT_EQ(key.outcome, hw::PairAttempt::Outcome::paired);
  json doc = {{"camera", {{"backend", "gphoto2"}}},
              {"lamps", {{"backend", "hue"}, {"bridge", emu.address()}, {"key", key.key}, {"lamps", {"1", "2", "9"}}}},
              {"trigger", {{"backend", "gpio"}, {"line", "VENEER_NO_SUCH_LINE"}}},
              {"led", {{"backend", "none"}}}};
  std::ostringstream out;
  int rc = check_hardware(out, doc);
  std::string text = out.str();
  std::cout << text;
  EXPECT_EQ(rc, 1);
  EXPECT_NE(text.find("ok       bridge"), std::string::npos);
  EXPECT_NE(text.find("ring position 1: lamp 1 \"Ring 1\""), std::string::npos);
  EXPECT_NE(text.find("MISSING  ring position 3: lamp 9 is not on the bridge"), std::string::npos);
  EXPECT_NE(text.find("trigger: GPIO line VENEER_NO_SUCH_LINE not found"), std::string::npos);
  if (text.find("detected ") == std::string::npos) {
    EXPECT_NE(text.find("MISSING  no camera found over USB"), std::string::npos);
  }
}

TEST(CheckHardware, NoBridgeAddressAndBadConfig) {
  std::ostringstream out;
  int rc = check_hardware(out, json{{"camera", {{"backend", "webcam"}}}});
  EXPECT_EQ(rc, 1);
  EXPECT_NE(out.str().find("camera.backend: unknown backend 'webcam'"), std::string::npos) << out.str();
  EXPECT_NE(out.str().find("lamps.bridge: no bridge address"), std::string::npos) << out.str();
}

}  // namespace
}  // namespace veneerd
