#include "calibration.hpp"

#include <QDialog>
#include <QFileDialog>
#include <QLabel>
#include <QVBoxLayout>

#include "veneer/ps/calibration.hpp"
#include "widgets.hpp"

namespace veneer::app {

CalibrationStep::CalibrationStep(Session& session, QWidget* window)
    : QObject(window), session_(session), window_(window) {}

bool CalibrationStep::calibrateLamps(const QString& sphere_folder, const QString& lights_file) {
  // Reading 12 photos and finding their highlights takes well under a second:
  // done here rather than as a cancellable step.
  auto set = veneer::io::read_set(sphere_folder.toStdString());
  if (!set) {
    session_.message(tr("calibration: %1").arg(qs(set.message())), true);
    return false;
  }
  auto cal = veneer::ps::calibrate_mirror_sphere(*set);
  if (!cal) {
    session_.message(tr("calibration from %1: %2").arg(sphere_folder, qs(cal.message())), true);
    return false;
  }
  if (auto st = veneer::ps::write_light_calibration(*cal, lights_file.toStdString()); !st) {
    session_.message(tr("calibration: %1").arg(qs(st.message())), true);
    return false;
  }
  image_ = to_qimage(veneer::ps::calibration_picture(*set, *cal));
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
  session_.message(text);
  if (!dialog_) {
    dialog_ = named<QDialog>("calibrationDialog", window_);
    dialog_->setWindowTitle(tr("Lamp calibration"));
    auto* layout = new QVBoxLayout(dialog_);
    picture_ = named<QLabel>("calibrationPicture");
    text_ = new QLabel;
    text_->setWordWrap(true);
    layout->addWidget(picture_);
    layout->addWidget(text_);
  }
  picture_->setPixmap(QPixmap::fromImage(image_));
  text_->setText(text);
  dialog_->show();
  return true;
}

void CalibrationStep::ask() {
  const QString dir = QFileDialog::getExistingDirectory(window_, tr("Set of chrome-sphere photos"));
  if (dir.isEmpty()) return;
  const QString file =
      QFileDialog::getSaveFileName(window_, tr("Write the lights file"), dir + "/lights.json", tr("Lights (*.json)"));
  if (!file.isEmpty()) calibrateLamps(dir, file);
}

}  // namespace veneer::app
