#include "veneerd/sim/simulated.hpp"

#include "veneer/util/log.hpp"

namespace veneerd {

void SimulatedTrigger::press(Press p) {
  {
    std::lock_guard lock(mutex_);
    ++presses_;
  }
  VLOG_INFO("Trigger", "simulated button: {} press",
            p == Press::short_press ? "short" : p == Press::long_press ? "long" : "double");
  Trigger::press(p);
}

int SimulatedTrigger::presses() const {
  std::lock_guard lock(mutex_);
  return presses_;
}

const char* led_state_name(LedState state) {
  switch (state) {
    case LedState::idle: return "idle";
    case LedState::capturing: return "capturing";
    case LedState::done: return "done";
    case LedState::error: return "error";
    case LedState::no_camera: return "no_camera";
  }
  return "unknown";
}

void SimulatedLed::show(LedState state) {
  std::lock_guard lock(mutex_);
  if (history_.size() >= 4096) history_.erase(history_.begin(), history_.begin() + 2048);
  state_ = state;
  history_.push_back(state);
  VLOG_DEBUG("Led", "simulated LED: {}", led_state_name(state));
}

LedState SimulatedLed::state() const {
  std::lock_guard lock(mutex_);
  return state_;
}

std::vector<LedState> SimulatedLed::history() const {
  std::lock_guard lock(mutex_);
  return history_;
}

}  // namespace veneerd
