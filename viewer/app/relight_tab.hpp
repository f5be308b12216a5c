#pragma once
// The Relight tab: a light dragged over a sphere, the source under it and the
// destination relit in the source's material through the map shown.
#include <QWidget>

#include "image_view.hpp"
#include "session.hpp"
#include "sphere_pad.hpp"

class QLabel;

namespace veneer::app {

class RelightTab : public QWidget {
  Q_OBJECT
 public:
  explicit RelightTab(Session& session, QWidget* parent = nullptr);
  cv::Vec3d direction() const { return relight_pad_->direction(); }
  // Renders the two pictures for the light shown.
  void refresh();
  // Shows pictures already rendered for `light` (by the worker that made the
  // result) when that is still the light shown; renders them otherwise.
  void showRelit(const QImage& relit, const QImage& relit_source, const cv::Vec3d& light);

 signals:
  void lightChanged();

 private:
  void updateLabel(const cv::Vec3d& direction);

  Session& session_;
  SpherePad* relight_pad_ = nullptr;
  QLabel* relight_label_ = nullptr;
  ImageView *relight_view_ = nullptr, *relight_src_view_ = nullptr;
};

}  // namespace veneer::app
