// The one flow from capture to live repaint, and the status line that tells
// where it is. Every step runs off the GUI thread; this file only chains them.
#include <QCheckBox>
#include <QFileInfo>
#include <QLabel>
#include <QPointer>
#include <QProgressBar>
#include <QPushButton>
#include <QtConcurrent/QtConcurrentRun>

#include <opencv2/imgproc.hpp>

#include "main_window.hpp"
#include "qt_convert.hpp"
#include "veneer/io/image_io.hpp"
#include "veneer/io/reduced.hpp"
#include "widgets.hpp"

namespace veneer::app {

bool MainWindow::autoFlow() const { return auto_flow_ && auto_flow_->isChecked(); }

void MainWindow::setAutoFlow(bool on) { auto_flow_->setChecked(on); }

QString MainWindow::stepLine() const { return step_label_ ? step_label_->text() : QString(); }

void MainWindow::showStep() {
  step_label_->setText(step_.line());
  const double f = step_.fraction();
  if (step_.running() && f < 0) {
    step_bar_->setRange(0, 0);  // busy, amount unknown
  } else {
    step_bar_->setRange(0, 100);
    step_bar_->setValue(f < 0 ? 0 : static_cast<int>(f * 100));
  }
  step_bar_->setVisible(step_.running());
  step_cancel_->setVisible(step_.running() || computing_ || job_running_ || loads_running_ > 0 || rig_.pulling());
  if (step_.running() && !step_timer_.isActive()) step_timer_.start();
  if (!step_.running()) step_timer_.stop();
}

// A set was stored on the rig, by whatever pressed the trigger: pull it.
void MainWindow::flowSetStored(const QString& id, veneer::io::Role role) {
  if (!autoFlow()) return;
  auto_pulls_[id] = role;
  step_.start("pull", role == veneer::io::Role::unknown ? tr("pulling %1").arg(id)
                                                     : tr("pulling %1 (%2)").arg(id, qs(veneer::io::role_name(role))));
  showStep();
  pull_bar_->setVisible(true);
  pull_bar_->setValue(0);
  rig_.pull(id, workdir_ + "/sets/" + id);
}

void MainWindow::flowPulled(const QString& id, const QString& folder) {
  auto it = auto_pulls_.find(id);
  std::optional<veneer::io::Role> role;
  if (it != auto_pulls_.end()) {
    role = it->second;
    auto_pulls_.erase(it);
    step_.finish();
  }
  loadSetInBackground(folder, role);
}

namespace {
// What loading a set makes off the GUI thread.
struct ReadSet {
  std::shared_ptr<LoadedSet> loaded;
  cv::Mat thumbnail;
  QString error;
};

cv::Mat thumbnail_of(const veneer::io::ImageSet& set) {
  if (set.images.empty()) return {};
  cv::Mat small;
  cv::resize(set.images.front(), small,
             cv::Size(96, std::max(1, 96 * set.size.height / std::max(1, set.size.width))), 0, 0, cv::INTER_AREA);
  return small;
}
}  // namespace

namespace {
// A set at the live view's width; `smaller` says whether that is smaller than the set.
// A set no wider is read whole, as before (the map is then the full-resolution one).
veneer::Expected<veneer::io::ImageSet> read_live_size(const std::string& folder, int width, bool* smaller) {
  veneer::io::ReadOptions manifest;
  manifest.load_photos = false;
  manifest.load_truth = false;
  auto whole = veneer::io::read_set(folder, manifest);
  if (!whole || whole->size.width <= width) return veneer::io::read_set(folder);
  veneer::io::ReducedOptions o;
  o.width = width;
  auto set = veneer::io::read_set_reduced(folder, o);
  *smaller = set && set->size.width < whole->size.width;
  return set;
}
}  // namespace

void MainWindow::loadSetInBackground(const QString& folder, std::optional<veneer::io::Role> as) {
  ++loads_running_;
  const QString name = QFileInfo(folder).fileName();
  if (as) {
    step_.start("load", *as == veneer::io::Role::unknown
                            ? tr("loading %1").arg(name)
                            : tr("loading %1 as the %2").arg(name, qs(veneer::io::role_name(*as))));
    showStep();
  }
  const bool full = as.has_value();
  // live first: the flow's sets at the live view's width (live_first.cpp)
  const int live_width = full && autoFlow() ? live_width_ : 0;
  QPointer<MainWindow> self(this);
  auto cancel = load_cancel_;
  (void)QtConcurrent::run(job_pool(), [self, folder, as, full, cancel, live_width] {
    ReadSet r;
    bool live_size = false;
    auto read = live_width > 0 ? read_live_size(folder.toStdString(), live_width, &live_size)
                               : veneer::io::read_set(folder.toStdString());
    if (!read) {
      r.error = qs(read.message());
    } else {
      r.loaded = std::make_shared<LoadedSet>();
      r.loaded->folder = folder;
      r.loaded->set = std::move(*read);
      r.loaded->live_size = live_size;
      r.thumbnail = thumbnail_of(r.loaded->set);
      if (full) {
        r.loaded->median = veneer::repaint::median_photo(r.loaded->set.images);
        r.loaded->median_picture = io::tonemap_picture(r.loaded->median);
        r.loaded->median_image = to_qimage(r.loaded->median_picture);  // what the views show, made here
        r.loaded->histogram = luminance_histogram(r.loaded->median_picture);
      }
    }
    QMetaObject::invokeMethod(self.data(), [self, r, as, folder, cancel] {
      if (!self) return;
      --self->loads_running_;
      if (as) self->step_.finish();
      if (cancel->load()) {
        self->message(tr("loading %1 cancelled").arg(folder));
        self->showStep();
        return;
      }
      if (!r.loaded) {
        if (self->reopen_ && (folder == self->reopen_->entry.destination || folder == self->reopen_->entry.source)) {
          self->reopen_.reset();
          self->message(tr("cannot reopen the map: %1").arg(r.error), true);
          self->showStep();
          return;
        }
        self->message(r.error, true);
        self->showStep();
        return;
      }
      self->addLocalItem(folder, r.loaded->set, r.thumbnail);
      if (!as) {
        self->showStep();
        return;
      }
      // unknown: the role the set's manifest gives it
      const veneer::io::Role role = *as != veneer::io::Role::unknown ? *as : r.loaded->set.role;
      if (role == veneer::io::Role::unknown) {
        self->message(tr("%1 has no role in its manifest: choose → Destination or → Source").arg(folder), true);
        self->showStep();
        return;
      }
      self->setLoaded(r.loaded, role);
      self->computeNormals(r.loaded);
      self->message(tr("loaded %1 as the %2").arg(folder, qs(veneer::io::role_name(role))));
      self->showStep();
      if (!self->reopenWhenLoaded(folder, role)) self->flowMaybeCompute();
    });
  });
}

void MainWindow::cancelStep() {
  if (computing_) cancelTransfer();
  if (job_running_) job_cancel_ = true;
  if (full_running_) full_cancel_->store(true);
  if (rig_.pulling()) {
    rig_.cancelPulls();
    auto_pulls_.clear();
  }
  reopen_.reset();
  if (loads_running_ > 0) {
    load_cancel_->store(true);
    load_cancel_ = std::make_shared<std::atomic<bool>>(false);
  }
  if (step_.running() && (step_.kind() == "capture" || step_.kind() == "store")) rig_.cancelCapture();
  message(tr("cancelling…"));
}

// Both sets there: the map, with the settings shown (the defaults unless the
// user changed them).
void MainWindow::flowMaybeCompute() {
  if (!autoFlow() || !dst_ || !src_) return;
  if (computing_) {
    rerun_ = true;  // a set changed under the running transfer: once more with both
    return;
  }
  if (result_) return;
  startTransfer();
}

// A map is shown and a rig is there: the live repaint starts by itself.
void MainWindow::flowMaybeGoLive() {
  if (!autoFlow() || !result_ || !rig_.isConnected() || live_btn_->isChecked()) return;
  showTab("Live");
  live_btn_->setChecked(true);
}

}  // namespace veneer::app
