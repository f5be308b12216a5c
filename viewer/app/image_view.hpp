#pragma once
// A picture with zoom (wheel) and pan (drag), kept in step with the other
// views that share the same ViewSync. A click reports the picture pixel under
// the mouse; shift+drag draws a rectangle (the segmentation rectangle);
// markers and lines can be drawn over the picture.
#include <QImage>
#include <QObject>
#include <QPointF>
#include <QPolygonF>
#include <QRect>
#include <QWidget>

#include <vector>

namespace veneer::app {

// Shared zoom and centre, in normalised picture coordinates (0..1), so views
// of different picture sizes stay in step.
class ViewSync : public QObject {
  Q_OBJECT
 public:
  double zoom() const { return zoom_; }
  QPointF centre() const { return centre_; }
  void set(double zoom, QPointF centre);
  void reset() { set(1.0, QPointF(0.5, 0.5)); }

 signals:
  void changed();

 private:
  double zoom_ = 1.0;
  QPointF centre_{0.5, 0.5};
};

class ImageView : public QWidget {
  Q_OBJECT
 public:
  explicit ImageView(const QString& title, QWidget* parent = nullptr);
  void setSync(ViewSync* sync);
  void setImage(const QImage& image);
  // `image` with `fitted`, the same picture already scaled (off the GUI
  // thread) to fitSize(): at zoom 1 it is blitted as it is, so painting
  // scales nothing (Qt's smooth scaling of a large picture waits on a thread
  // pool the computing can fill). Any other zoom paints `image`.
  void setImage(const QImage& image, const QImage& fitted);
  // The size a `picture`-sized image is painted at in a `widget`-sized view
  // at zoom 1 (what a fitted image must be).
  static QSize fitSize(QSize widget, QSize picture);
  int fittedPaints() const { return fitted_paints_; }  // paints that scaled nothing
  const QImage& image() const { return image_; }
  void setTitle(const QString& title);

  struct Marker {
    QPointF pixel;
    QColor colour;
    bool cross = false;  // a cross (unmapped) instead of a ring
  };
  void setMarkers(std::vector<Marker> markers);
  void setRect(const QRect& rect);  // picture pixels; empty = none
  // The hand segmentation's outline, in picture pixels (drawn in yellow).
  void setOutline(std::vector<QPolygonF> outline);
  QRect rect_() const { return rect_px_; }

  // The widget point of a picture pixel, and back.
  QPointF toWidget(QPointF pixel) const;
  QPointF toPixel(QPointF widget) const;

 signals:
  void pixelClicked(QPoint pixel);
  void rectDrawn(QRect rect);
  // ctrl+drag paints the object mask in (add), alt+drag out; one per mouse move
  void brushed(QPoint pixel, bool add);

 protected:
  void paintEvent(QPaintEvent*) override;
  void wheelEvent(QWheelEvent*) override;
  void mousePressEvent(QMouseEvent*) override;
  void mouseMoveEvent(QMouseEvent*) override;
  void mouseReleaseEvent(QMouseEvent*) override;
  QSize sizeHint() const override { return {320, 240}; }

 private:
  double scale() const;  // widget px per picture px
  QString title_;
  QImage image_, fitted_;
  int fitted_paints_ = 0;
  ViewSync* sync_ = nullptr;
  ViewSync own_sync_;
  std::vector<Marker> markers_;
  QRect rect_px_;
  std::vector<QPolygonF> outline_;
  int brush_ = 0;  // +1 adding, -1 removing, 0 not brushing
  bool dragging_ = false, drawing_ = false, moved_ = false;
  QPointF press_pos_, last_pos_;
};

}  // namespace veneer::app
