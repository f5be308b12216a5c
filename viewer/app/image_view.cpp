#include "image_view.hpp"

#include <algorithm>
#include <cmath>

#include <QMouseEvent>
#include <QPainter>
#include <QWheelEvent>

namespace veneer::app {

void ViewSync::set(double zoom, QPointF centre) {
  zoom = std::clamp(zoom, 1.0, 64.0);
  centre.setX(std::clamp(centre.x(), 0.0, 1.0));
  centre.setY(std::clamp(centre.y(), 0.0, 1.0));
  if (zoom == zoom_ && centre == centre_) return;
  zoom_ = zoom;
  centre_ = centre;
  emit changed();
}

ImageView::ImageView(const QString& title, QWidget* parent) : QWidget(parent), title_(title) {
  setSync(&own_sync_);
  setMouseTracking(false);
  setMinimumSize(160, 120);
  setSizePolicy(QSizePolicy::Expanding, QSizePolicy::Expanding);
}

void ImageView::setSync(ViewSync* sync) {
  if (sync_) disconnect(sync_, nullptr, this, nullptr);
  sync_ = sync;
  connect(sync_, &ViewSync::changed, this, qOverload<>(&QWidget::update));
  update();
}

void ImageView::setImage(const QImage& image) {
  image_ = image;
  fitted_ = QImage();
  update();
}

void ImageView::setImage(const QImage& image, const QImage& fitted) {
  image_ = image;
  fitted_ = fitted;
  update();
}

QSize ImageView::fitSize(QSize widget, QSize picture) {
  if (picture.isEmpty()) return {};
  const double fit = std::max(1e-3, std::min(widget.width() / double(picture.width()),
                                             (widget.height() - 18) / double(picture.height())));
  return {std::max(1, static_cast<int>(std::lround(picture.width() * fit))),
          std::max(1, static_cast<int>(std::lround(picture.height() * fit)))};
}

void ImageView::setTitle(const QString& title) {
  title_ = title;
  update();
}

void ImageView::setOutline(std::vector<QPolygonF> outline) {
  outline_ = std::move(outline);
  update();
}

void ImageView::setMarkers(std::vector<Marker> markers) {
  markers_ = std::move(markers);
  update();
}

void ImageView::setRect(const QRect& rect) {
  rect_px_ = rect;
  update();
}

double ImageView::scale() const {
  if (image_.isNull()) return 1.0;
  const double fit = std::min(width() / double(image_.width()), (height() - 18) / double(image_.height()));
  return std::max(1e-3, fit) * sync_->zoom();
}

QPointF ImageView::toWidget(QPointF pixel) const {
  const double s = scale();
  const QPointF c(sync_->centre().x() * image_.width(), sync_->centre().y() * image_.height());
  return QPointF(width() / 2.0 + (pixel.x() - c.x()) * s, 18 + (height() - 18) / 2.0 + (pixel.y() - c.y()) * s);
}

QPointF ImageView::toPixel(QPointF widget) const {
  const double s = scale();
  const QPointF c(sync_->centre().x() * image_.width(), sync_->centre().y() * image_.height());
  return QPointF(c.x() + (widget.x() - width() / 2.0) / s, c.y() + (widget.y() - 18 - (height() - 18) / 2.0) / s);
}

void ImageView::paintEvent(QPaintEvent*) {
  QPainter p(this);
  p.fillRect(rect(), QColor(24, 24, 28));
  p.setPen(QColor(200, 200, 200));
  p.drawText(QRect(4, 0, width() - 8, 18), Qt::AlignLeft | Qt::AlignVCenter, title_);
  if (image_.isNull()) {
    p.drawText(rect(), Qt::AlignCenter, tr("(nothing yet)"));
    return;
  }
  const QPointF tl = toWidget(QPointF(0, 0)), br = toWidget(QPointF(image_.width(), image_.height()));
  p.setClipRect(QRect(0, 18, width(), height() - 18));
  if (!fitted_.isNull() && sync_->zoom() == 1.0 && fitted_.size() == fitSize(size(), image_.size())) {
    // already at the painted size: a plain copy, nothing scaled here
    p.drawImage(QPoint(static_cast<int>(std::lround(tl.x())), static_cast<int>(std::lround(tl.y()))), fitted_);
    ++fitted_paints_;
  } else {
    p.setRenderHint(QPainter::SmoothPixmapTransform, sync_->zoom() < 2.0);
    p.drawImage(QRectF(tl, br), image_);
  }
  p.setRenderHint(QPainter::Antialiasing, true);
  for (const Marker& m : markers_) {
    const QPointF w = toWidget(m.pixel + QPointF(0.5, 0.5));
    p.setPen(QPen(m.colour, 2));
    if (m.cross) {
      p.drawLine(w + QPointF(-5, -5), w + QPointF(5, 5));
      p.drawLine(w + QPointF(-5, 5), w + QPointF(5, -5));
    } else {
      p.drawEllipse(w, 5, 5);
    }
  }
  if (!outline_.empty()) {
    p.setPen(QPen(QColor(255, 220, 0), 1.5));
    for (const QPolygonF& poly : outline_) {
      QPolygonF w;
      for (const QPointF& q : poly) w << toWidget(q + QPointF(0.5, 0.5));
      p.drawPolygon(w);
    }
  }
  if (!rect_px_.isEmpty()) {
    p.setPen(QPen(QColor(255, 200, 0), 1, Qt::DashLine));
    p.drawRect(QRectF(toWidget(rect_px_.topLeft()), toWidget(rect_px_.bottomRight() + QPoint(1, 1))));
  }
}

void ImageView::wheelEvent(QWheelEvent* e) {
  if (image_.isNull()) return;
  // Zoom about the pixel under the mouse.
  const QPointF before = toPixel(e->position());
  const double factor = std::pow(1.0015, e->angleDelta().y());
  const double zoom = std::clamp(sync_->zoom() * factor, 1.0, 64.0);
  const double s_new = scale() / sync_->zoom() * zoom;
  const QPointF c(before.x() - (e->position().x() - width() / 2.0) / s_new,
                  before.y() - (e->position().y() - 18 - (height() - 18) / 2.0) / s_new);
  sync_->set(zoom, QPointF(c.x() / image_.width(), c.y() / image_.height()));
}

void ImageView::mousePressEvent(QMouseEvent* e) {
  press_pos_ = last_pos_ = e->position();
  moved_ = false;
  drawing_ = (e->modifiers() & Qt::ShiftModifier) && e->button() == Qt::LeftButton;
  brush_ = e->button() != Qt::LeftButton || drawing_ ? 0
           : (e->modifiers() & Qt::ControlModifier) ? 1
           : (e->modifiers() & Qt::AltModifier)     ? -1
                                                    : 0;
  dragging_ = !drawing_ && brush_ == 0;
  if (brush_ != 0 && !image_.isNull()) emit brushed(toPixel(e->position()).toPoint(), brush_ > 0);
}

void ImageView::mouseMoveEvent(QMouseEvent* e) {
  if ((e->position() - press_pos_).manhattanLength() > 3) moved_ = true;
  if (brush_ != 0 && !image_.isNull()) {
    emit brushed(toPixel(e->position()).toPoint(), brush_ > 0);
  } else if (drawing_) {
    const QPoint a = toPixel(press_pos_).toPoint(), b = toPixel(e->position()).toPoint();
    rect_px_ = QRect(a, b).normalized().intersected(image_.rect());
    update();
  } else if (dragging_ && !image_.isNull()) {
    const QPointF d = e->position() - last_pos_;
    const double s = scale();
    sync_->set(sync_->zoom(), sync_->centre() - QPointF(d.x() / s / image_.width(), d.y() / s / image_.height()));
  }
  last_pos_ = e->position();
}

void ImageView::mouseReleaseEvent(QMouseEvent* e) {
  if (brush_ != 0) moved_ = true;  // a stroke is not a click
  if (drawing_ && moved_) {
    emit rectDrawn(rect_px_);
  } else if (!moved_ && !image_.isNull()) {
    const QPointF px = toPixel(e->position());
    const QPoint p(static_cast<int>(std::floor(px.x())), static_cast<int>(std::floor(px.y())));
    if (image_.rect().contains(p)) emit pixelClicked(p);
  }
  drawing_ = dragging_ = false;
  brush_ = 0;
}

}  // namespace veneer::app
