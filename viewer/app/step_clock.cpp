#include "step_clock.hpp"

#include <algorithm>
#include <cmath>

#include <QObject>

namespace veneer::app {

void StepClock::start(const QString& kind, const QString& text) {
  kind_ = kind;
  text_ = text;
  fraction_ = -1;
  running_ = true;
  clock_.start();
}

void StepClock::update(double fraction, const QString& text) {
  if (fraction >= 0) fraction_ = std::clamp(fraction, 0.0, 1.0);
  if (!text.isEmpty()) text_ = text;
}

void StepClock::finish() {
  if (!running_) return;
  last_seconds_[kind_] = clock_.elapsed() / 1000.0;
  running_ = false;
}

double StepClock::secondsLeft() const {
  if (!running_) return -1;
  const double elapsed = clock_.elapsed() / 1000.0;
  // Extrapolated from this step's own pace once it has made some way...
  if (fraction_ >= 0.05 && elapsed >= 0.3) return elapsed * (1 - fraction_) / fraction_;
  // ...before that from how long the last step of its kind took.
  auto it = last_seconds_.find(kind_);
  if (it != last_seconds_.end() && it->second > elapsed) return it->second - elapsed;
  return -1;
}

QString StepClock::line() const {
  if (!running_) return text_;
  QString s = text_;
  if (fraction_ >= 0) s += QString(" · %1 %").arg(static_cast<int>(std::floor(fraction_ * 100)));
  if (fraction_ >= 1) return s;
  const double left = secondsLeft();
  if (left < 0)
    s += QObject::tr(" · estimating time left…");
  else  // whole seconds, rounded up: work remains, so never "0 s"
    s += QObject::tr(" · about %1 s left").arg(std::max(1, static_cast<int>(std::ceil(left))));
  return s;
}

}  // namespace veneer::app
