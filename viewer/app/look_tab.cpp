#include "look_tab.hpp"

#include <algorithm>
#include <cmath>

#include <QComboBox>
#include <QFileInfo>
#include <QHBoxLayout>
#include <QLabel>
#include <QPainter>
#include <QPushButton>
#include <QSignalBlocker>
#include <QVBoxLayout>

#include <opencv2/imgproc.hpp>

#include "veneer/io/image_io.hpp"
#include "veneer/repaint/specular.hpp"
#include "widgets.hpp"

namespace veneer::app {

LookTab::LookTab(Session& session, QWidget* parent) : QWidget(parent), session_(session) {
  auto* layout = new QVBoxLayout(this);
  auto* top = new QHBoxLayout;
  look_what_ = named<QComboBox>("lookWhat");
  look_what_->addItems({tr("median of all lamps"), tr("normals"), tr("albedo"), tr("mask"),
                        tr("correspondence map"), tr("source reuse"), tr("confidence"),
                        tr("specular enhancement")});
  look_what_->setToolTip(tr("confidence: the photometric-stereo fit per set (bright = the lamps agree) and the "
                            "map's match distance on the result (bright = close match); specular enhancement: "
                            "the normals shaded shiny under the Relight tab's light"));
  connect(look_what_, &QComboBox::currentIndexChanged, this, [this] { refresh(); });
  top->addWidget(new QLabel(tr("Show")));
  top->addWidget(look_what_);
  look_style_ = named<QComboBox>("look");
  for (auto l : {veneer::repaint::Look::shaded, veneer::repaint::Look::copy})
    look_style_->addItem(qs(veneer::repaint::look_name(l)));
  look_style_->setCurrentText(qs(veneer::repaint::look_name(veneer::pipeline::TransferOptions{}.look)));
  look_style_->setToolTip(tr("how the result is painted, as veneer transfer --look: shaded (the source's texture "
                             "whole, each lamp shading it as it shades the destination, the source's gloss "
                             "placed by the destination's normals) or copy (each lamp's source photo pasted "
                             "through the map, blended)"));
  connect(look_style_, &QComboBox::currentTextChanged, this, [this](const QString& name) {
    if (auto l = veneer::repaint::parse_look(name.toStdString())) emit lookChosen(*l);
  });
  top->addWidget(new QLabel(tr("Look")));
  top->addWidget(look_style_);
  auto* reset = button(tr("Fit"), "fitViews", this);
  connect(reset, &QPushButton::clicked, this, [this] { sync_.reset(); });
  top->addWidget(reset);
  auto* snap = button(tr("Snapshot…"), "snapshot", this);
  snap->setToolTip(tr("save the view shown (this tab, as on screen) as a PNG"));
  connect(snap, &QPushButton::clicked, this, &LookTab::snapshotAsked);
  top->addWidget(snap);
  top->addStretch();
  histogram_ = named<QLabel>("histogram");
  top->addWidget(histogram_);
  exposure_label_ = named<QLabel>("exposure");
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
  connect(dst_view_, &ImageView::pixelClicked, this, &LookTab::showOrigin);
  connect(result_view_, &ImageView::pixelClicked, this, &LookTab::showOrigin);
  connect(dst_view_, &ImageView::rectDrawn, this, [this](QRect r) {
    dst_view_->setRect({});
    emit handRectDrawn(veneer::io::Role::destination, r);
  });
  connect(src_view_, &ImageView::rectDrawn, this, [this](QRect r) {
    src_view_->setRect({});
    emit handRectDrawn(veneer::io::Role::source, r);
  });
  connect(dst_view_, &ImageView::brushed, this,
          [this](QPoint p, bool add) { emit brushed(veneer::io::Role::destination, p, add); });
  connect(src_view_, &ImageView::brushed, this,
          [this](QPoint p, bool add) { emit brushed(veneer::io::Role::source, p, add); });
}

void LookTab::refresh() {
  gui_work([this] { refreshNow(); });
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

void LookTab::refreshNow() {
  const int what = look_what_->currentIndex();
  const cv::Vec3d light = session_.light();
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
  dst_view_->setImage(pick_image(session_.dst));
  src_view_->setImage(pick_image(session_.src));
  if (session_.result) {
    cv::Mat r;
    if (what == 4) {
      r = veneer::repaint::map_picture(session_.result->map, session_.result->source_size);
    } else if (what == 6) {
      const cv::Mat& d = session_.result->map.distance;
      cv::Mat xy[2];
      cv::split(session_.result->map.xy, xy);
      cv::Mat valid = xy[0] >= 0, good;  // unmapped pixels: black
      double hi = 0;
      cv::minMaxLoc(d, nullptr, &hi, nullptr, nullptr, valid);
      good = 1.0 - d / std::max(1e-6, hi);
      r = confidence_picture(good, valid);
    } else if (what == 5) {
      r = veneer::repaint::reuse_picture(session_.result->reuse, session_.result->source_median);
      src_view_->setImage(to_qimage(r));
      r = session_.result_picture.empty() ? picture_of(session_.result->repainted_median) : session_.result_picture;
    } else if (!session_.result_image.isNull()) {
      result_view_->setImage(session_.result_image);  // made by the transfer's worker
      return;
    } else {
      r = session_.result_picture.empty() ? picture_of(session_.result->repainted_median) : session_.result_picture;
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

void LookTab::updateHistogram() {
  const LoadedSet* s = session_.dst ? session_.dst.get() : session_.src.get();
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

void LookTab::showOrigin(QPoint p) {
  if (!session_.result || !session_.dst || !session_.src) {
    session_.message(tr("compute a transfer first; then a click shows where a pixel's look comes from"), true);
    return;
  }
  const auto& map = session_.result->map;
  if (p.x() >= map.xy.cols || p.y() >= map.xy.rows) return;
  const cv::Vec2f m = map.xy.at<cv::Vec2f>(p.y(), p.x());
  std::vector<ImageView::Marker> dst_markers{{QPointF(p), QColor(0, 220, 255), m[0] < 0}};
  dst_view_->setMarkers(dst_markers);
  result_view_->setMarkers(dst_markers);
  if (m[0] >= 0) {
    src_view_->setMarkers({{QPointF(m[0], m[1]), QColor(0, 220, 255), false}});
    session_.message(tr("destination (%1, %2) ← source (%3, %4), distance %5")
                         .arg(p.x()).arg(p.y()).arg(m[0], 0, 'f', 0).arg(m[1], 0, 'f', 0)
                         .arg(map.distance.at<float>(p.y(), p.x()), 0, 'g', 3));
  } else {
    src_view_->setMarkers({});
    session_.message(tr("destination (%1, %2) is not mapped").arg(p.x()).arg(p.y()));
  }
  origin_view_->setImage(to_qimage(
      veneer::repaint::origin_picture(map, session_.dst->median, session_.src->median, {cv::Point(p.x(), p.y())})));
}


void LookTab::showResult() {
  if (look_what_->currentIndex() != 0)
    look_what_->setCurrentIndex(0);  // refreshes the views
  else
    refresh();
}

void LookTab::lightChanged() {
  if (look_what_->currentIndex() == 7) refresh();  // specular enhancement follows the light
}

void LookTab::setLook(veneer::repaint::Look look) {
  QSignalBlocker block(look_style_);
  look_style_->setCurrentText(qs(veneer::repaint::look_name(look)));
}

int LookTab::lookIndex(const QString& what) const { return look_what_->findText(what); }

void LookTab::showLook(int index) {
  look_what_->setCurrentIndex(index);
  refresh();
}

void LookTab::setOutline(veneer::io::Role set, const std::vector<QPolygonF>& outline) {
  (set == veneer::io::Role::source ? src_view_ : dst_view_)->setOutline(outline);
}

}  // namespace veneer::app
