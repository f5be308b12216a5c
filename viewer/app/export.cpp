// Export: the map, the result pictures, the relight sweep; screenshots of the views.
#include "main_window.hpp"
#include "widgets.hpp"

#include <algorithm>
#include <filesystem>
#include <cmath>

#include <QApplication>
#include <QCheckBox>
#include <QComboBox>
#include <QDir>
#include <QFile>
#include <QFileInfo>
#include <QPointer>
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

// A job off the GUI thread, told in the status line, cancellable there.
void MainWindow::runJob(const QString& kind, const QString& text,
                        std::function<veneer::Status(const veneer::Progress&)> job, const QString& done) {
  if (job_running_) return message(tr("an export is running: wait for it or cancel it"), true);
  job_running_ = true;
  job_cancel_ = false;
  step_.start(kind, text);
  showStep();
  QPointer<MainWindow> self(this);
  job_future_ = QtConcurrent::run(job_pool(), [this, self, job, done] {
    veneer::Progress progress;
    progress.cancel = &job_cancel_;
    progress.on_progress = [self](double f, const std::string& stage) {
      const QString s = qs(stage);
      QMetaObject::invokeMethod(self.data(), [self, f, s] {
        if (!self) return;
        self->step_.update(f);
        self->showStep();
      });
    };
    const veneer::Status s = job(progress);
    // cancelled: the job stopped on the cancel (a cancel that came after it
    // finished changes nothing: what it wrote is whole and in place)
    const bool cancelled = !s && job_cancel_.load();
    const QString error = s ? QString() : qs(s.message());
    QMetaObject::invokeMethod(self.data(), [self, done, error, cancelled] {
      if (!self) return;
      self->job_running_ = false;
      self->step_.finish();
      self->showStep();
      const QString line = cancelled ? tr("export cancelled; nothing half-written was left")
                                     : (error.isEmpty() ? done : error);
      self->step_label_->setText(line);
      self->message(line, !cancelled && !error.isEmpty());
    });
  });
}

void MainWindow::exportMap() {
  if (!result_) return message(tr("nothing to export: compute a transfer first"), true);
  QString dir = QFileDialog::getExistingDirectory(this, tr("Export the map into"));
  if (!dir.isEmpty()) exportMapTo(dir);
}

void MainWindow::exportMapTo(const QString& dir) {
  if (!result_) return message(tr("nothing to export: compute a transfer first"), true);
  auto result = result_;
  runJob("export-map", tr("writing the map into %1").arg(dir), [result, dir](const veneer::Progress& p) -> veneer::Status {
    if (auto s = veneer::match::write_map((dir + "/map.pfm").toStdString(), result->map); !s) return s;
    p.report(0.5, "map.png");
    if (p.cancelled()) {
      QFile::remove(dir + "/map.pfm");
      return veneer::make_error("cancelled");
    }
    if (auto s = veneer::io::write_picture((dir + "/map.png").toStdString(),
                                       veneer::repaint::map_picture(result->map, result->source_size));
        !s)
      return s;
    p.report(1, "done");
    return {};
  }, tr("map written to %1").arg(dir));
}

void MainWindow::exportResults() {
  if (!result_) return message(tr("nothing to export: compute a transfer first"), true);
  QString dir = QFileDialog::getExistingDirectory(this, tr("Export the results into"));
  if (!dir.isEmpty()) exportResultsTo(dir);
}

void MainWindow::exportResultsTo(const QString& dir) {
  if (!result_) return message(tr("nothing to export: compute a transfer first"), true);
  auto result = result_;
  // written into a temporary sibling and moved into place, so a cancel or a
  // failure leaves no half-written folder; a cancel stops between files
  // (write_transfer checks it before each one) and removes the sibling
  runJob("export-results", tr("writing the result pictures into %1").arg(dir),
         [result, dir](const veneer::Progress& p) -> veneer::Status {
           const QString temp = dir + ".part";
           QDir(temp).removeRecursively();
           if (auto s = veneer::pipeline::write_transfer(*result, temp.toStdString(), p.part(0, 0.95)); !s) {
             QDir(temp).removeRecursively();
             return s;
           }
           if (p.cancelled()) {
             QDir(temp).removeRecursively();
             return veneer::make_error("cancelled");
           }
           QDir target(dir);
           QDir().mkpath(dir);
           for (const QString& f : QDir(temp).entryList(QDir::Files)) {
             QFile::remove(target.filePath(f));
             if (!QFile::rename(temp + "/" + f, target.filePath(f)))
               return veneer::make_error("cannot move " + f.toStdString() + " into " + dir.toStdString());
           }
           QDir(temp).removeRecursively();
           p.report(1, "done");
           return {};
         },
         tr("results written to %1").arg(dir));
}

void MainWindow::exportRelightVideo() {
  if (!result_ || !relighter_ || !dst_) return message(tr("nothing to export: compute a transfer first"), true);
  QString file = QFileDialog::getSaveFileName(this, tr("Relight sweep video"), "relight.avi", "AVI (*.avi)");
  if (!file.isEmpty()) exportRelightVideoTo(file);
}

void MainWindow::exportRelightVideoTo(const QString& file) {
  if (!result_ || !relighter_ || !dst_) return message(tr("nothing to export: compute a transfer first"), true);
  auto result = result_;
  auto relighter = relighter_;
  const cv::Mat backdrop = dst_->median * 0.25;
  runJob("export-video", tr("writing the relight sweep %1").arg(file),
         [result, relighter, backdrop, file](const veneer::Progress& p) -> veneer::Status {
           const cv::Size size = result->map.xy.size();
           // written under a temporary name beside it (same suffix: it picks
           // the container) and renamed when whole
           const QFileInfo info(file);
           const QString temp = info.dir().filePath("." + info.completeBaseName() + ".part." + info.suffix());
           cv::VideoWriter writer(temp.toStdString(), cv::VideoWriter::fourcc('M', 'J', 'P', 'G'), 25, size);
           if (!writer.isOpened()) return veneer::make_error("cannot write a video to " + file.toStdString());
           const int frames = 100;
           for (int i = 0; i < frames; ++i) {
             if (p.cancelled()) {
               writer.release();
               QFile::remove(temp);
               return veneer::make_error("cancelled");
             }
             const double a = 2 * M_PI * i / frames;
             const cv::Vec3d d = veneer::repaint::direction_on_sphere(0.7 * std::cos(a), 0.7 * std::sin(a));
             writer << io::tonemap_picture(relighter->render(result->map, d, backdrop));
             p.report((i + 1.0) / frames, "frame");
           }
           writer.release();
           std::error_code ec;  // replaces an older file in one step
           std::filesystem::rename(temp.toStdString(), file.toStdString(), ec);
           if (ec) {
             QFile::remove(temp);
             return veneer::make_error("cannot move the video into " + file.toStdString() + ": " + ec.message());
           }
           return {};
         },
         tr("relight sweep written to %1").arg(file));
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
