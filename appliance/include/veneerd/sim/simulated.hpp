#pragma once
// Trigger and status LED backends "simulated": the button is pressed through
// press() (from the API or a test hook); the LED remembers what it showed.
#include <mutex>
#include <string>
#include <vector>

#include "veneerd/devices/trigger.hpp"

namespace veneerd {

class SimulatedTrigger : public Trigger {
 public:
  std::string name() const override { return "simulated"; }
  void press(Press p) override;
  int presses() const;

 private:
  mutable std::mutex mutex_;
  int presses_ = 0;
};

class SimulatedLed : public StatusLed {
 public:
  std::string name() const override { return "simulated"; }
  void show(LedState state) override;
  LedState state() const;
  std::vector<LedState> history() const;  // every state shown, oldest first

 private:
  mutable std::mutex mutex_;
  LedState state_ = LedState::idle;
  std::vector<LedState> history_;
};

const char* led_state_name(LedState state);

}  // namespace veneerd
