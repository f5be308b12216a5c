#pragma once
// The one line of status: what the viewer is doing now, how far along, and
// how long is left, estimated from measured timings only. Before there is
// enough to go on, it says so ("estimating…") instead of a made-up number;
// while work remains it never says "0 s left".
#include <map>

#include <QElapsedTimer>
#include <QString>

namespace veneer::app {

class StepClock {
 public:
  // A new step starts now; `kind` groups steps whose durations predict each
  // other ("pull", "compute", ...), `text` is what the user reads.
  void start(const QString& kind, const QString& text);
  // The step's fraction done (0..1, or < 0 when unknown) and its latest stage.
  void update(double fraction, const QString& text = {});
  // The step is over: its duration is remembered for the next of its kind.
  void finish();
  bool running() const { return running_; }
  double elapsedSeconds() const { return running_ ? clock_.elapsed() / 1000.0 : 0; }
  // "computing the map · 40 % · about 3 s left"
  QString line() const;
  // Seconds left (< 0 when there is nothing to estimate from yet).
  double secondsLeft() const;
  double fraction() const { return fraction_; }
  const QString& kind() const { return kind_; }

 private:
  QString kind_, text_;
  double fraction_ = -1;
  bool running_ = false;
  QElapsedTimer clock_;
  std::map<QString, double> last_seconds_;  // measured duration of the last step of each kind
};

}  // namespace veneer::app
