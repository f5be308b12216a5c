// Live first: the automatic flow went live on a map made at the live view's
// width (flow.cpp reads the pulled sets through reduced decodes); here the
// full-resolution map follows in the background, made as `veneer transfer`
// makes it (pipeline::prepare_pair through the result cache, then the
// transfer with the options of the map shown), and replaces the live one
// when done. Everything heavy -- the sets, the pictures, the live session --
// is made off the GUI thread; the swap itself only moves pointers.
#include <QLabel>
#include <QPointer>
#include <QProgressBar>
#include <QStatusBar>
#include <QtConcurrent/QtConcurrentRun>

#include <opencv2/imgproc.hpp>

#include "main_window.hpp"
#include "qt_convert.hpp"
#include "veneer/io/image_io.hpp"
#include "veneer/pipeline/prepare.hpp"
#include "image_view.hpp"
#include "sphere_pad.hpp"
#include "veneer/ps/photometric_stereo.hpp"
#include "widgets.hpp"

namespace veneer::app {

namespace {

// What the background job hands the GUI thread.
struct FullResolution {
  std::shared_ptr<LoadedSet> dst, src;
  std::shared_ptr<const veneer::pipeline::PreparedPair> pair;
  std::shared_ptr<veneer::pipeline::TransferResult> result;
  cv::Mat result_picture;
  QImage result_image;
  std::shared_ptr<veneer::repaint::LiveSession> session;
  std::shared_ptr<veneer::repaint::Relighter> relighter;
  QImage relit, relit_source;  // the relight views for `light`, made by the job
  QString error;
};

std::shared_ptr<LoadedSet> loaded_from(const QString& folder, const veneer::io::ImageSet& set) {
  auto l = std::make_shared<LoadedSet>();
  l->folder = folder;
  l->set = set;
  l->median = veneer::repaint::median_photo(l->set.images);
  l->median_picture = io::tonemap_picture(l->median);
  l->median_image = to_qimage(l->median_picture);
  l->histogram = luminance_histogram(l->median_picture);
  return l;
}

}  // namespace

QString MainWindow::fullResolutionLine() const { return full_label_ ? full_label_->text() : QString(); }

void MainWindow::flowMaybeFullResolution() {
  if (!autoFlow() || full_running_ || !result_ || !dst_ || !src_ || !(dst_->live_size || src_->live_size)) return;
  if (!full_label_) {
    full_label_ = new QLabel;
    full_label_->setObjectName("fullResolutionStatus");
    full_bar_ = new QProgressBar;
    full_bar_->setObjectName("fullResolutionProgress");
    full_bar_->setMaximumWidth(100);
    full_bar_->setTextVisible(false);
    statusBar()->addPermanentWidget(full_label_);
    statusBar()->addPermanentWidget(full_bar_);
  }
  full_running_ = true;
  full_cancel_ = std::make_shared<std::atomic<bool>>(false);
  full_step_.start("full", tr("full resolution"));
  full_label_->setText(tr("full resolution: starting"));
  full_label_->setVisible(true);
  full_bar_->setValue(0);
  full_bar_->setVisible(true);
  const QString dst_folder = dst_->folder, src_folder = src_->folder;
  const auto options = shown_.options;
  const int generation = sets_loaded_;
  const cv::Vec3d light = relight_pad_->direction();
  auto cancel = full_cancel_;
  QPointer<MainWindow> self(this);
  (void)QtConcurrent::run(job_pool(), [self, dst_folder, src_folder, options, generation, cancel, light] {
    auto report = [self](double f, const std::string& stage) {
      const QString s = qs(stage);
      if (self)
        QMetaObject::invokeMethod(self.data(), [self, f, s] {
          if (!self || !self->full_running_) return;
          self->full_step_.update(f, s);
          const double left = self->full_step_.secondsLeft();
          self->full_label_->setText(
              left >= 0 ? tr("full resolution: %1 · %2 % · about %3 s left").arg(s).arg(int(f * 100)).arg(int(left + 0.5))
                        : tr("full resolution: %1 · %2 %").arg(s).arg(int(f * 100)));
          self->full_bar_->setValue(static_cast<int>(f * 100));
        });
    };
    veneer::Progress progress;
    progress.cancel = cancel.get();
    progress.on_progress = report;
    FullResolution out;
    veneer::pipeline::TransferOptions o = options;
    o.keep_pictures = true;
    std::vector<veneer::pipeline::SetReport> reports;
    veneer::pipeline::PrepareOptions prep;
    prep.read.raw.demosaic = veneer::io::Demosaic::mhc;  // as `veneer transfer` reads RAW files (its default)
    auto pair = veneer::pipeline::prepare_pair(dst_folder.toStdString(), src_folder.toStdString(), o, prep, &reports,
                                               progress.part(0, 0.6));
    if (!pair) {
      out.error = qs(pair.message());
    } else {
      auto result = veneer::pipeline::transfer(*pair, o, progress.part(0.6, 0.9));
      if (!result) {
        out.error = qs(result.message());
      } else {
        report(0.9, "pictures and the live session");
        out.result = std::make_shared<veneer::pipeline::TransferResult>(std::move(*result));
        out.result_picture = picture_of(out.result->repainted_median);
        out.result_image = to_qimage(out.result_picture);
        out.dst = loaded_from(dst_folder, pair->destination);
        out.src = loaded_from(src_folder, pair->source);
        out.session = std::make_shared<veneer::repaint::LiveSession>(out.src->set.images, pair->src.view.mask,
                                                                   out.result->map, out.result->source_size,
                                                                   out.dst->median_picture, out.result->blend);
        // the Look tab's normals, albedo and mask views: the pair's
        for (auto [l, o] : {std::pair{out.dst.get(), &pair->dst}, std::pair{out.src.get(), &pair->src}}) {
          veneer::ps::PsResult ps;
          ps.normals = o->view.normals;
          ps.mask = o->view.mask;
          l->normals.emplace(std::move(ps));
        }
        auto fitted = veneer::repaint::Relighter::fit(out.src->set);
        if (fitted) {
          out.relighter = std::make_shared<veneer::repaint::Relighter>(std::move(*fitted));
          out.relit = to_qimage(picture_of(out.relighter->render(out.result->map, light, out.dst->median * 0.25)));
          out.relit_source = to_qimage(picture_of(out.relighter->render_source(light)));
        }
        out.pair = std::make_shared<const veneer::pipeline::PreparedPair>(std::move(*pair));
      }
    }
    (void)veneer::pipeline::finish_cache_writes();
    if (!self) return;
    QMetaObject::invokeMethod(self.data(), [self, out, generation, cancel, light] {
      if (!self) return;
      self->full_running_ = false;
      self->full_step_.finish();
      self->full_bar_->setVisible(false);
      if (cancel->load() || generation != self->sets_loaded_ || !self->dst_ || !self->src_) {
        self->full_label_->setText(tr("full resolution: not used (the sets changed)"));
        return;
      }
      if (!out.result) {
        self->full_label_->setText(tr("full resolution failed: %1").arg(out.error));
        self->message(tr("full resolution failed: %1").arg(out.error), true);
        return;
      }
      // The swap: pointers only, everything was made by the job.
      self->dst_ = out.dst;
      self->src_ = out.src;
      ++self->sets_loaded_;
      self->prepared_ = out.pair;
      self->prepared_key_ = self->preparationKey();
      self->result_ = out.result;
      self->result_picture_ = out.result_picture;
      self->result_image_ = out.result_image;
      if (out.relighter) self->relighter_ = out.relighter;
      self->live_session_ = out.session;
      self->live_refusal_.clear();
      ++self->full_swaps_;
      self->full_label_->setText(tr("full resolution: %1x%2 map in use")
                                     .arg(out.result->map.xy.cols)
                                     .arg(out.result->map.xy.rows));
      self->message(tr("full-resolution map swapped in (%1x%2)").arg(out.result->map.xy.cols).arg(out.result->map.xy.rows));
      self->refreshLook();
      if (out.relighter && light == self->relight_pad_->direction()) {
        self->relight_view_->setImage(out.relit);
        self->relight_src_view_->setImage(out.relit_source);
        self->updateRelightLabel(light);
      } else {
        self->refreshRelight();
      }
    });
  });
}

}  // namespace veneer::app
