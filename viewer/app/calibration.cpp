// Lamp calibration from a chrome-sphere set (File > Calibrate lamps…): the
// core finds the sphere and the highlights (veneer::ps::calibrate_mirror_sphere)
// and writes the lights file; the window shows the circle and highlights it
// found and how far each lamp is from the set's own directions.
#include <QDialog>
#include <QFileDialog>
#include <QLabel>
#include <QMenuBar>
#include <QVBoxLayout>

#include "main_window.hpp"
#include "qt_convert.hpp"
#include "veneer/ps/calibration.hpp"

namespace veneer::app {

bool MainWindow::calibrateLamps(const QString& sphere_folder, const QString& lights_file) {
  // Reading 12 photos and finding their highlights takes well under a second:
  // done here rather than as a cancellable step.
  auto set = veneer::io::read_set(sphere_folder.toStdString());
  if (!set) {
    message(tr("calibration: %1").arg(qs(set.message())), true);
    return false;
  }
  auto cal = veneer::ps::calibrate_mirror_sphere(*set);
  if (!cal) {
    message(tr("calibration from %1: %2").arg(sphere_folder, qs(cal.message())), true);
    return false;
  }
  if (auto st = veneer::ps::write_light_calibration(*cal, lights_file.toStdString()); !st) {
    message(tr("calibration: %1").arg(qs(st.message())), true);
    return false;
  }
  calibration_image_ = to_qimage(veneer::ps::calibration_picture(*set, *cal));
  QString text = tr("%1 lamps calibrated from %2 (sphere radius %3 px) into %4")
                     .arg(cal->directions.size())
                     .arg(sphere_folder)
                     .arg(cal->radius, 0, 'f', 1)
                     .arg(lights_file);
  if (set->lights.size() == cal->directions.size()) {
    double sum = 0;
    for (size_t i = 0; i < cal->directions.size(); ++i)
      sum += veneer::ps::angle_deg(cal->directions[i], set->lights[i].direction);
    text += tr("; %1 deg on average from the set's directions").arg(sum / cal->directions.size(), 0, 'f', 2);
  }
  message(text);
  if (!calibration_dialog_) {
    calibration_dialog_ = new QDialog(this);
    calibration_dialog_->setObjectName("calibrationDialog");
    calibration_dialog_->setWindowTitle(tr("Lamp calibration"));
    auto* layout = new QVBoxLayout(calibration_dialog_);
    calibration_label_ = new QLabel;
    calibration_label_->setObjectName("calibrationPicture");
    calibration_text_ = new QLabel;
    calibration_text_->setWordWrap(true);
    layout->addWidget(calibration_label_);
    layout->addWidget(calibration_text_);
  }
  calibration_label_->setPixmap(QPixmap::fromImage(calibration_image_));
  calibration_text_->setText(text);
  calibration_dialog_->show();
  return true;
}

void MainWindow::addCalibrationMenu(QMenu* menu) {
  menu->addAction(tr("Calibrate lamps from a chrome-sphere set…"), this, [this] {
    const QString dir = QFileDialog::getExistingDirectory(this, tr("Set of chrome-sphere photos"));
    if (dir.isEmpty()) return;
    const QString file = QFileDialog::getSaveFileName(this, tr("Write the lights file"), dir + "/lights.json",
                                                      tr("Lights (*.json)"));
    if (!file.isEmpty()) calibrateLamps(dir, file);
  });
}

}  // namespace veneer::app
