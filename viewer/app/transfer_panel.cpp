// The Transfer panel: the compute settings and the transfer run off the GUI thread.
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
#include <QSignalBlocker>
#include <QSpinBox>
#include <QToolButton>
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

namespace {
const char* kMethods[] = {"combined", "coherent", "linear", "flann", "candidates", "patchmatch", "regiongrow", "baseline"};
}  // namespace

QWidget* MainWindow::buildTransferPanel() {
  auto* box = new QGroupBox(tr("Transfer"));
  auto* outer = new QVBoxLayout(box);
  auto* top = new QFormLayout;
  outer->addLayout(top);
  preset_ = new QComboBox;
  preset_->setObjectName("preset");
  for (const auto& p : presets()) preset_->addItem(p.name);
  preset_->addItem(tr("custom"));
  preset_->setToolTip(tr("settings for common needs; changing a setting under Advanced makes it \"custom\""));
  top->addRow(tr("Preset"), preset_);
  // Every expert parameter lives in a fold, closed at first.
  auto* fold = new QToolButton;
  fold->setObjectName("advancedToggle");
  fold->setText(tr("Advanced"));
  fold->setCheckable(true);
  fold->setToolButtonStyle(Qt::ToolButtonTextBesideIcon);
  fold->setArrowType(Qt::RightArrow);
  fold->setAutoRaise(true);
  outer->addWidget(fold);
  auto* advanced = new QWidget;
  advanced->setObjectName("advanced");
  advanced->setVisible(false);
  outer->addWidget(advanced);
  connect(fold, &QToolButton::toggled, this, [fold, advanced](bool open) {
    fold->setArrowType(open ? Qt::DownArrow : Qt::RightArrow);
    advanced->setVisible(open);
  });
  auto* form = new QFormLayout(advanced);
  form->setContentsMargins(12, 0, 0, 0);
  method_ = new QComboBox;
  method_->setObjectName("method");
  for (const char* m : kMethods) method_->addItem(m);
  feature_ = new QComboBox;
  feature_->setObjectName("feature");
  feature_->addItems({"normals", "intensities"});
  patch_ = new QComboBox;
  patch_->setObjectName("patch");
  patch_->addItems({"1", "3", "5", "7"});
  // every matching box starts at the default transfer's (the CLI's)
  const veneer::match::MatchOptions defaults = veneer::pipeline::default_match_options();
  const veneer::pipeline::TransferOptions transfer_defaults;
  candidates_ = new QSpinBox;
  candidates_->setObjectName("candidates");
  candidates_->setRange(1, 100);
  candidates_->setValue(defaults.candidates);
  threshold_ = number_box("threshold", 0, 2, 3, 0.01, defaults.threshold);
  iterations_ = new QSpinBox;
  iterations_->setObjectName("iterations");
  iterations_->setRange(1, 50);
  iterations_->setValue(defaults.iterations);
  coherent_threshold_ = number_box("coherentThreshold", 0, 2, 3, 0.01, defaults.coherent_threshold,
                                   tr("coherent: the normal error a chunk may make (0.1 = about 6°; on intensities "
                                      "converted by the destination's own normals)"));
  coherent_smooth_ = number_box("coherentSmooth", 0, 20, 2, 0.25, defaults.coherent_smooth,
                                tr("coherent: how much a seam between two chunks costs, in coherent thresholds "
                                   "(0 = chunks only; larger = fewer seams, less exact shading)"));
  coherent_guide_ = number_box("coherentGuide", 0, 32, 1, 1, defaults.coherent_guide,
                               tr("coherent on normals: match the source's normals smoothed over this radius, so "
                                  "its small relief (dimples, grain) is copied whole (0 = off)"));
  coherent_guide_->setSuffix(tr(" px"));
  blend_ = new QSpinBox;
  blend_->setObjectName("blend");
  blend_->setRange(0, 16);
  blend_->setSuffix(tr(" px"));
  blend_->setValue(transfer_defaults.blend);
  blend_->setToolTip(tr("result pictures: blend the chunks meeting at a seam over this radius (0 = off: each "
                        "pixel its own source pixel)"));
  blend_guide_ = number_box("blendGuide", 0, 2, 2, 0.05, transfer_defaults.blend_guide,
                            tr("result pictures, maps matched on normals: blend only chunks whose normals fit "
                               "(fall-off |dn|, 0.1 = about 6°), so outlines such as a leg in front of the body "
                               "stay sharp (0 = plain blend)"));
  uniformity_ = number_box("uniformity", 0, 10, 2, 0.1, defaults.uniformity);
  fast_ = new QCheckBox(tr("fast engine"));
  fast_->setObjectName("fast");
  fast_->setChecked(true);
  truth_normals_ = new QCheckBox(tr("truth normals (simulated sets)"));
  truth_normals_->setObjectName("truthNormals");
  seg_method_ = new QComboBox;
  seg_method_->setObjectName("segMethod");
  seg_method_->addItems({"automatic", "otsu", "threshold"});
  seg_threshold_ = number_box("segThreshold", 0, 0.99, 3, 0.005, veneer::ps::SegmentOptions{}.threshold);
  rect_label_ = new QLabel(tr("no rectangle (shift+drag on the destination)"));
  rect_label_->setWordWrap(true);
  form->addRow(tr("Method"), method_);
  form->addRow(tr("Feature"), feature_);
  form->addRow(tr("Patch"), patch_);
  form->addRow(tr("Candidates K"), candidates_);
  form->addRow(tr("Region threshold"), threshold_);
  form->addRow(tr("PatchMatch iterations"), iterations_);
  form->addRow(tr("Coherent threshold"), coherent_threshold_);
  form->addRow(tr("Seam cost"), coherent_smooth_);
  form->addRow(tr("Source relief"), coherent_guide_);
  form->addRow(tr("Uniformity"), uniformity_);
  form->addRow(tr("Blend seams"), blend_);
  form->addRow(tr("Blend guide"), blend_guide_);
  form->addRow(fast_);
  form->addRow(truth_normals_);
  live_update_ = new QCheckBox(tr("recompute as options change"));
  live_update_->setObjectName("liveUpdate");
  live_update_->setChecked(true);
  live_update_->setToolTip(tr("after a first Compute, changing a matching option recomputes the map alone "
                              "(normals and masks are kept)"));
  top->addRow(live_update_);
  form->addRow(tr("Segmentation"), seg_method_);
  form->addRow(tr("Seg. threshold"), seg_threshold_);
  form->addRow(rect_label_);
  compute_btn_ = button(tr("Compute"), "compute", box);
  cancel_btn_ = button(tr("Cancel"), "cancelTransfer", box);
  cancel_btn_->setEnabled(false);
  connect(compute_btn_, &QPushButton::clicked, this, &MainWindow::startTransfer);
  connect(cancel_btn_, &QPushButton::clicked, this, &MainWindow::cancelTransfer);
  for (QComboBox* c : {method_, feature_, patch_})
    connect(c, &QComboBox::currentIndexChanged, this, &MainWindow::matchOptionChanged);
  for (QSpinBox* b : {candidates_, iterations_, blend_})
    connect(b, &QSpinBox::valueChanged, this, &MainWindow::matchOptionChanged);
  for (QDoubleSpinBox* b : {threshold_, coherent_threshold_, coherent_smooth_, coherent_guide_, uniformity_, blend_guide_})
    connect(b, &QDoubleSpinBox::valueChanged, this, &MainWindow::matchOptionChanged);
  connect(fast_, &QCheckBox::toggled, this, &MainWindow::matchOptionChanged);
  // segmentation and truth normals change the prepared objects: prepared again, then the map
  connect(truth_normals_, &QCheckBox::toggled, this, &MainWindow::matchOptionChanged);
  connect(seg_method_, &QComboBox::currentIndexChanged, this, &MainWindow::matchOptionChanged);
  connect(seg_threshold_, &QDoubleSpinBox::valueChanged, this, &MainWindow::matchOptionChanged);
  connect(preset_, &QComboBox::currentIndexChanged, this, [this](int i) {
    if (i >= 0 && i < static_cast<int>(presets().size())) applyPreset(presets()[i]);
  });
  // a setting changed by hand: no preset describes it any more
  auto custom = [this] {
    if (applying_preset_) return;
    QSignalBlocker block(preset_);
    preset_->setCurrentIndex(preset_->count() - 1);
  };
  for (QComboBox* c : {method_, feature_, patch_}) connect(c, &QComboBox::currentIndexChanged, this, custom);
  for (QSpinBox* b : {candidates_, iterations_, blend_}) connect(b, &QSpinBox::valueChanged, this, custom);
  for (QDoubleSpinBox* b : {threshold_, coherent_threshold_, coherent_smooth_, coherent_guide_, uniformity_, blend_guide_})
    connect(b, &QDoubleSpinBox::valueChanged, this, custom);
  connect(fast_, &QCheckBox::toggled, this, custom);
  applyPreset(presets().front());
  auto* bottom = new QFormLayout;
  outer->addLayout(bottom);
  auto* row = new QHBoxLayout;
  row->addWidget(compute_btn_);
  row->addWidget(cancel_btn_);
  bottom->addRow(row);
  transfer_bar_ = new QProgressBar;
  transfer_bar_->setObjectName("transferProgress");
  transfer_label_ = new QLabel;
  transfer_label_->setObjectName("transferStatus");
  transfer_label_->setWordWrap(true);
  bottom->addRow(transfer_bar_);
  bottom->addRow(transfer_label_);
  return box;
}


// The presets: the CLI's defaults first (what the flow computes with).
const std::vector<MainWindow::Preset>& MainWindow::presets() {
  static const std::vector<Preset> list = [] {
    const veneer::match::MatchOptions m = veneer::pipeline::default_match_options();
    const veneer::pipeline::TransferOptions t;
    Preset standard{tr("default (combined)"), "combined", "normals", 1, m.candidates, m.threshold, m.iterations,
                    m.coherent_threshold, m.coherent_smooth, m.coherent_guide, m.uniformity, t.blend, t.blend_guide,
                    true};
    Preset quick = standard;
    quick.name = tr("quick preview (coherent)");
    quick.method = "coherent";
    Preset faithful = standard;
    faithful.name = tr("faithful, slow (linear, 3x3 patches)");
    faithful.method = "linear";
    faithful.patch = 3;
    faithful.fast = false;
    return std::vector<Preset>{standard, quick, faithful};
  }();
  return list;
}

void MainWindow::applyPreset(const Preset& p) {
  applying_preset_ = true;
  {
    // one recomputation for the whole preset, not one per field
    const bool was = live_update_ && live_update_->isChecked();
    if (live_update_) live_update_->setChecked(false);
    method_->setCurrentText(p.method);
    feature_->setCurrentText(p.feature);
    patch_->setCurrentText(QString::number(p.patch));
    candidates_->setValue(p.candidates);
    threshold_->setValue(p.threshold);
    iterations_->setValue(p.iterations);
    coherent_threshold_->setValue(p.coherent_threshold);
    coherent_smooth_->setValue(p.coherent_smooth);
    coherent_guide_->setValue(p.coherent_guide);
    uniformity_->setValue(p.uniformity);
    blend_->setValue(p.blend);
    blend_guide_->setValue(p.blend_guide);
    fast_->setChecked(p.fast);
    if (live_update_) live_update_->setChecked(was);
  }
  applying_preset_ = false;
  matchOptionChanged();
}

// ---------------------------------------------------------------- transfer

void MainWindow::startTransfer() {
  if (computing_) return;
  // a library map reopened: repainted through it, not matched (this run only)
  std::shared_ptr<const veneer::match::Map> given = std::move(given_map_);
  given_map_.reset();
  if (!dst_ || !src_) {
    message(tr("load a destination and a source set first"), true);
    return;
  }
  veneer::pipeline::TransferOptions options;
  auto method = veneer::match::parse_method(method_->currentText().toStdString());
  auto feature = veneer::match::parse_feature(feature_->currentText().toStdString());
  if (!method || !feature) {
    message(qs(!method ? method.message() : feature.message()), true);
    return;
  }
  options.match.method = *method;
  options.match.feature = *feature;
  options.match.patch = patch_->currentText().toInt();
  options.match.candidates = candidates_->value();
  options.match.threshold = threshold_->value();
  options.match.iterations = iterations_->value();
  options.match.coherent_threshold = coherent_threshold_->value();
  options.match.uniformity = uniformity_->value();
  options.match.coherent_smooth = coherent_smooth_->value();
  options.match.coherent_guide = coherent_guide_->value();
  options.match.fast = fast_->isChecked();
  options.truth_normals = truth_normals_->isChecked();
  options.blend = blend_->value();
  options.blend_guide = blend_guide_->value();
  if (auto ok = options.check(); !ok) {
    message(qs(ok.message()), true);
    return;
  }
  veneer::ps::SegmentOptions seg;
  seg.method = seg_method_->currentText() == "otsu"        ? veneer::ps::SegmentMethod::otsu
               : seg_method_->currentText() == "threshold" ? veneer::ps::SegmentMethod::threshold
                                                           : veneer::ps::SegmentMethod::automatic;
  seg.threshold = seg_threshold_->value();
  if (!seg_rect_.isEmpty()) seg.rect = cv::Rect(seg_rect_.x(), seg_rect_.y(), seg_rect_.width(), seg_rect_.height());
  const bool custom_segmentation = seg.method != veneer::ps::SegmentMethod::automatic || seg.rect.has_value();
  const cv::Mat dst_hand = dst_->hand_mask.clone(), src_hand = src_->hand_mask.clone();
  running_ = RunSettings{options, dst_hand, src_hand, given ? reopened_folder_ : QString()};

  computing_ = true;
  cancel_ = false;
  compute_btn_->setEnabled(false);
  cancel_btn_->setEnabled(true);
  transfer_bar_->setValue(0);
  transfer_label_->setText(tr("computing…"));
  step_.start("compute", tr("computing the map (%1)").arg(method_->currentText()));
  step_.update(0);
  showStep();
  transfer_error_.clear();
  relight_error_.clear();
  pending_result_.reset();
  pending_relighter_.reset();
  auto dst = dst_, src = src_;
  // the prepared objects are kept while what made them stays the same
  const QString key = preparationKey();
  auto cached = key == prepared_key_ ? prepared_ : nullptr;
  auto relighter = cached ? relighter_ : nullptr;
  // the same matching options as the map shown (only the blend changed, or
  // Compute again): repainted from that map, not matched again
  std::shared_ptr<const veneer::pipeline::TransferResult> previous =
      !given && cached && result_ && result_->match_options == options.match ? result_ : nullptr;
  if (previous)
    ++repaint_only_runs_;
  else if (cached)
    ++map_only_runs_;
  pending_prepared_.reset();
  pending_key_ = key;
  pending_session_.reset();
  pending_result_picture_ = cv::Mat();
  pending_result_image_ = QImage();
  pending_relit_ = pending_relit_source_ = cv::Mat();
  const cv::Vec3d light = relight_pad_->direction();
  QPointer<MainWindow> self(this);
  transfer_watch_.setFuture(QtConcurrent::run(job_pool(), [this, self, dst, src, options, seg, custom_segmentation, dst_hand, src_hand, cached,
                                               previous, given, relighter, light] {
    veneer::Progress progress;
    progress.cancel = &cancel_;
    progress.on_progress = [self](double f, const std::string& stage) {
      const QString s = qs(stage);
      if (self)
        QMetaObject::invokeMethod(self.data(), [self, f, s] {
          if (!self) return;
          self->transfer_bar_->setValue(static_cast<int>(f * 100));
          self->transfer_label_->setText(s);
          if (self->computing_) {
            self->step_.update(f, tr("computing the map: %1").arg(s));
            self->showStep();
          }
        });
    };
    std::shared_ptr<const veneer::pipeline::PreparedPair> pair = cached;
    if (!pair) {
      veneer::io::ImageSet d = dst->set;
      if (!dst_hand.empty()) {
        d.mask = dst_hand;  // by hand: the supplied mask
      } else if (custom_segmentation) {
        // The user's threshold / rectangle decide the destination's object pixels.
        auto m = veneer::ps::segment(d, seg);
        if (!m) {
          transfer_error_ = tr("segmentation: %1").arg(qs(m.message()));
          return;
        }
        d.mask = m->mask;
      }
      veneer::io::ImageSet s;
      if (!src_hand.empty()) {
        s = src->set;
        s.mask = src_hand;
      }
      auto prepared = veneer::pipeline::prepare_pair(d, src_hand.empty() ? src->set : s, options, progress);
      if (!prepared) {
        transfer_error_ = qs(prepared.message());
        return;
      }
      pair = std::make_shared<const veneer::pipeline::PreparedPair>(std::move(*prepared));
      pending_prepared_ = pair;
    }
    auto result = previous ? veneer::pipeline::transfer(*pair, options, previous->map, progress)
                  : given  ? veneer::pipeline::transfer(*pair, options, *given, progress)
                           : veneer::pipeline::transfer(*pair, options, progress);
    if (!result) {
      transfer_error_ = qs(result.message());
      return;
    }
    pending_result_ = std::make_shared<veneer::pipeline::TransferResult>(std::move(*result));
    // what showing the result needs, made here rather than on the GUI thread
    pending_result_picture_ = picture_of(pending_result_->repainted_median);
    pending_result_image_ = to_qimage(pending_result_picture_);
    {  // the live session: the source's stills (full size) and its object there
      cv::Mat still_mask = pair->src.view.mask;
      if (still_mask.size() != src->set.size)
        cv::resize(pair->src.view.mask, still_mask, src->set.size, 0, 0, cv::INTER_NEAREST);
      pending_session_ = std::make_shared<veneer::repaint::LiveSession>(
          src->set.images, still_mask, pending_result_->map, pending_result_->source_size, dst->median_picture,
          pending_result_->blend);
    }
    if (relighter) {  // same source as last time
      pending_relighter_ = relighter;
    } else {
      auto fitted = veneer::repaint::Relighter::fit(src->set);
      if (fitted) {
        pending_relighter_ = std::make_shared<veneer::repaint::Relighter>(std::move(*fitted));
      } else {
        relight_error_ = qs(fitted.message());
      }
    }
    if (pending_relighter_) {
      pending_relit_ = picture_of(pending_relighter_->render(pending_result_->map, light, dst->median * 0.25));
      pending_relit_source_ = picture_of(pending_relighter_->render_source(light));
      pending_relit_direction_ = light;
    }
  }));
}

void MainWindow::cancelTransfer() {
  if (!computing_) return;
  cancel_ = true;
  transfer_label_->setText(tr("cancelling…"));
}

// What the prepared objects depend on: the sets loaded, truth normals, the
// segmentation settings. Anything else is a matching option.
QString MainWindow::preparationKey() const {
  return QString("%1|%2|%3|%4|%5,%6,%7,%8|%9,%10")
      .arg(sets_loaded_)  // a set (re)loaded: everything is prepared again
      .arg(truth_normals_->isChecked())
      .arg(seg_method_->currentText())
      .arg(seg_threshold_->value())
      .arg(seg_rect_.x())
      .arg(seg_rect_.y())
      .arg(seg_rect_.width())
      .arg(seg_rect_.height())
      .arg(dst_ ? dst_->hand_version : 0)
      .arg(src_ ? src_->hand_version : 0);
}

// An option changed: once a transfer has been shown, recompute (the map alone
// when only matching options changed, the objects kept); while one runs,
// once more when it ends.
void MainWindow::matchOptionChanged() {
  if (!live_update_ || !live_update_->isChecked() || !result_) return;
  if (computing_) {
    rerun_ = true;
    return;
  }
  startTransfer();
}

void MainWindow::onTransferDone() {
  computing_ = false;
  step_.finish();
  compute_btn_->setEnabled(true);
  cancel_btn_->setEnabled(false);
  if (pending_prepared_) {
    prepared_ = pending_prepared_;
    prepared_key_ = pending_key_;
    pending_prepared_.reset();
  }
  if (rerun_) {  // the options moved on while this ran: show the latest
    rerun_ = false;
    if (pending_result_) {
      result_ = pending_result_;
      shown_ = running_;
      relighter_ = pending_relighter_;
      result_picture_ = pending_result_picture_;
      result_image_ = pending_result_image_;
    }
    startTransfer();
    return;
  }
  if (!pending_result_) {
    const bool cancelled = cancel_.load();
    transfer_label_->setText(cancelled ? tr("cancelled") : tr("failed: %1").arg(transfer_error_));
    message(cancelled ? tr("transfer cancelled") : tr("transfer failed: %1").arg(transfer_error_), !cancelled);
    transfer_bar_->setValue(0);
    step_label_->setText(transfer_label_->text());
    showStep();
    return;
  }
  result_ = pending_result_;
  shown_ = running_;
  relighter_ = pending_relighter_;
  transfer_bar_->setValue(100);
  QString text = tr("done");
  if (result_->quality) {
    const auto& q = *result_->quality;
    text += tr(" · coverage %1% · coherence %2%").arg(q.coverage * 100, 0, 'f', 1).arg(q.coherence * 100, 0, 'f', 1);
    if (q.normal_mean_deg) text += tr(" · normals %1°").arg(*q.normal_mean_deg, 0, 'f', 2);
  }
  if (result_->map_given)
    text += tr(" · map kept");
  else
    text += tr(" · map %1 ms").arg(result_->match_seconds * 1000, 0, 'f', 1);
  transfer_label_->setText(text);
  if (!shown_.reopened.isEmpty())
    message(tr("map reopened from the library, not matched again: %1").arg(shown_.reopened));
  else
    message(tr("transfer done (%1)").arg(method_->currentText()));
  showStep();
  step_label_->setText((shown_.reopened.isEmpty() ? tr("map computed: ") : tr("map reopened from the library: ")) +
                       text);
  result_picture_ = pending_result_picture_;
  result_image_ = pending_result_image_;
  if (pending_session_) {
    live_session_ = std::move(pending_session_);
    live_refusal_.clear();
  }
  pending_session_.reset();
  if (look_what_->currentIndex() != 0)
    look_what_->setCurrentIndex(0);  // refreshes the views
  else
    refreshLook();
  if (relighter_ && !pending_relit_.empty() && pending_relit_direction_ == relight_pad_->direction()) {
    // the worker rendered it for this direction
    relight_view_->setImage(to_qimage(pending_relit_));
    relight_src_view_->setImage(to_qimage(pending_relit_source_));
    updateRelightLabel(pending_relit_direction_);
  } else {
    refreshRelight();
  }
  if (!result_->map_given) saveMapToLibrary();
  flowMaybeGoLive();
  flowMaybeFullResolution();  // live on a live-size map: the full resolution behind it
}

}  // namespace veneer::app
