#pragma once
// Small helpers the panels share to build their widgets.
#include <QCheckBox>
#include <QDoubleSpinBox>
#include <QPushButton>
#include <QString>
#include <QThreadPool>

#include <functional>
#include <utility>

#include <opencv2/core.hpp>

namespace veneer::app {

// A new widget of type W named `name` (what the tests find it by); `args` go to its constructor.
template <class W, class... Args>
W* named(const QString& name, Args&&... args) {
  auto* w = new W(std::forward<Args>(args)...);
  w->setObjectName(name);
  return w;
}

inline QPushButton* button(const QString& text, const QString& name, QWidget* parent) {
  return named<QPushButton>(name, text, parent);
}

// A number box of the transfer panel: range, decimals, step and start value.
inline QDoubleSpinBox* number_box(const QString& name, double lo, double hi, int decimals, double step, double value,
                                  const QString& tip = {}) {
  auto* b = new QDoubleSpinBox;
  b->setObjectName(name);
  b->setRange(lo, hi);
  b->setDecimals(decimals);
  b->setSingleStep(step);
  b->setValue(value);
  if (!tip.isEmpty()) b->setToolTip(tip);
  return b;
}

// A check box, ticked or not, with an optional tool tip.
inline QCheckBox* check_box(const QString& name, const QString& text, bool checked, const QString& tip = {}) {
  auto* b = named<QCheckBox>(name, text);
  b->setChecked(checked);
  if (!tip.isEmpty()) b->setToolTip(tip);
  return b;
}

// Parallel work done on the GUI thread (a live frame's repaint, a view's
// picture). Isolated, so that while it waits for its own parallel loop the
// GUI thread does not take a task of a background job's loop (one photo of a
// 10 Mpx set being decoded: seconds) -- measured as a 10 s stall in bench_app.
// (widgets.cpp: TBB's headers and Qt's `emit` do not mix.)
void gui_work(const std::function<void()>& f);

// The pool the window's long jobs run in (compute, load, normals, export,
// library maps): not Qt's global pool, whose threads Qt 6.4's own image
// conversion and scaling borrow while the GUI thread waits for them -- a
// transfer holding one there stalled the painting of the views.
QThreadPool* job_pool();

// The mouse wheel changes a spin box, combo box or slider under `root` only
// when it has focus (clicked or tabbed into); otherwise the wheel scrolls the
// panel, as when scrolling past the field.
void guard_wheel(QWidget* root);

// "2026-11-25T20:08:18Z" -> "2026-11-25 20:08" (as written when it is not ISO 8601)
inline QString short_date(const std::string& iso) {
  const QString t = QString::fromStdString(iso);
  return t.size() >= 16 && t[10] == 'T' ? t.left(10) + " " + t.mid(11, 5) : t;
}

// The 64-bin luminance histogram (CV_32F) of an 8-bit BGR picture, what the
// Look tab draws; made where the picture is made (off the GUI thread).
cv::Mat luminance_histogram(const cv::Mat& bgr8);

// A linear picture tonemapped for the views (empty stays empty).
cv::Mat picture_of(const cv::Mat& linear);

}  // namespace veneer::app
