#include "export.hpp"

#include <cmath>
#include <filesystem>

#include <QDir>
#include <QFile>
#include <QFileDialog>
#include <QFileInfo>
#include <QPointer>
#include <QtConcurrent/QtConcurrentRun>

#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>

#include "veneer/io/image_io.hpp"
#include "veneer/repaint/web_export.hpp"
#include "widgets.hpp"

namespace veneer::app {

ExportActions::ExportActions(Session& session, QWidget* window)
    : QObject(window), session_(session), window_(window) {}

ExportActions::~ExportActions() {
  job_cancel_ = true;
  job_future_.waitForFinished();
}

// A job off the GUI thread, told in the status line, cancellable there.
void ExportActions::runJob(const QString& kind, const QString& text,
                        std::function<veneer::Status(const veneer::Progress&)> job, const QString& done) {
  if (job_running_) return session_.message(tr("an export is running: wait for it or cancel it"), true);
  job_running_ = true;
  job_cancel_ = false;
  session_.status.step().start(kind, text);
  session_.status.showStep();
  QPointer<ExportActions> self(this);
  job_future_ = QtConcurrent::run(job_pool(), [this, self, job, done] {
    veneer::Progress progress;
    progress.cancel = &job_cancel_;
    progress.on_progress = [self](double f, const std::string& stage) {
      const QString s = qs(stage);
      QMetaObject::invokeMethod(self.data(), [self, f, s] {
        if (!self) return;
        self->session_.status.step().update(f);
        self->session_.status.showStep();
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
      self->session_.status.step().finish();
      self->session_.status.showStep();
      const QString line = cancelled ? tr("export cancelled; nothing half-written was left")
                                     : (error.isEmpty() ? done : error);
      self->session_.status.say(line);
      self->session_.message(line, !cancelled && !error.isEmpty());
    });
  });
}

bool ExportActions::haveResult() {
  if (!session_.result) session_.message(tr("nothing to export: compute a transfer first"), true);
  return session_.result != nullptr;
}

void ExportActions::exportIntoFolder(const QString& title, void (ExportActions::*into)(const QString&)) {
  if (!haveResult()) return;
  const QString dir = QFileDialog::getExistingDirectory(window_, title);
  if (!dir.isEmpty()) (this->*into)(dir);
}

void ExportActions::exportMap() { exportIntoFolder(tr("Export the map into"), &ExportActions::exportMapTo); }

void ExportActions::exportMapTo(const QString& dir) {
  if (!haveResult()) return;
  auto result = session_.result;
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

void ExportActions::exportResults() {
  exportIntoFolder(tr("Export the results into"), &ExportActions::exportResultsTo);
}

void ExportActions::exportResultsTo(const QString& dir) {
  if (!haveResult()) return;
  auto result = session_.result;
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

void ExportActions::exportWebPage() {
  if (!haveResult()) return;
  const QString dir = QFileDialog::getSaveFileName(window_, tr("Web page of the look (a new folder)"), "look",
                                                   QString(), nullptr, QFileDialog::ShowDirsOnly);
  if (!dir.isEmpty()) exportWebPageTo(dir);
}

void ExportActions::exportWebPageTo(const QString& dir) {
  if (!haveResult()) return;
  if (!session_.dst || !session_.src) return session_.message(tr("nothing to export: load both sets first"), true);
  auto result = session_.result;
  std::vector<cv::Vec3d> directions;
  for (const veneer::io::Light& l : session_.dst->set.lights) directions.push_back(l.direction);
  veneer::repaint::WebExportOptions options;
  options.object = session_.dst->set.object.empty() ? QFileInfo(session_.dst->folder).fileName().toStdString()
                                                     : session_.dst->set.object;
  options.material = session_.src->set.object.empty() ? QFileInfo(session_.src->folder).fileName().toStdString()
                                                        : session_.src->set.object;
  if (auto s = veneer::repaint::check_web_folder(dir.toStdString()); !s) return session_.message(qs(s.message()), true);
  runJob("export-web", tr("writing the web page into %1").arg(dir),
         [result, directions, options, dir](const veneer::Progress& p) -> veneer::Status {
           if (result->repainted.size() != directions.size())
             return veneer::make_error("the result holds " + std::to_string(result->repainted.size()) +
                                       " repainted photos for " + std::to_string(directions.size()) + " lamps");
           std::vector<cv::Mat> photos;  // the page's size first, in float (the fit's input)
           for (const cv::Mat& r : result->repainted) {
             cv::Mat f = r;
             if (f.depth() != CV_32F) r.convertTo(f, CV_32F);
             cv::Mat small;
             cv::resize(f, small, veneer::repaint::web_size(f.size(), options.max_side), 0, 0, cv::INTER_AREA);
             photos.push_back(small);
           }
           auto page = veneer::repaint::export_web(photos, directions, dir.toStdString(), options, p);
           if (!page) return page.error();
           return {};
         },
         tr("web page written to %1/index.html: send the whole folder").arg(dir));
}

void ExportActions::exportRelightVideo() {
  if (!session_.result || !session_.relighter || !session_.dst)
    return session_.message(tr("nothing to export: compute a transfer first"), true);
  QString file = QFileDialog::getSaveFileName(window_, tr("Relight sweep video"), "relight.avi", "AVI (*.avi)");
  if (!file.isEmpty()) exportRelightVideoTo(file);
}

void ExportActions::exportRelightVideoTo(const QString& file) {
  if (!session_.result || !session_.relighter || !session_.dst)
    return session_.message(tr("nothing to export: compute a transfer first"), true);
  auto result = session_.result;
  auto relighter = session_.relighter;
  const cv::Mat backdrop = session_.dst->median * 0.25;
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

}  // namespace veneer::app
