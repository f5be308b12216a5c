#include "light_dial.hpp"

#include <algorithm>
#include <cmath>

#include <QPainter>
#include <QPainterPath>

namespace veneer::app {

LightDial::LightDial(QWidget* parent) : QWidget(parent) {
  setMinimumSize(160, 210);
  setLight(std::nullopt, veneer::repaint::Look::copy);
}

void LightDial::setLight(const std::optional<veneer::repaint::LiveLight>& light, veneer::repaint::Look painted) {
  light_ = light;
  if (!light) {
    text_ = painted == veneer::repaint::Look::copy ? tr("no light estimate: pixel copy")
                                                  : tr("no light estimate yet");
  } else {
    const auto& l = *light;
    text_ = tr("intensity %1 · ambient %2\nresidual %3").arg(l.intensity, 0, 'f', 2).arg(l.ambient, 0, 'f', 2)
                .arg(l.residual, 0, 'f', 2);
    if (l.position_m)
      text_ += tr("\nlamp at (%1, %2, %3) m").arg((*l.position_m)[0], 0, 'f', 2).arg((*l.position_m)[1], 0, 'f', 2)
                   .arg((*l.position_m)[2], 0, 'f', 2);
    if (!l.explained)
      text_ += tr("\nnot one lamp: %1").arg(l.fallback.empty() ? tr("(no fallback named)")
                                                               : QString::fromStdString(l.fallback));
  }
  setToolTip(text_);
  update();
}

void LightDial::paintEvent(QPaintEvent*) {
  QPainter p(this);
  p.setRenderHint(QPainter::Antialiasing);
  const int side = std::min(width(), height() - 70);
  const QRectF disc(width() / 2.0 - side / 2.0 + 6, 6, side - 12, side - 12);
  const QPointF c = disc.center();
  const double r = disc.width() / 2;
  p.setPen(QPen(QColor(90, 90, 100), 1));
  p.setBrush(QColor(36, 36, 42));
  p.drawEllipse(disc);
  p.drawLine(QPointF(c.x() - r, c.y()), QPointF(c.x() + r, c.y()));
  p.drawLine(QPointF(c.x(), c.y() - r), QPointF(c.x(), c.y() + r));
  if (light_) {
    const auto& l = *light_;
    // the lamp's colour, at a brightness that stays visible
    const cv::Vec3d col = l.colour;
    const double top = std::max({col[0], col[1], col[2], 1e-6});
    const QColor lamp = l.explained ? QColor::fromRgbF(std::clamp(col[0] / top, 0.2, 1.0),
                                                       std::clamp(col[1] / top, 0.2, 1.0),
                                                       std::clamp(col[2] / top, 0.2, 1.0))
                                    : QColor(230, 120, 60);
    // the direction seen from the camera: x right, y up (the widget's y is down)
    const QPointF tip(c.x() + r * l.direction[0], c.y() - r * l.direction[1]);
    p.setPen(QPen(lamp, 3, l.explained ? Qt::SolidLine : Qt::DashLine, Qt::RoundCap));
    p.drawLine(c, tip);
    p.setBrush(lamp);
    p.drawEllipse(tip, 6, 6);
  }
  p.setPen(palette().color(QPalette::WindowText));
  const QRectF words(2, side, width() - 4, height() - side);
  p.drawText(words, Qt::AlignHCenter | Qt::AlignTop | Qt::TextWordWrap, text_);
}

}  // namespace veneer::app
