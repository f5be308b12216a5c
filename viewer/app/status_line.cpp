#include "status_line.hpp"

#include <QLabel>
#include <QProgressBar>
#include <QPushButton>
#include <QStatusBar>

#include "widgets.hpp"

namespace veneer::app {

StatusLine::StatusLine(QStatusBar* bar, QObject* parent) : QObject(parent) {
  message_label_ = named<QLabel>("message");
  step_bar_ = named<QProgressBar>("stepProgress");
  step_bar_->setMaximumWidth(140);
  step_bar_->setTextVisible(false);
  step_bar_->setVisible(false);
  step_label_ = named<QLabel>("stepStatus", tr("connect to a rig, then capture a source and a destination"));
  // the one line: the step running and its progress first, the last message, the rig
  bar->addWidget(step_label_, 3);
  bar->addWidget(step_bar_);
  cancel_ = button(tr("Cancel"), "stepCancel", nullptr);
  cancel_->setVisible(false);
  connect(cancel_, &QPushButton::clicked, this, &StatusLine::cancelRequested);
  bar->addWidget(cancel_);
  bar->addWidget(message_label_, 2);
  timer_.setInterval(250);
  connect(&timer_, &QTimer::timeout, this, &StatusLine::showStep);
}

void StatusLine::message(const QString& text, bool error) {
  last_message_ = text;
  message_label_->setText(text);
  message_label_->setStyleSheet(error ? "color: #e05050;" : "");
}

void StatusLine::say(const QString& text) { step_label_->setText(text); }

QString StatusLine::line() const { return step_label_->text(); }

void StatusLine::showStep() {
  step_label_->setText(step_.line());
  const double f = step_.fraction();
  if (step_.running() && f < 0) {
    step_bar_->setRange(0, 0);  // busy, amount unknown
  } else {
    step_bar_->setRange(0, 100);
    step_bar_->setValue(f < 0 ? 0 : static_cast<int>(f * 100));
  }
  step_bar_->setVisible(step_.running());
  cancel_->setVisible(step_.running() || (busy_ && busy_()));
  if (step_.running() && !timer_.isActive()) timer_.start();
  if (!step_.running()) timer_.stop();
}

}  // namespace veneer::app
