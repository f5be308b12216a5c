#pragma once
// The Live tab's light overlay: the light the live view estimated in the
// frame (repaint::LiveLight) drawn as a dial -- the object's disc seen from
// the camera with an arrow toward the lamp (x right, y up; a lamp behind the
// camera's axis at the centre) -- with its intensity, residual and, when one
// lamp did not explain the frame, what the view did instead. No estimate
// (the copy look, a lost frame): it says so.
#include <optional>

#include <QWidget>

#include "veneer/repaint/live_look.hpp"
#include "veneer/repaint/look.hpp"

namespace veneer::app {

class LightDial : public QWidget {
  Q_OBJECT
 public:
  explicit LightDial(QWidget* parent = nullptr);
  // The frame's light and the look it was painted in.
  void setLight(const std::optional<veneer::repaint::LiveLight>& light, veneer::repaint::Look painted);
  const std::optional<veneer::repaint::LiveLight>& light() const { return light_; }
  // What the dial says in words (intensity, residual, the fallback or why no estimate).
  QString text() const { return text_; }

 protected:
  void paintEvent(QPaintEvent*) override;
  QSize sizeHint() const override { return {180, 230}; }

 private:
  std::optional<veneer::repaint::LiveLight> light_;
  QString text_;
};

}  // namespace veneer::app
