#pragma once
// Lamp calibration from a chrome-sphere set (File > Calibrate lamps…): the
// core finds the sphere and the highlights (veneer::ps::calibrate_mirror_sphere)
// and writes the lights file; a dialog shows the circle and highlights it
// found and how far each lamp is from the set's own directions.
#include <QImage>
#include <QObject>

#include "session.hpp"

class QDialog;
class QLabel;
class QWidget;

namespace veneer::app {

class CalibrationStep : public QObject {
  Q_OBJECT
 public:
  // `window` is the parent of the dialogs.
  CalibrationStep(Session& session, QWidget* window);
  // Asks for the sphere set and the lights file, then calibrates.
  void ask();
  // Writes the lights file (what `veneer normals --lights` reads) and shows
  // what was found.
  bool calibrateLamps(const QString& sphere_folder, const QString& lights_file);
  QImage image() const { return image_; }

 private:
  Session& session_;
  QWidget* window_;
  QImage image_;
  QDialog* dialog_ = nullptr;
  QLabel *picture_ = nullptr, *text_ = nullptr;
};

}  // namespace veneer::app
