#pragma once
// The window's one line of status: the step running (capture, pull, load,
// compute, export) with its progress, time left and a Cancel button, then the
// last message. Every panel tells it what it does; it draws nothing else.
#include <functional>

#include <QObject>
#include <QString>
#include <QTimer>

#include "step_clock.hpp"

class QLabel;
class QProgressBar;
class QPushButton;
class QStatusBar;

namespace veneer::app {

class StatusLine : public QObject {
  Q_OBJECT
 public:
  // Adds its widgets to `bar`.
  explicit StatusLine(QStatusBar* bar, QObject* parent = nullptr);

  // The last message (red when `error`).
  void message(const QString& text, bool error = false);
  const QString& lastMessage() const { return last_message_; }

  StepClock& step() { return step_; }
  // Shows the step as it is now: its line, its bar, the Cancel button.
  void showStep();
  // Replaces the step's line with `text` (what happened last).
  void say(const QString& text);
  QString line() const;
  // What else keeps the Cancel button shown besides a step (a compute, an
  // export, a load, a pull).
  void setBusyCheck(std::function<bool()> busy) { busy_ = std::move(busy); }

 signals:
  void cancelRequested();

 private:
  StepClock step_;
  QTimer timer_;  // redraws the line so the time left counts down
  QString last_message_;
  std::function<bool()> busy_;
  QLabel *step_label_ = nullptr, *message_label_ = nullptr;
  QProgressBar* step_bar_ = nullptr;
  QPushButton* cancel_ = nullptr;
};

}  // namespace veneer::app
