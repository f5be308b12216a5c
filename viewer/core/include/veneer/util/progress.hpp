#pragma once
// Long computations take a Progress: a callback told the fraction done (0..1)
// and the stage's name, and a cancel flag polled between chunks of work.
// Both parts are optional; a default-constructed Progress is silent and never
// cancels.
#include <atomic>
#include <functional>
#include <string>

namespace veneer {

struct Progress {
  std::function<void(double fraction, const std::string& stage)> on_progress;
  const std::atomic<bool>* cancel = nullptr;

  void report(double fraction, const std::string& stage) const {
    if (on_progress) on_progress(fraction, stage);
  }
  bool cancelled() const { return cancel != nullptr && cancel->load(std::memory_order_relaxed); }
};

}  // namespace veneer
