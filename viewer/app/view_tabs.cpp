// The Look, Live and Relight tabs and what they show.
#include "main_window.hpp"
#include "widgets.hpp"

#include <algorithm>
#include <cmath>

#include <QApplication>
#include <QCheckBox>
#include <QComboBox>
#include <QDir>
#include <QPainter>
#include <QPointer>
#include <QSaveFile>
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
#include "veneer/repaint/specular.hpp"

namespace veneer::app {

QWidget* MainWindow::buildLookTab() {
  auto* w = new QWidget;
  auto* layout = new QVBoxLayout(w);
  auto* top = new QHBoxLayout;
  look_what_ = new QComboBox;
  look_what_->setObjectName("lookWhat");
  look_what_->addItems({tr("median of all lamps"), tr("normals"), tr("albedo"), tr("mask"),
                        tr("correspondence map"), tr("source reuse"), tr("confidence"),
                        tr("specular enhancement")});
  look_what_->setToolTip(tr("confidence: the photometric-stereo fit per set (bright = the lamps agree) and the "
                            "map's match distance on the result (bright = close match); specular enhancement: "
                            "the normals shaded shiny under the Relight tab's light"));
  connect(look_what_, &QComboBox::currentIndexChanged, this, [this] { refreshLook(); });
  top->addWidget(new QLabel(tr("Show")));
  top->addWidget(look_what_);
  auto* reset = button(tr("Fit"), "fitViews", w);
  connect(reset, &QPushButton::clicked, this, [this] { sync_.reset(); });
  top->addWidget(reset);
  auto* snap = button(tr("Snapshot…"), "snapshot", w);
  snap->setToolTip(tr("save the view shown (this tab, as on screen) as a PNG"));
  connect(snap, &QPushButton::clicked, this, [this] {
    const QString f = QFileDialog::getSaveFileName(this, tr("Snapshot"), "snapshot.png", "PNG (*.png)");
    if (!f.isEmpty()) snapshotTo(f);
  });
  top->addWidget(snap);
  top->addStretch();
  histogram_ = new QLabel;
  histogram_->setObjectName("histogram");
  top->addWidget(histogram_);
  exposure_label_ = new QLabel;
  exposure_label_->setObjectName("exposure");
  top->addWidget(exposure_label_);
  layout->addLayout(top);
  auto* row = new QHBoxLayout;
  dst_view_ = new ImageView(tr("destination"));
  src_view_ = new ImageView(tr("source"));
  result_view_ = new ImageView(tr("result"));
  for (auto* v : {dst_view_, src_view_, result_view_}) {
    v->setSync(&sync_);
    row->addWidget(v);
  }
  layout->addLayout(row, 3);
  origin_view_ = new ImageView(tr("origin: click a destination or result pixel"));
  layout->addWidget(origin_view_, 2);
  connect(dst_view_, &ImageView::pixelClicked, this, &MainWindow::showOrigin);
  connect(result_view_, &ImageView::pixelClicked, this, &MainWindow::showOrigin);
  connect(dst_view_, &ImageView::rectDrawn, this, [this](QRect r) {
    dst_view_->setRect({});
    setHandRect(veneer::io::Role::destination, r);
  });
  connect(src_view_, &ImageView::rectDrawn, this, [this](QRect r) {
    src_view_->setRect({});
    setHandRect(veneer::io::Role::source, r);
  });
  connect(dst_view_, &ImageView::brushed, this,
          [this](QPoint p, bool add) { brushHandMask(veneer::io::Role::destination, p, add); });
  connect(src_view_, &ImageView::brushed, this,
          [this](QPoint p, bool add) { brushHandMask(veneer::io::Role::source, p, add); });
  return w;
}

QWidget* MainWindow::buildLiveTab() {
  auto* w = new QWidget;
  auto* layout = new QVBoxLayout(w);
  auto* top = new QHBoxLayout;
  live_btn_ = button(tr("Start live view"), "liveToggle", w);
  live_btn_->setCheckable(true);
  fps_ = new QDoubleSpinBox;
  fps_->setObjectName("liveFps");
  fps_->setRange(1, 60);
  fps_->setValue(15);
  connect(live_btn_, &QPushButton::toggled, this, [this](bool on) {
    live_btn_->setText(on ? tr("Stop live view") : tr("Start live view"));
    if (on) {
      live_clock_.start();
      live_frames_ = 0;
      rig_.startLive(fps_->value());
    } else {
      rig_.stopLive();
    }
  });
  top->addWidget(live_btn_);
  auto* live_cap_src = button(tr("Capture source"), "liveCaptureSource", w);
  auto* live_cap_dst = button(tr("Capture destination"), "liveCaptureDestination", w);
  connect(live_cap_src, &QPushButton::clicked, this, [this] { capture_(veneer::io::Role::source); });
  connect(live_cap_dst, &QPushButton::clicked, this, [this] { capture_(veneer::io::Role::destination); });
  top->addWidget(live_cap_src);
  top->addWidget(live_cap_dst);
  top->addWidget(new QLabel(tr("fps")));
  top->addWidget(fps_);
  top->addWidget(new QLabel(tr("Lamps:")));
  lamp_row_ = new QHBoxLayout;
  top->addLayout(lamp_row_);
  top->addStretch();
  live_label_ = new QLabel;
  live_label_->setObjectName("liveStatus");
  top->addWidget(live_label_);
  layout->addLayout(top);
  auto* row = new QHBoxLayout;
  live_src_view_ = new ImageView(tr("source, live"));
  live_dst_view_ = new ImageView(tr("destination, repainted live"));
  row->addWidget(live_src_view_, 3);
  row->addWidget(live_dst_view_, 3);
  auto* pad_box = new QVBoxLayout;
  pad_box->addWidget(new QLabel(tr("hand-held lamp\n(simulated rig)")));
  hand_pad_ = new SpherePad;
  hand_pad_->setObjectName("handLamp");
  connect(hand_pad_, &SpherePad::directionChanged, this, [this](cv::Vec3d d) {
    // The lamp 0.6 m from the object in the chosen direction.
    rig_.moveHandLamp(d * 0.6);
  });
  pad_box->addWidget(hand_pad_);
  pad_box->addStretch();
  row->addLayout(pad_box, 1);
  layout->addLayout(row, 1);
  return w;
}

QWidget* MainWindow::buildRelightTab() {
  auto* w = new QWidget;
  auto* layout = new QHBoxLayout(w);
  auto* left = new QVBoxLayout;
  left->addWidget(new QLabel(tr("Drag the light over the sphere")));
  relight_pad_ = new SpherePad;
  relight_pad_->setObjectName("relightPad");
  relight_pad_->setDirection(cv::Vec3d(-0.4, 0.4, std::sqrt(1 - 0.32)));
  connect(relight_pad_, &SpherePad::directionChanged, this, [this] {
    refreshRelight();
    if (look_what_->currentIndex() == 7) refreshLook();  // specular enhancement follows the light
  });
  left->addWidget(relight_pad_);
  relight_label_ = new QLabel;
  relight_label_->setWordWrap(true);
  left->addWidget(relight_label_);
  left->addStretch();
  layout->addLayout(left, 1);
  relight_src_view_ = new ImageView(tr("source under the virtual light"));
  relight_view_ = new ImageView(tr("destination relit in the source's material"));
  layout->addWidget(relight_src_view_, 3);
  layout->addWidget(relight_view_, 3);
  return w;
}


// ---------------------------------------------------------------- views

void MainWindow::refreshLook() {
  gui_work([this] { refreshLookNow(); });
}

namespace {
// 0..1 (1 = best) shown with a colour scale; black outside `valid`.
cv::Mat confidence_picture(const cv::Mat& goodness, const cv::Mat& valid) {
  cv::Mat g8, out;
  goodness.convertTo(g8, CV_8U, 255.0);
  cv::applyColorMap(g8, out, cv::COLORMAP_VIRIDIS);
  if (!valid.empty()) out.setTo(cv::Scalar::all(0), valid == 0);
  return out;
}

}  // namespace

void MainWindow::refreshLookNow() {
  const int what = look_what_->currentIndex();
  const cv::Vec3d light = relight_pad_ ? relight_pad_->direction() : cv::Vec3d(0, 0, 1);
  // the median, the view shown most, comes ready from the loader (a 10 Mpx
  // set's conversion is not done on the GUI thread); the other views are made here
  auto pick_image = [what, light](const std::shared_ptr<LoadedSet>& s) -> QImage {
    if (!s) return {};
    if (what == 0 && !s->median_image.isNull()) return s->median_image;
    cv::Mat picture;
    switch (what) {
      case 1: picture = s->normals ? io::normals_picture(s->normals->normals) : cv::Mat(); break;
      case 2: picture = s->normals ? picture_of(s->normals->albedo) : cv::Mat(); break;
      case 3: picture = s->normals ? s->normals->mask : cv::Mat(); break;
      case 6:
        if (s->normals && !s->normals->residual.empty()) {
          cv::Mat good = 1.0 - cv::min(s->normals->residual * 10.0, 1.0);  // residual 0.1 of the brightest: none
          picture = confidence_picture(good, s->normals->mask);
        }
        break;
      case 7:  // specular enhancement (core), following the relight pad's light
        if (s->normals) {
          auto shaded = veneer::repaint::specular_enhancement(s->normals->normals, light);
          if (shaded) picture = *shaded;
        }
        break;
      default: picture = s->median_picture.empty() ? picture_of(s->median) : s->median_picture;
    }
    return to_qimage(picture);
  };
  updateHistogram();
  dst_view_->setImage(pick_image(dst_));
  src_view_->setImage(pick_image(src_));
  if (result_) {
    cv::Mat r;
    if (what == 4) {
      r = veneer::repaint::map_picture(result_->map, result_->source_size);
    } else if (what == 6) {
      const cv::Mat& d = result_->map.distance;
      cv::Mat xy[2];
      cv::split(result_->map.xy, xy);
      cv::Mat valid = xy[0] >= 0, good;  // unmapped pixels: black
      double hi = 0;
      cv::minMaxLoc(d, nullptr, &hi, nullptr, nullptr, valid);
      good = 1.0 - d / std::max(1e-6, hi);
      r = confidence_picture(good, valid);
    } else if (what == 5) {
      r = veneer::repaint::reuse_picture(result_->reuse, result_->source_median);
      src_view_->setImage(to_qimage(r));
      r = result_picture_.empty() ? picture_of(result_->repainted_median) : result_picture_;
    } else if (!result_image_.isNull()) {
      result_view_->setImage(result_image_);  // made by the transfer's worker
      return;
    } else {
      r = result_picture_.empty() ? picture_of(result_->repainted_median) : result_picture_;
    }
    result_view_->setImage(to_qimage(r));
  } else {
    result_view_->setImage({});
  }
}

// The destination's luminance histogram (of the picture shown on the Look
// tab's median) with the exposure its manifest records.
cv::Mat luminance_histogram(const cv::Mat& bgr8) {
  if (bgr8.empty()) return {};
  cv::Mat grey, hist;
  cv::cvtColor(bgr8, grey, cv::COLOR_BGR2GRAY);
  const int bins = 64, channels[] = {0}, size[] = {bins};
  const float range[] = {0, 256};
  const float* ranges[] = {range};
  cv::calcHist(&grey, 1, channels, cv::Mat(), hist, 1, size, ranges);
  return hist;
}

void MainWindow::updateHistogram() {
  const LoadedSet* s = dst_ ? dst_.get() : src_.get();
  if (!s || s->median_picture.empty()) {
    histogram_->clear();
    return;
  }
  const cv::Mat hist = s->histogram.empty() ? luminance_histogram(s->median_picture) : s->histogram;
  const int bins = hist.rows;
  double peak = 0;
  cv::minMaxLoc(hist, nullptr, &peak);
  QPixmap pixmap(bins * 2, 36);
  pixmap.fill(QColor(24, 24, 28));
  QPainter p(&pixmap);
  p.setPen(QColor(220, 220, 220));
  for (int i = 0; i < bins; ++i) {
    const int h = static_cast<int>(std::round(35 * std::sqrt(hist.at<float>(i) / std::max(1.0, peak))));
    p.fillRect(i * 2, 36 - h, 2, h, QColor(200, 200, 200));
  }
  p.end();
  const auto& c = s->set.camera;
  QString exposure = c.exposure_s <= 0 ? tr("exposure not recorded")
                     : c.exposure_s < 1 ? tr("1/%1 s").arg(std::round(1 / c.exposure_s))
                                        : tr("%1 s").arg(c.exposure_s, 0, 'g', 3);
  if (c.aperture > 0) exposure += tr(" · f/%1").arg(c.aperture, 0, 'g', 3);
  if (c.iso > 0) exposure += tr(" · ISO %1").arg(c.iso);
  histogram_->setPixmap(pixmap);
  histogram_->setToolTip(tr("%1: median picture's luminance (square-root scale)\n%2 (%3)")
                             .arg(QFileInfo(s->folder).fileName(), exposure, qs(c.model)));
  exposure_text_ = exposure;
  if (exposure_label_) exposure_label_->setText(exposure);
}

bool MainWindow::showLook(const QString& what) {
  const int i = look_what_->findText(what);
  if (i < 0) return false;
  showTab("Look");
  look_what_->setCurrentIndex(i);
  refreshLook();
  return true;
}

QString MainWindow::snapshotTo(const QString& file) {
  QWidget* view = tabs_->currentWidget();
  if (!view) return {};
  if (!file.endsWith(".png", Qt::CaseInsensitive)) {
    message(tr("a snapshot is a PNG: %1 does not end in .png").arg(file), true);
    return {};
  }
  QSaveFile out(file);  // whole or not at all
  if (!out.open(QIODevice::WriteOnly) || !view->grab().save(&out, "PNG") || !out.commit()) {
    message(tr("cannot write the snapshot %1: %2").arg(file, out.errorString()), true);
    return {};
  }
  message(tr("snapshot saved as %1").arg(file));
  return file;
}

void MainWindow::showOrigin(QPoint p) {
  if (!result_ || !dst_ || !src_) {
    message(tr("compute a transfer first; then a click shows where a pixel's look comes from"), true);
    return;
  }
  const auto& map = result_->map;
  if (p.x() >= map.xy.cols || p.y() >= map.xy.rows) return;
  const cv::Vec2f m = map.xy.at<cv::Vec2f>(p.y(), p.x());
  std::vector<ImageView::Marker> dst_markers{{QPointF(p), QColor(0, 220, 255), m[0] < 0}};
  dst_view_->setMarkers(dst_markers);
  result_view_->setMarkers(dst_markers);
  if (m[0] >= 0) {
    src_view_->setMarkers({{QPointF(m[0], m[1]), QColor(0, 220, 255), false}});
    message(tr("destination (%1, %2) ← source (%3, %4), distance %5")
                .arg(p.x()).arg(p.y()).arg(m[0], 0, 'f', 0).arg(m[1], 0, 'f', 0)
                .arg(map.distance.at<float>(p.y(), p.x()), 0, 'g', 3));
  } else {
    src_view_->setMarkers({});
    message(tr("destination (%1, %2) is not mapped").arg(p.x()).arg(p.y()));
  }
  origin_view_->setImage(to_qimage(
      veneer::repaint::origin_picture(map, dst_->median, src_->median, {cv::Point(p.x(), p.y())})));
}

void MainWindow::refreshRelight() {
  if (result_ && !relight_error_.isEmpty()) {
    relight_label_->setText(relight_error_);
    return;
  }
  if (!result_ || !relighter_ || !dst_) {
    relight_label_->setText(tr("compute a transfer first"));
    return;
  }
  const cv::Vec3d d = relight_pad_->direction();
  cv::Mat backdrop = dst_->median * 0.25;  // the destination dimmed where nothing is mapped
  relight_view_->setImage(to_qimage(relighter_->render(result_->map, d, backdrop)));
  relight_src_view_->setImage(to_qimage(relighter_->render_source(d)));
  updateRelightLabel(d);
}

void MainWindow::updateRelightLabel(const cv::Vec3d& d) {
  relight_label_->setText(tr("light (%1, %2, %3)\n%4 fit, RMS %5")
                              .arg(d[0], 0, 'f', 2).arg(d[1], 0, 'f', 2).arg(d[2], 0, 'f', 2)
                              .arg(relighter_->basis_name())
                              .arg(relighter_->fit_rms(), 0, 'f', 4));
}

// One box per lamp: the lamps of the set loaded (its manifest's light list),
// else the rig's lamp count; none before either is known.
void MainWindow::updateLampBoxes() {
  QStringList names, tips;
  const LoadedSet* set = dst_ ? dst_.get() : src_.get();
  if (set && !set->set.lights.empty()) {
    for (const auto& l : set->set.lights) {
      names << QString::number(l.index + 1);
      tips << tr("lamp %1 (%2), direction (%3, %4, %5)")
                  .arg(l.index + 1)
                  .arg(qs(l.lamp_id))
                  .arg(l.direction[0], 0, 'f', 2)
                  .arg(l.direction[1], 0, 'f', 2)
                  .arg(l.direction[2], 0, 'f', 2);
    }
  } else {
    for (int i = 0; i < rig_.lastStatus().lamp_count; ++i) {
      names << QString::number(i + 1);
      tips << tr("rig lamp %1").arg(i + 1);
    }
  }
  if (static_cast<int>(lamp_boxes_.size()) == names.size()) {
    for (size_t i = 0; i < lamp_boxes_.size(); ++i) lamp_boxes_[i]->setToolTip(tips[static_cast<int>(i)]);
    return;
  }
  qDeleteAll(lamp_boxes_);
  lamp_boxes_.clear();
  for (int i = 0; i < names.size(); ++i) {
    auto* box = new QCheckBox(names[i]);
    box->setObjectName(QString("lamp%1").arg(i + 1));
    box->setToolTip(tips[i]);
    lamp_boxes_.push_back(box);
    lamp_row_->addWidget(box);
    connect(box, &QCheckBox::toggled, this, [this] {
      std::vector<bool> on;
      for (auto* b : lamp_boxes_) on.push_back(b->isChecked());
      // the rig takes one entry per lamp of its own
      if (rig_.lastStatus().lamp_count > 0) on.resize(static_cast<size_t>(rig_.lastStatus().lamp_count), false);
      rig_.setLamps(on, 254);
    });
  }
}

// A live frame is decoded, registered and repainted off the GUI thread (one
// at a time, on the live view's own thread; frames arriving meanwhile wait as
// the newest one only); the GUI thread only shows the pictures made there.
void MainWindow::onLiveFrame(const veneer::rig::LiveFrame& frame) {
  if (live_busy_) {
    live_next_ = frame;  // coalesced: an older waiting frame is dropped
    return;
  }
  live_busy_ = true;
  auto session = live_session_ && live_session_->ready() && live_refusal_.isEmpty() ? live_session_ : nullptr;
  QPointer<MainWindow> self(this);
  (void)QtConcurrent::run(&live_pool_, [self, frame, session] {
    auto out = std::make_shared<LiveOut>();
    out->seq = frame.seq;
    out->frame = cv::imdecode(frame.jpeg, cv::IMREAD_COLOR);
    if (!out->frame.empty()) {
      cv::Mat shown = out->frame;
      if (session) {
        auto r = session->process(out->frame);
        if (!r) {
          out->refusal = qs(r.message());
        } else {
          out->repainted = r->repainted;
          out->repainted_image = to_qimage(r->repainted);
          // where the source was found: its outline over the frame, green when tracked, red when lost
          shown = out->frame.clone();
          if (r->outline.size() >= 3) {
            std::vector<cv::Point> poly;
            for (const cv::Point2f& p : r->outline) poly.emplace_back(cvRound(p.x), cvRound(p.y));
            cv::polylines(shown, std::vector<std::vector<cv::Point>>{poly}, true,
                          r->lost ? cv::Scalar(0, 0, 255) : cv::Scalar(0, 220, 0), std::max(1, shown.cols / 500),
                          cv::LINE_AA);
          }
          out->state = r->lost ? tr("LOST - hold still / recapture (match %1)").arg(r->quality, 0, 'f', 2)
                               : tr("tracked, match %1").arg(r->quality, 0, 'f', 2);
        }
      }
      out->shown_image = to_qimage(shown);
    }
    QMetaObject::invokeMethod(self.data(), [self, out, session] {
      if (self) self->showLiveFrame(*out, session.get());
    });
  });
}

void MainWindow::showLiveFrame(const LiveOut& out, const veneer::repaint::LiveSession* session) {
  live_busy_ = false;
  if (out.frame.empty()) {
    message(tr("live view: a frame that is not a JPEG was dropped"), true);
  } else {
    live_frame_ = out.frame;
    ++live_frames_;
    if (live_clock_.isValid() && live_clock_.elapsed() > 0) live_fps_ = live_frames_ * 1000.0 / live_clock_.elapsed();
    // the session may have been replaced meanwhile (a new map): its verdicts only for itself
    const bool current = session && session == live_session_.get();
    if (current && !out.refusal.isEmpty() && live_refusal_.isEmpty()) {
      // the live view's framing can't be related to the stills: said once, no wrong picture
      live_refusal_ = out.refusal;
      message(tr("live view: %1").arg(live_refusal_), true);
    }
    if (current && !out.repainted.empty()) {
      live_repainted_ = out.repainted;
      live_dst_view_->setImage(out.repainted_image);
    }
    live_src_view_->setImage(out.shown_image);
    const bool repainting = live_session_ && live_refusal_.isEmpty();
    live_label_->setText(tr("frame %1 · %2 fps").arg(out.seq).arg(live_fps_, 0, 'f', 1) +
                         (out.state.isEmpty() || !current ? QString() : " · " + out.state));
    if (!step_.running())
      step_label_->setText((repainting ? tr("live repaint · ")
                                       : live_session_ ? tr("live view (framing not related to the stills) · ")
                                                       : tr("live view (no map yet) · ")) +
                           live_label_->text());
  }
  if (live_next_) {
    const veneer::rig::LiveFrame next = std::move(*live_next_);
    live_next_.reset();
    onLiveFrame(next);
  }
}

}  // namespace veneer::app
