#pragma once
// Live first: the automatic flow loads the pulled sets at the live view's
// width through reduced decodes (io/reduced.hpp) and goes live on that map;
// this job then makes the full-resolution map in the background (the
// pipeline's, as `veneer transfer` makes it) with progress and time left in
// the status bar, and swaps it in when done.
#include <atomic>
#include <memory>

#include <QObject>

#include "session.hpp"

class QLabel;
class QProgressBar;
class QStatusBar;

namespace veneer::app {

class TransferPanel;

class LiveFirstJob : public QObject {
  Q_OBJECT
 public:
  LiveFirstJob(Session& session, TransferPanel& transfer, QStatusBar* bar, QObject* parent = nullptr);
  // Starts the job when the map shown was made from live-size sets.
  void maybeStart();
  void cancel() { cancel_->store(true); }
  bool running() const { return running_; }
  int swaps() const { return swaps_; }  // full-resolution maps swapped in
  // While held, a job waits before it begins (the live-size map stays the
  // one shown): what a test needs to see the live view before the swap.
  void setHeld(bool held) { held_->store(held); }
  QString line() const;

 signals:
  // The full-resolution map is the one shown now; `relit` and `relit_source`
  // are the relight pictures the job made for `light` (null when none).
  void swapped(QImage relit, QImage relit_source, cv::Vec3d light);

 private:
  Session& session_;
  TransferPanel& transfer_;
  QStatusBar* bar_;
  bool running_ = false;
  int swaps_ = 0;
  std::shared_ptr<std::atomic<bool>> cancel_ = std::make_shared<std::atomic<bool>>(false);
  std::shared_ptr<std::atomic<bool>> held_ = std::make_shared<std::atomic<bool>>(false);
  StepClock step_;
  QLabel* label_ = nullptr;
  QProgressBar* progress_ = nullptr;
};

}  // namespace veneer::app
