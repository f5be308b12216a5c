#pragma once
// A shaded sphere on which the user drags a virtual light; reports the light
// direction in the rig frame (x right, y up, z toward the camera).
#include <QWidget>

#include <opencv2/core.hpp>

namespace veneer::app {

class SpherePad : public QWidget {
  Q_OBJECT
 public:
  explicit SpherePad(QWidget* parent = nullptr);
  cv::Vec3d direction() const { return direction_; }
  void setDirection(const cv::Vec3d& d);

 signals:
  void directionChanged(cv::Vec3d direction);

 protected:
  void paintEvent(QPaintEvent*) override;
  void mousePressEvent(QMouseEvent*) override;
  void mouseMoveEvent(QMouseEvent*) override;
  QSize sizeHint() const override { return {180, 180}; }

 private:
  void pick(QPointF pos);
  cv::Vec3d direction_{0, 0, 1};
};

}  // namespace veneer::app
