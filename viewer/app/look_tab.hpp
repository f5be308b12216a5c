#pragma once
// The Look tab: the destination, the source and the result side by side (one
// zoom for all), what to show of them (median, normals, map, confidence, ...),
// the destination's histogram and exposure, and where a clicked pixel's look
// comes from.
#include <QWidget>

#include "image_view.hpp"
#include "session.hpp"

class QComboBox;
class QLabel;

namespace veneer::app {

class LookTab : public QWidget {
  Q_OBJECT
 public:
  explicit LookTab(Session& session, QWidget* parent = nullptr);
  // Draws the views again (their parallel work isolated: widgets.hpp, gui_work).
  void refresh();
  // A new result is shown: the median view, refreshed.
  void showResult();
  // The light moved: the specular enhancement follows it.
  void lightChanged();
  // The index of the "Show" choice `what` (-1 = none such) and choosing it.
  int lookIndex(const QString& what) const;
  void showLook(int index);
  void setOutline(veneer::io::Role set, const std::vector<QPolygonF>& outline);
  QString exposureText() const { return exposure_text_; }
  // The look selector (the transfer's TransferOptions::look): shown without telling anyone.
  void setLook(veneer::repaint::Look look);


 signals:
  void snapshotAsked();
  // The user chose how the stills are painted (shaded or the pixel copy).
  void lookChosen(veneer::repaint::Look look);
  // shift+drag (rectangle) and ctrl/alt+drag (brush) on the destination or source view
  void handRectDrawn(veneer::io::Role set, QRect rect);
  void brushed(veneer::io::Role set, QPoint pixel, bool add);

 private:
  void refreshNow();
  void updateHistogram();
  void showOrigin(QPoint destination_pixel);

  Session& session_;
  ViewSync sync_;
  QString exposure_text_;
  QComboBox *look_what_ = nullptr, *look_style_ = nullptr;
  QLabel *histogram_ = nullptr, *exposure_label_ = nullptr;
  ImageView *dst_view_ = nullptr, *src_view_ = nullptr, *result_view_ = nullptr, *origin_view_ = nullptr;
};

}  // namespace veneer::app
