// The Look, Live and Relight tabs and what they show.
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

QWidget* MainWindow::buildLookTab() {
  auto* w = new QWidget;
  auto* layout = new QVBoxLayout(w);
  auto* top = new QHBoxLayout;
  look_what_ = new QComboBox;
  look_what_->setObjectName("lookWhat");
  look_what_->addItems({tr("median of all lamps"), tr("normals"), tr("albedo"), tr("mask"),
                        tr("correspondence map"), tr("source reuse")});
  connect(look_what_, &QComboBox::currentIndexChanged, this, [this] { refreshLook(); });
  top->addWidget(new QLabel(tr("Show")));
  top->addWidget(look_what_);
  auto* reset = button(tr("Fit"), "fitViews", w);
  connect(reset, &QPushButton::clicked, this, [this] { sync_.reset(); });
  top->addWidget(reset);
  top->addStretch();
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
    seg_rect_ = r;
    rect_label_->setText(r.isEmpty() ? tr("no rectangle")
                                     : tr("rectangle %1,%2 %3x%4").arg(r.x()).arg(r.y()).arg(r.width()).arg(r.height()));
    matchOptionChanged();  // a new object outline: prepared again and matched
  });
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
  connect(live_cap_src, &QPushButton::clicked, this, [this] { capture_(veneer::Role::source); });
  connect(live_cap_dst, &QPushButton::clicked, this, [this] { capture_(veneer::Role::destination); });
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
  connect(relight_pad_, &SpherePad::directionChanged, this, [this] { refreshRelight(); });
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

void MainWindow::refreshLookNow() {
  const int what = look_what_->currentIndex();
  auto pick = [what](const std::shared_ptr<LoadedSet>& s) -> cv::Mat {
    if (!s) return {};
    switch (what) {
      case 1: return s->normals ? normals_picture(s->normals->normals) : cv::Mat();
      case 2: return s->normals ? picture_of(s->normals->albedo) : cv::Mat();
      case 3: return s->normals ? s->normals->mask : cv::Mat();
      default: return s->median_picture.empty() ? picture_of(s->median) : s->median_picture;
    }
  };
  dst_view_->setImage(to_qimage(pick(dst_)));
  src_view_->setImage(to_qimage(pick(src_)));
  if (result_) {
    cv::Mat r;
    if (what == 4) {
      r = veneer::match::map_picture(result_->map, result_->source_size);
    } else if (what == 5) {
      r = veneer::match::reuse_picture(result_->reuse, result_->source_median);
      src_view_->setImage(to_qimage(r));
      r = result_picture_.empty() ? picture_of(result_->repainted_median) : result_picture_;
    } else {
      r = result_picture_.empty() ? picture_of(result_->repainted_median) : result_picture_;
    }
    result_view_->setImage(to_qimage(r));
  } else {
    result_view_->setImage({});
  }
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
      veneer::match::origin_picture(map, dst_->median, src_->median, {cv::Point(p.x(), p.y())})));
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

void MainWindow::onLiveFrame(const veneer::rig::LiveFrame& frame) {
  cv::Mat decoded = cv::imdecode(frame.jpeg, cv::IMREAD_COLOR);
  if (decoded.empty()) {
    message(tr("live view: a frame that is not a JPEG was dropped"), true);
    return;
  }
  live_frame_ = decoded;
  ++live_frames_;
  if (live_clock_.isValid() && live_clock_.elapsed() > 0) live_fps_ = live_frames_ * 1000.0 / live_clock_.elapsed();
  gui_work([&] {
    live_src_view_->setImage(to_qimage(decoded));
    if (repainter_.ready()) {
      live_repainted_ = repainter_.apply(decoded);
      live_dst_view_->setImage(to_qimage(live_repainted_));
    }
  });
  live_label_->setText(tr("frame %1 · %2 fps").arg(frame.seq).arg(live_fps_, 0, 'f', 1));
  if (!step_.running())
    step_label_->setText((repainter_.ready() ? tr("live repaint · ") : tr("live view (no map yet) · ")) +
                         live_label_->text());
}

}  // namespace veneer::app
