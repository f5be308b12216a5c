#include "sphere_pad.hpp"

#include <algorithm>
#include <cmath>

#include <QMouseEvent>
#include <QPainter>

#include "veneer/repaint/relight.hpp"

namespace veneer::app {

SpherePad::SpherePad(QWidget* parent) : QWidget(parent) { setMinimumSize(140, 140); }

void SpherePad::setDirection(const cv::Vec3d& d) {
  direction_ = d;
  update();
  emit directionChanged(direction_);
}

void SpherePad::pick(QPointF pos) {
  const double r = std::min(width(), height()) / 2.0 - 6;
  const double u = (pos.x() - width() / 2.0) / r, v = -(pos.y() - height() / 2.0) / r;
  setDirection(veneer::repaint::direction_on_sphere(u, v));
}

void SpherePad::mousePressEvent(QMouseEvent* e) { pick(e->position()); }
void SpherePad::mouseMoveEvent(QMouseEvent* e) { pick(e->position()); }

void SpherePad::paintEvent(QPaintEvent*) {
  QPainter p(this);
  p.fillRect(rect(), QColor(24, 24, 28));
  const int r = std::min(width(), height()) / 2 - 6;
  const QPoint c(width() / 2, height() / 2);
  // The sphere shaded by the chosen light: a picture of what it means.
  QImage img(2 * r + 1, 2 * r + 1, QImage::Format_RGB32);
  img.fill(QColor(24, 24, 28));
  for (int y = -r; y <= r; ++y)
    for (int x = -r; x <= r; ++x) {
      const double u = x / double(r), v = -y / double(r), q = u * u + v * v;
      if (q > 1) continue;
      const double shade = std::max(0.0, u * direction_[0] + v * direction_[1] + std::sqrt(1 - q) * direction_[2]);
      const int g = static_cast<int>(30 + 200 * shade);
      img.setPixel(x + r, y + r, qRgb(g, g, g));
    }
  p.drawImage(c.x() - r, c.y() - r, img);
  p.setRenderHint(QPainter::Antialiasing);
  const QPointF dot(c.x() + direction_[0] * r, c.y() - direction_[1] * r);
  p.setPen(QPen(QColor(255, 210, 0), 2));
  p.setBrush(QColor(255, 230, 120));
  p.drawEllipse(dot, 6, 6);
}

}  // namespace veneer::app
