#pragma once
// The capture button and the status LED on GPIO lines (libgpiod 1.6; the
// library's types stay in gpio.cpp). Debounce and press gestures come from
// firmware/button.c, LED patterns from firmware/led.c.
//
// Event-loop integration: the trigger exposes its event fd; the daemon polls
// it and calls on_readable(), and calls on_timer() when next_deadline_us()
// passes (debounce confirmation, long-press and double-press timeouts). A
// back-end created from the config runs that loop on its own small thread
// instead (start()/stop()), so the daemon needs nothing GPIO-specific.
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include <nlohmann/json.hpp>

#include "veneer/util/expected.hpp"
#include "veneerd/devices/trigger.hpp"

namespace veneerd::hw {

// Monotonic microseconds (CLOCK_MONOTONIC), the clock the kernel stamps GPIO
// events with since Linux 5.7.
uint64_t monotonic_us();

struct GpioLineConfig {
  std::string chip;          // "gpiochip0", "/dev/gpiochip0", a label or ""; "" = search every chip
  std::string line;          // line name, e.g. "GPIO17" (names survive board revisions)
  int offset = -1;           // or an offset on `chip` (needs `chip`); -1 = use the name
  bool active_low = true;    // button: pressed pulls the line to ground
  std::string describe() const;
};

struct GpioButtonTiming {
  uint32_t debounce_ms = 20;      // a level must hold this long
  uint32_t long_press_ms = 800;   // held at least this long = long press (cancel)
  uint32_t double_press_ms = 350; // second press within this gap = double press; 0 = off
};

// Config sections ({"backend":"gpio", "chip":..., "line":..., ...}); the error
// names the field and the value. `alt_key` is read when "line" is absent: the
// config's shared "gpio" block fills in "button_line" / "led_line" offsets.
veneer::Expected<GpioLineConfig> parse_gpio_line(const nlohmann::json& section, const std::string& where,
                                                 const char* alt_key = nullptr);
veneer::Expected<GpioButtonTiming> parse_gpio_timing(const nlohmann::json& section, const std::string& where);

// What the machine offers: each chip with its label and named lines.
struct GpioChipInfo {
  std::string name, label, path;
  unsigned lines = 0;
  std::vector<std::string> line_names;  // "" for unnamed lines
};
std::vector<GpioChipInfo> list_gpio_chips();

class GpioTrigger : public Trigger {
 public:
  // Requests both edges on the line (with a pull-up for active-low buttons).
  static veneer::Expected<std::unique_ptr<GpioTrigger>> open(const GpioLineConfig& line,
                                                             const GpioButtonTiming& timing);
  // Decodes `struct gpioevent_data` records from `fd` with libgpiod's own
  // reader (tests feed a pipe). Takes ownership of `fd`.
  static std::unique_ptr<GpioTrigger> from_event_fd(int fd, bool active_low, int initial_level,
                                                    const GpioButtonTiming& timing,
                                                    std::function<uint64_t()> clock_us = monotonic_us);
  ~GpioTrigger() override;

  std::string name() const override { return "gpio"; }

  int fd() const;
  // Reads every pending event and feeds the debouncer; delivers presses.
  void on_readable();
  // When on_timer() should run next (monotonic µs); nullopt = no deadline.
  std::optional<uint64_t> next_deadline_us() const;
  void on_timer();

  // Runs the poll loop on an own thread; stop() ends and joins it.
  veneer::Status start();
  void stop();

  // Number of event records that could not be decoded.
  unsigned bad_records() const { return bad_records_; }

 private:
  struct Impl;
  explicit GpioTrigger(std::unique_ptr<Impl> impl);
  void deliver();
  uint64_t to_monotonic(uint64_t event_ns);

  std::unique_ptr<Impl> impl_;
  mutable std::mutex mu_;
  std::thread thread_;
  int wake_[2] = {-1, -1};
  unsigned bad_records_ = 0;
};

class GpioLed : public StatusLed {
 public:
  static veneer::Expected<std::unique_ptr<GpioLed>> open(const GpioLineConfig& line);
  // Drives `sink` instead of a line (tests; an LED on another bus).
  static std::unique_ptr<GpioLed> with_sink(std::function<void(int)> sink,
                                            std::function<uint64_t()> clock_us = monotonic_us);
  ~GpioLed() override;

  std::string name() const override { return "gpio"; }
  void show(LedState state) override;
  LedState state() const;
  // Sets the level the pattern wants now; returns when it should run next.
  std::optional<uint64_t> tick();

  veneer::Status start();  // own timer thread
  void stop();

 private:
  struct Impl;
  explicit GpioLed(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
  mutable std::mutex mu_;
  std::thread thread_;
  int wake_[2] = {-1, -1};
  bool stopping_ = false;
};

}  // namespace veneerd::hw
