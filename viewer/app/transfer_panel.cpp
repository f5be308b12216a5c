// The Transfer panel: the compute settings and the transfer run off the GUI thread.
#include "transfer_panel.hpp"

#include <QCheckBox>
#include <QComboBox>
#include <QDoubleSpinBox>
#include <QFormLayout>
#include <QHBoxLayout>
#include <QLabel>
#include <QPointer>
#include <QProgressBar>
#include <QPushButton>
#include <QSignalBlocker>
#include <QSpinBox>
#include <QToolButton>
#include <QVBoxLayout>
#include <QtConcurrent/QtConcurrentRun>

#include <opencv2/imgproc.hpp>

#include "veneer/pipeline/live.hpp"
#include "veneer/pipeline/prepare.hpp"
#include "veneer/ps/segmentation.hpp"
#include "live_tab.hpp"
#include "widgets.hpp"

namespace veneer::app {

namespace {
const char* kMethods[] = {"combined", "coherent", "linear", "flann", "candidates", "patchmatch", "regiongrow", "baseline"};
}  // namespace

TransferPanel::TransferPanel(Session& session, QWidget* parent) : QGroupBox(tr("Transfer"), parent), session_(session) {
  auto* outer = new QVBoxLayout(this);
  auto* top = new QFormLayout;
  outer->addLayout(top);
  preset_ = named<QComboBox>("preset");
  for (const auto& p : presets(look_)) preset_->addItem(p.name);
  preset_->addItem(tr("custom"));
  preset_->setToolTip(tr("settings for common needs; changing a setting under Advanced makes it \"custom\""));
  top->addRow(tr("Preset"), preset_);
  // Every expert parameter lives in a fold, closed at first.
  auto* fold = named<QToolButton>("advancedToggle");
  fold->setText(tr("Advanced"));
  fold->setCheckable(true);
  fold->setToolButtonStyle(Qt::ToolButtonTextBesideIcon);
  fold->setArrowType(Qt::RightArrow);
  fold->setAutoRaise(true);
  outer->addWidget(fold);
  auto* advanced = named<QWidget>("advanced");
  advanced->setVisible(false);
  outer->addWidget(advanced);
  connect(fold, &QToolButton::toggled, this, [fold, advanced](bool open) {
    fold->setArrowType(open ? Qt::DownArrow : Qt::RightArrow);
    advanced->setVisible(open);
  });
  auto* form = new QFormLayout(advanced);
  form->setContentsMargins(12, 0, 0, 0);
  method_ = named<QComboBox>("method");
  for (const char* m : kMethods) method_->addItem(m);
  feature_ = named<QComboBox>("feature");
  feature_->addItems({"normals", "intensities"});
  patch_ = named<QComboBox>("patch");
  patch_->addItems({"1", "3", "5", "7"});
  // every matching box starts at the default transfer's (the CLI's)
  const veneer::pipeline::TransferOptions transfer_defaults = veneer::pipeline::default_transfer_options(look_);
  const veneer::match::MatchOptions defaults = transfer_defaults.match;
  candidates_ = named<QSpinBox>("candidates");
  candidates_->setRange(1, 100);
  candidates_->setValue(defaults.candidates);
  threshold_ = number_box("threshold", 0, 2, 3, 0.01, defaults.threshold);
  iterations_ = named<QSpinBox>("iterations");
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
  blend_ = named<QSpinBox>("blend");
  blend_->setRange(0, 16);
  blend_->setSuffix(tr(" px"));
  blend_->setValue(transfer_defaults.blend);
  blend_->setToolTip(tr("the copy look (the stills' and the live view's): blend the chunks meeting at a seam "
                        "over this radius (0 = off: each pixel its own source pixel); the shaded look does not "
                        "blend"));
  blend_guide_ = number_box("blendGuide", 0, 2, 2, 0.05, transfer_defaults.blend_guide,
                            tr("result pictures, maps matched on normals: blend only chunks whose normals fit "
                               "(fall-off |dn|, 0.1 = about 6°), so outlines such as a leg in front of the body "
                               "stay sharp (0 = plain blend)"));
  uniformity_ = number_box("uniformity", 0, 10, 2, 0.1, defaults.uniformity);
  fast_ = check_box("fast", tr("fast engine"), true);
  truth_normals_ = check_box("truthNormals", tr("truth normals (simulated sets)"), false);
  seg_method_ = named<QComboBox>("segMethod");
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
  live_update_ = check_box("liveUpdate", tr("recompute as options change"), true,
                           tr("after a first Compute, changing a matching option recomputes the map alone "
                              "(normals and masks are kept)"));
  top->addRow(live_update_);
  form->addRow(tr("Segmentation"), seg_method_);
  form->addRow(tr("Seg. threshold"), seg_threshold_);
  form->addRow(rect_label_);
  compute_btn_ = button(tr("Compute"), "compute", this);
  cancel_btn_ = button(tr("Cancel"), "cancelTransfer", this);
  cancel_btn_->setEnabled(false);
  connect(compute_btn_, &QPushButton::clicked, this, &TransferPanel::startTransfer);
  connect(cancel_btn_, &QPushButton::clicked, this, &TransferPanel::cancelTransfer);
  for (QComboBox* c : {method_, feature_, patch_})
    connect(c, &QComboBox::currentIndexChanged, this, &TransferPanel::matchOptionChanged);
  for (QSpinBox* b : {candidates_, iterations_, blend_})
    connect(b, &QSpinBox::valueChanged, this, &TransferPanel::matchOptionChanged);
  for (QDoubleSpinBox* b : {threshold_, coherent_threshold_, coherent_smooth_, coherent_guide_, uniformity_, blend_guide_})
    connect(b, &QDoubleSpinBox::valueChanged, this, &TransferPanel::matchOptionChanged);
  connect(fast_, &QCheckBox::toggled, this, &TransferPanel::matchOptionChanged);
  // segmentation and truth normals change the prepared objects: prepared again, then the map
  connect(truth_normals_, &QCheckBox::toggled, this, &TransferPanel::matchOptionChanged);
  connect(seg_method_, &QComboBox::currentIndexChanged, this, &TransferPanel::matchOptionChanged);
  connect(seg_threshold_, &QDoubleSpinBox::valueChanged, this, &TransferPanel::matchOptionChanged);
  connect(preset_, &QComboBox::currentIndexChanged, this, [this](int i) {
    if (i >= 0 && i < static_cast<int>(presets(look_).size())) applyPreset(presets(look_)[i]);
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
  applyPreset(presets(look_).front());
  auto* bottom = new QFormLayout;
  outer->addLayout(bottom);
  auto* row = new QHBoxLayout;
  row->addWidget(compute_btn_);
  row->addWidget(cancel_btn_);
  bottom->addRow(row);
  transfer_bar_ = named<QProgressBar>("transferProgress");
  transfer_label_ = named<QLabel>("transferStatus");
  transfer_label_->setWordWrap(true);
  bottom->addRow(transfer_bar_);
  bottom->addRow(transfer_label_);
  connect(&transfer_watch_, &QFutureWatcher<void>::finished, this, &TransferPanel::onTransferDone);
}

TransferPanel::~TransferPanel() {
  cancel_ = true;
  transfer_watch_.waitForFinished();
}


// The presets for a look: the CLI's defaults first (what the flow computes with).
std::vector<TransferPanel::Preset> TransferPanel::presets(veneer::repaint::Look look) {
  return [look] {
    const veneer::pipeline::TransferOptions t = veneer::pipeline::default_transfer_options(look);
    const veneer::match::MatchOptions m = t.match;
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
}

void TransferPanel::setLook(veneer::repaint::Look look) {
  if (look == look_) return;
  look_ = look;
  const int i = preset_->currentIndex();
  if (i >= 0 && i < static_cast<int>(presets(look_).size()))
    applyPreset(presets(look_)[i]);  // the look's matching (coherent threshold), and a recomputation
  else
    matchOptionChanged();  // custom: the user's matching, painted the other way
}

void TransferPanel::applyPreset(const Preset& p) {
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

void TransferPanel::startTransfer() {
  if (computing_) return;
  // a library map reopened: repainted through it, not matched (this run only)
  std::shared_ptr<const veneer::match::Map> given = std::move(given_map_);
  given_map_.reset();
  if (!session_.dst || !session_.src) {
    session_.message(tr("load a destination and a source set first"), true);
    return;
  }
  // the CLI's default transfer for the look, then what the boxes say
  veneer::pipeline::TransferOptions options = veneer::pipeline::default_transfer_options(look_);
  auto method = veneer::match::parse_method(method_->currentText().toStdString());
  auto feature = veneer::match::parse_feature(feature_->currentText().toStdString());
  if (!method || !feature) {
    session_.message(qs(!method ? method.message() : feature.message()), true);
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
    session_.message(qs(ok.message()), true);
    return;
  }
  veneer::ps::SegmentOptions seg;
  seg.method = seg_method_->currentText() == "otsu"        ? veneer::ps::SegmentMethod::otsu
               : seg_method_->currentText() == "threshold" ? veneer::ps::SegmentMethod::threshold
                                                           : veneer::ps::SegmentMethod::automatic;
  seg.threshold = seg_threshold_->value();
  if (!seg_rect_.isEmpty()) seg.rect = cv::Rect(seg_rect_.x(), seg_rect_.y(), seg_rect_.width(), seg_rect_.height());
  const bool custom_segmentation = seg.method != veneer::ps::SegmentMethod::automatic || seg.rect.has_value();
  const cv::Mat dst_hand = session_.dst->hand_mask.clone(), src_hand = session_.src->hand_mask.clone();
  running_ = RunSettings{options, dst_hand, src_hand, given ? reopened_folder_ : QString()};

  computing_ = true;
  cancel_ = false;
  compute_btn_->setEnabled(false);
  cancel_btn_->setEnabled(true);
  transfer_bar_->setValue(0);
  transfer_label_->setText(tr("computing…"));
  session_.status.step().start("compute", tr("computing the map (%1)").arg(method_->currentText()));
  session_.status.step().update(0);
  session_.status.showStep();
  transfer_error_.clear();
  session_.relight_error.clear();
  pending_relight_error_.clear();
  pending_result_.reset();
  pending_relighter_.reset();
  auto dst = session_.dst, src = session_.src;
  // the prepared objects are kept while what made them stays the same
  const QString key = preparationKey();
  auto cached = key == prepared_key_ ? prepared_ : nullptr;
  auto relighter = cached ? session_.relighter : nullptr;
  // the same matching options as the map shown (only the blend changed, or
  // Compute again): repainted from that map, not matched again
  std::shared_ptr<const veneer::pipeline::TransferResult> previous =
      !given && cached && session_.result && session_.result->match_options == options.match ? session_.result : nullptr;
  if (previous)
    ++repaint_only_runs_;
  else if (cached)
    ++map_only_runs_;
  pending_prepared_.reset();
  pending_key_ = key;
  pending_session_.reset();
  pending_live_note_.clear();
  pending_result_picture_ = cv::Mat();
  pending_result_image_ = QImage();
  pending_relit_ = pending_relit_source_ = cv::Mat();
  const cv::Vec3d light = session_.light();
  QPointer<TransferPanel> self(this);
  transfer_watch_.setFuture(QtConcurrent::run(job_pool(), [this, self, dst, src, options, seg, custom_segmentation,
                                                           dst_hand, src_hand, cached,
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
            self->session_.status.step().update(f, tr("computing the map: %1").arg(s));
            self->session_.status.showStep();
          }
        });
    };
    std::shared_ptr<const veneer::pipeline::PreparedPair> pair = cached;
    if (!pair) {
      // Prepared from the sets' folders as `veneer transfer` prepares them
      // (pipeline::default_prepare_options; live-size sets as `veneer transfer
      // --live`), so the viewer and the CLI give one answer (issue 40).
      veneer::pipeline::PrepareOptions prep = veneer::pipeline::default_prepare_options();
      prep.destination_mask = dst_hand;  // by hand: the supplied mask (as --dst-mask)
      prep.source_mask = src_hand;
      if (dst_hand.empty() && custom_segmentation) {
        // The user's threshold / rectangle decide the destination's object pixels.
        auto m = veneer::ps::segment(dst->set, seg);
        if (!m) {
          transfer_error_ = tr("segmentation: %1").arg(qs(m.message()));
          return;
        }
        prep.destination_mask = m->mask;
      }
      veneer::Expected<veneer::pipeline::PreparedPair> prepared = veneer::make_error("not prepared");
      if (dst->live_size || src->live_size) {
        veneer::pipeline::LiveOptions live;
        live.read.width = std::max(dst->live_width, src->live_width);
        live.destination_mask = prep.destination_mask;
        live.source_mask = prep.source_mask;
        // both read at this width by the flow (read_set_reduced, as prepare_live_pair reads): not read again
        if (dst->live_size && src->live_size && dst->live_width == src->live_width)
          prepared = veneer::pipeline::prepare_live_pair(dst->set, src->set, options, live, nullptr, progress);
        else
          prepared = veneer::pipeline::prepare_live_pair(dst->folder.toStdString(), src->folder.toStdString(),
                                                         options, live, nullptr, progress);
      } else {
        prepared = veneer::pipeline::prepare_pair(dst->folder.toStdString(), src->folder.toStdString(), options,
                                                  prep, nullptr, progress);
        (void)veneer::pipeline::finish_cache_writes();  // not fatal: the next run prepares again
      }
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
    {  // the live session: the source's stills (full size), its object there, the live look of the map
      veneer::Progress cancel_only;
      cancel_only.cancel = &cancel_;
      pending_session_ = make_live_session(*pair, options, *pending_result_, src->set.images, pair->src.view.mask,
                                           dst->median_picture, &pending_live_note_, cancel_only);
      if (cancel_) {
        transfer_error_ = "cancelled";
        pending_result_.reset();
        pending_session_.reset();
        return;
      }
    }
    if (relighter) {  // same source as last time
      pending_relighter_ = relighter;
    } else {
      auto fitted = veneer::repaint::Relighter::fit(src->set);
      if (fitted) {
        pending_relighter_ = std::make_shared<veneer::repaint::Relighter>(std::move(*fitted));
      } else {
        pending_relight_error_ = qs(fitted.message());
      }
    }
    if (pending_relighter_) {
      pending_relit_ = picture_of(pending_relighter_->render(pending_result_->map, light, dst->median * 0.25));
      pending_relit_source_ = picture_of(pending_relighter_->render_source(light));
      pending_relit_direction_ = light;
    }
  }));
}

void TransferPanel::cancelTransfer() {
  if (!computing_) return;
  cancel_ = true;
  transfer_label_->setText(tr("cancelling…"));
}

// What the prepared objects depend on: the sets loaded, truth normals, the
// segmentation settings. Anything else is a matching option.
QString TransferPanel::preparationKey() const {
  return QString("%1|%2|%3|%4|%5,%6,%7,%8|%9,%10")
      .arg(session_.sets_loaded)  // a set (re)loaded: everything is prepared again
      .arg(truth_normals_->isChecked())
      .arg(seg_method_->currentText())
      .arg(seg_threshold_->value())
      .arg(seg_rect_.x())
      .arg(seg_rect_.y())
      .arg(seg_rect_.width())
      .arg(seg_rect_.height())
      .arg(session_.dst ? session_.dst->hand_version : 0)
      .arg(session_.src ? session_.src->hand_version : 0);
}

// An option changed: once a transfer has been shown, recompute (the map alone
// when only matching options changed, the objects kept); while one runs,
// once more when it ends.
void TransferPanel::matchOptionChanged() {
  if (!live_update_ || !live_update_->isChecked() || !session_.result) return;
  runOrRerun();
}

void TransferPanel::runOrRerun() {
  if (computing_) {
    rerun_ = true;
    return;
  }
  startTransfer();
}

void TransferPanel::handMaskChanged(const QString& hand) {
  rect_label_->setText(hand);
  matchOptionChanged();  // a new object outline: prepared again and matched
}

void TransferPanel::showOptions(const veneer::pipeline::TransferOptions& o) {
  Preset p{tr("as reopened"),
           qs(veneer::match::method_name(o.match.method)),
           qs(veneer::match::feature_name(o.match.feature)),
           o.match.patch,
           o.match.candidates,
           o.match.threshold,
           o.match.iterations,
           o.match.coherent_threshold,
           o.match.coherent_smooth,
           o.match.coherent_guide,
           o.match.uniformity,
           o.blend,
           o.blend_guide,
           o.match.fast};
  if (o.look != look_) {
    look_ = o.look;
    emit lookShown(look_);
  }
  applyPreset(p);
  truth_normals_->setChecked(o.truth_normals);
}

void TransferPanel::repaintThrough(std::shared_ptr<const veneer::match::Map> map, const QString& library_folder) {
  given_map_ = std::move(map);
  reopened_folder_ = library_folder;
}

void TransferPanel::adoptPrepared(std::shared_ptr<const veneer::pipeline::PreparedPair> pair) {
  prepared_ = std::move(pair);
  prepared_key_ = preparationKey();
}

void TransferPanel::onTransferDone() {
  computing_ = false;
  emit transferEnded();
  session_.status.step().finish();
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
      session_.result = pending_result_;
      session_.shown = running_;
      session_.relighter = pending_relighter_;
      session_.relight_error = pending_relight_error_;
      session_.result_picture = pending_result_picture_;
      session_.result_image = pending_result_image_;
    }
    startTransfer();
    return;
  }
  if (!pending_result_) {
    const bool cancelled = cancel_.load();
    transfer_label_->setText(cancelled ? tr("cancelled") : tr("failed: %1").arg(transfer_error_));
    session_.message(cancelled ? tr("transfer cancelled") : tr("transfer failed: %1").arg(transfer_error_), !cancelled);
    transfer_bar_->setValue(0);
    session_.status.say(transfer_label_->text());
    session_.status.showStep();
    return;
  }
  session_.result = pending_result_;
  session_.shown = running_;
  session_.relighter = pending_relighter_;
  session_.relight_error = pending_relight_error_;
  transfer_bar_->setValue(100);
  QString text = tr("done");
  if (session_.result->quality) {
    const auto& q = *session_.result->quality;
    text += tr(" · coverage %1% · coherence %2%").arg(q.coverage * 100, 0, 'f', 1).arg(q.coherence * 100, 0, 'f', 1);
    if (q.normal_mean_deg) text += tr(" · normals %1°").arg(*q.normal_mean_deg, 0, 'f', 2);
  }
  if (session_.result->map_given)
    text += tr(" · map kept");
  else
    text += tr(" · map %1 ms").arg(session_.result->match_seconds * 1000, 0, 'f', 1);
  transfer_label_->setText(text);
  if (!session_.shown.reopened.isEmpty())
    session_.message(tr("map reopened from the library, not matched again: %1").arg(session_.shown.reopened));
  else
    session_.message(tr("transfer done (%1)").arg(method_->currentText()));
  session_.status.showStep();
  const bool reopened = !session_.shown.reopened.isEmpty();
  session_.status.say((reopened ? tr("map reopened from the library: ") : tr("map computed: ")) + text);
  session_.result_picture = pending_result_picture_;
  session_.result_image = pending_result_image_;
  if (pending_session_) {
    session_.live_session = std::move(pending_session_);
    session_.live_refusal.clear();
    if (!pending_live_note_.isEmpty()) session_.message(pending_live_note_, true);
  }
  pending_session_.reset();
  // the views, the library, the live repaint and the full resolution follow
  emit resultShown(to_qimage(pending_relit_), to_qimage(pending_relit_source_), pending_relit_direction_);
}

}  // namespace veneer::app
