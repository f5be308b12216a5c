#pragma once
// Small helpers the panels share to build their widgets.
#include <QDoubleSpinBox>
#include <QPushButton>
#include <QString>

#include <opencv2/core.hpp>

namespace veneer::app {

inline QPushButton* button(const QString& text, const QString& name, QWidget* parent) {
  auto* b = new QPushButton(text, parent);
  b->setObjectName(name);
  return b;
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

// A linear picture tonemapped for the views (empty stays empty).
cv::Mat picture_of(const cv::Mat& linear);

}  // namespace veneer::app
