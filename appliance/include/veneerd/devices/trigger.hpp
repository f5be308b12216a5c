#pragma once
// The capture button and the status LED (interfaces). Implementations: "gpio"
// (hw/, libgpiod, logic from firmware/), "simulated" (sim/, pressed through
// the API / a test hook); LED "none" (below) for a rig without one.
#include <functional>
#include <string>

namespace veneerd {

enum class Press { short_press, long_press, double_press };

class Trigger {
 public:
  virtual ~Trigger() = default;
  virtual std::string name() const = 0;
  // Delivers recognised presses (short = capture next, long = cancel).
  std::function<void(Press)> on_press;
  virtual void press(Press p) { if (on_press) on_press(p); }  // simulated rig / tests
};

enum class LedState { idle, capturing, done, error, no_camera };

class StatusLed {
 public:
  virtual ~StatusLed() = default;
  virtual std::string name() const = 0;
  virtual void show(LedState state) = 0;
};

// LED back-end "none": a rig without a status LED.
class NoLed : public StatusLed {
 public:
  std::string name() const override { return "none"; }
  void show(LedState) override {}
};

}  // namespace veneerd
