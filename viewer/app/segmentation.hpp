#pragma once
// Segmentation by hand: a rectangle keeps the object inside it, a brush adds
// or removes pixels; the result is the set's object mask for the transfer
// (its supplied mask), drawn as an outline on the views.
#include <vector>

#include <QObject>
#include <QPolygonF>
#include <QRect>
#include <QStringList>

#include "session.hpp"

namespace veneer::app {

class SegmentationTool : public QObject {
  Q_OBJECT
 public:
  explicit SegmentationTool(Session& session, QObject* parent = nullptr);
  // What the views' shift+drag (rectangle) and ctrl/alt+drag (brush in/out) do.
  void setHandRect(veneer::io::Role set, const QRect& rect);
  void brushHandMask(veneer::io::Role set, QPoint pixel, bool add, int radius = 0);
  void clearHandMask(veneer::io::Role set);
  // A mask kept with a library map, put back (ignored when its size is not the set's).
  void restoreHandMask(veneer::io::Role set, const cv::Mat& mask);
  // Writes the hand masks as <dir>/dst-mask.png and src-mask.png, what
  // `veneer transfer --dst-mask/--src-mask` reads; returns the files written.
  QStringList exportMasksTo(const QString& dir);

 signals:
  // `set`'s mask changed: its outline (empty: none), and a line saying which
  // sets have a mask drawn by hand.
  void maskChanged(veneer::io::Role set, std::vector<QPolygonF> outline, QString hand);

 private:
  bool startHandMask(LoadedSet& s);
  void changed(veneer::io::Role role);

  Session& session_;
};

}  // namespace veneer::app
