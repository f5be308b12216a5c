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
  // A stage of a longer job: its 0..1 reported as from..to of this one, same cancel flag.
  Progress part(double from, double to) const {
    Progress out;
    out.cancel = cancel;
    if (on_progress)
      out.on_progress = [cb = on_progress, from, to](double f, const std::string& stage) { cb(from + (to - from) * f, stage); };
    return out;
  }
};

}  // namespace veneer
