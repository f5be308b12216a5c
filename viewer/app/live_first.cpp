// The full-resolution map is made as `veneer transfer` makes it
// (pipeline::prepare_pair through the result cache, then the transfer with
// the options of the map shown; sets wider than the live view matched at its
// width and refined to full resolution, as the CLI does). Everything heavy --
// the sets, the pictures, the live session -- is made off the GUI thread; the
// swap only moves pointers.
#include <chrono>
#include <thread>

#include <QLabel>
#include <QPointer>
#include <QProgressBar>
#include <QStatusBar>
#include <QtConcurrent/QtConcurrentRun>

#include <opencv2/imgproc.hpp>

#include "live_first.hpp"
#include "background.hpp"
#include "live_tab.hpp"
#include "qt_convert.hpp"
#include "veneer/io/image_io.hpp"
#include "veneer/io/reduced.hpp"
#include "veneer/pipeline/prepare.hpp"
#include "transfer_panel.hpp"
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
  QString live_note;  // why the live session paints the copy only ("" = the look)
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

LiveFirstJob::LiveFirstJob(Session& session, TransferPanel& transfer, QStatusBar* bar, QObject* parent)
    : QObject(parent), session_(session), transfer_(transfer), bar_(bar) {}

QString LiveFirstJob::line() const { return label_ ? label_->text() : QString(); }

void LiveFirstJob::maybeStart() {
  const Session& s = session_;
  if (running_ || !s.result || !s.dst || !s.src || !(s.dst->live_size || s.src->live_size)) return;
  if (s.dst->preview || s.src->preview) return;  // the full files are still being pulled (FlowController::pulled starts it)
  if (!label_) {
    label_ = named<QLabel>("fullResolutionStatus");
    progress_ = named<QProgressBar>("fullResolutionProgress");
    progress_->setMaximumWidth(100);
    progress_->setTextVisible(false);
    bar_->addPermanentWidget(label_);
    bar_->addPermanentWidget(progress_);
  }
  running_ = true;
  cancel_ = std::make_shared<std::atomic<bool>>(false);
  step_.start("full", tr("full resolution"));
  label_->setText(tr("full resolution: starting"));
  label_->setVisible(true);
  progress_->setValue(0);
  progress_->setVisible(true);
  const QString dst_folder = session_.dst->folder, src_folder = session_.src->folder;
  const auto options = session_.shown.options;
  const int generation = session_.sets_loaded;
  const cv::Vec3d light = session_.light();
  auto cancel = cancel_, held = held_;
  QPointer<LiveFirstJob> self(this);
  // below the live view and the GUI: the background's threads at a lower priority, its loops its own (background.hpp)
  (void)run_in_background([self, dst_folder, src_folder, options, generation, cancel, held, light] {
    while (held->load() && !cancel->load()) std::this_thread::sleep_for(std::chrono::milliseconds(20));
    auto report = [self](double f, const std::string& stage) {
      const QString s = qs(stage);
      if (self)
        QMetaObject::invokeMethod(self.data(), [self, f, s] {
          if (!self || !self->running_) return;
          self->step_.update(f, s);
          const double left = self->step_.secondsLeft();
          self->label_->setText(
              left >= 0 ? tr("full resolution: %1 · %2 % · about %3 s left").arg(s).arg(int(f * 100)).arg(int(left + 0.5))
                        : tr("full resolution: %1 · %2 %").arg(s).arg(int(f * 100)));
          self->progress_->setValue(static_cast<int>(f * 100));
        });
    };
    veneer::Progress progress;
    progress.cancel = cancel.get();
    progress.on_progress = report;
    FullResolution out;
    veneer::pipeline::TransferOptions o = options;
    o.keep_pictures = true;
    // as `veneer transfer` makes it: sets wider than the live view matched at
    // its width and refined to full resolution (issue 42), so the map shown
    // is the CLI's (refining the live map itself, made from reduced decodes,
    // gave another map than the CLI's)
    o.refine_from_width = veneer::io::ReducedOptions{}.width;
    std::vector<veneer::pipeline::SetReport> reports;
    veneer::pipeline::PrepareOptions prep = veneer::pipeline::default_prepare_options();  // as `veneer transfer`
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
        // the live look of the full-resolution map too: the Live tab keeps painting the shaded look
        out.session = make_live_session(*pair, o, *out.result, out.src->set.images, pair->src.view.mask,
                                        out.dst->median_picture, &out.live_note, progress.part(0.9, 1.0));
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
      self->running_ = false;
      self->step_.finish();
      self->progress_->setVisible(false);
      if (cancel->load() || generation != self->session_.sets_loaded || !self->session_.dst || !self->session_.src) {
        self->label_->setText(tr("full resolution: not used (the sets changed)"));
        return;
      }
      if (!out.result) {
        self->label_->setText(tr("full resolution failed: %1").arg(out.error));
        self->session_.message(tr("full resolution failed: %1").arg(out.error), true);
        return;
      }
      // The swap: pointers only, everything was made by the job.
      self->session_.dst = out.dst;
      self->session_.src = out.src;
      ++self->session_.sets_loaded;
      self->transfer_.adoptPrepared(out.pair);
      self->session_.result = out.result;
      self->session_.result_picture = out.result_picture;
      self->session_.result_image = out.result_image;
      if (out.relighter) self->session_.relighter = out.relighter;
      self->session_.live_session = out.session;
      self->session_.live_refusal.clear();
      if (!out.live_note.isEmpty()) self->session_.message(out.live_note, true);
      ++self->swaps_;
      self->label_->setText(tr("full resolution: %1x%2 map in use")
                                     .arg(out.result->map.xy.cols)
                                     .arg(out.result->map.xy.rows));
      self->session_.message(
          tr("full-resolution map swapped in (%1x%2)").arg(out.result->map.xy.cols).arg(out.result->map.xy.rows));
      emit self->swapped(out.relit, out.relit_source, light);
    });
  });
}

}  // namespace veneer::app
