// Export: the map, the result pictures, the relight sweep; screenshots of the views.
#include "main_window.hpp"
#include "widgets.hpp"

#include <algorithm>
#include <cmath>

#include <QApplication>
#include <QCheckBox>
#include <QComboBox>
#include <QDir>
#include <QDoubleSpinBox>
#include <QFileDialog>
#include <QFormLayout>
#include <QGroupBox>
#include <QHBoxLayout>
#include <QLabel>
#include <QLineEdit>
#include <QMenuBar>
#include <QProgressBar>
#include <QPushButton>
#include <QScrollArea>
#include <QSpinBox>
#include <QSplitter>
#include <QStandardPaths>
#include <QStatusBar>
#include <QTabWidget>
#include <QTreeWidget>
#include <QVBoxLayout>
#include <QtConcurrent/QtConcurrentRun>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>

#include "veneer/io/image_io.hpp"
#include "veneer/ps/segmentation.hpp"

namespace veneer::app {

// ---------------------------------------------------------------- export

void MainWindow::exportMap() {
  if (!result_) return message(tr("nothing to export: compute a transfer first"), true);
  QString dir = QFileDialog::getExistingDirectory(this, tr("Export the map into"));
  if (dir.isEmpty()) return;
  auto s = veneer::match::write_map((dir + "/map.pfm").toStdString(), result_->map);
  if (!s) return message(qs(s.message()), true);
  cv::imwrite((dir + "/map.png").toStdString(), veneer::match::map_picture(result_->map, result_->source_size));
  message(tr("map written to %1").arg(dir));
}

void MainWindow::exportResults() {
  if (!result_) return message(tr("nothing to export: compute a transfer first"), true);
  QString dir = QFileDialog::getExistingDirectory(this, tr("Export the results into"));
  if (dir.isEmpty()) return;
  auto s = veneer::match::write_transfer(*result_, dir.toStdString());
  message(s ? tr("results written to %1").arg(dir) : qs(s.message()), !s);
}

void MainWindow::exportRelightVideo() {
  if (!result_ || !relighter_ || !dst_) return message(tr("nothing to export: compute a transfer first"), true);
  QString file = QFileDialog::getSaveFileName(this, tr("Relight sweep video"), "relight.avi", "AVI (*.avi)");
  if (file.isEmpty()) return;
  const cv::Size size = result_->map.xy.size();
  cv::VideoWriter writer(file.toStdString(), cv::VideoWriter::fourcc('M', 'J', 'P', 'G'), 25, size);
  if (!writer.isOpened()) return message(tr("cannot write a video to %1").arg(file), true);
  cv::Mat backdrop = dst_->median * 0.25;
  for (int i = 0; i < 100; ++i) {
    const double a = 2 * M_PI * i / 100.0;
    const cv::Vec3d d = veneer::match::direction_on_sphere(0.7 * std::cos(a), 0.7 * std::sin(a));
    writer << tonemap_picture(relighter_->render(result_->map, d, backdrop));
  }
  message(tr("relight sweep written to %1").arg(file));
}

QStringList MainWindow::saveScreenshots(const QString& dir) {
  QDir().mkpath(dir);
  QStringList files;
  const int current = tabs_->currentIndex();
  for (int i = 0; i < tabs_->count(); ++i) {
    tabs_->setCurrentIndex(i);
    QApplication::processEvents();
    const QString f = dir + "/" + tabs_->tabText(i).toLower() + ".png";
    if (grab().save(f)) files << f;
  }
  tabs_->setCurrentIndex(current);
  return files;
}

void MainWindow::showTab(const QString& name) {
  for (int i = 0; i < tabs_->count(); ++i)
    if (tabs_->tabText(i).compare(name, Qt::CaseInsensitive) == 0) tabs_->setCurrentIndex(i);
}

}  // namespace veneer::app
