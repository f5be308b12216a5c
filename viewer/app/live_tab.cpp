#include "live_tab.hpp"

#include <QCheckBox>
#include <QComboBox>
#include <QDoubleSpinBox>
#include <QHBoxLayout>
#include <QLabel>
#include <QPointer>
#include <QPushButton>
#include <QSignalBlocker>
#include <QVBoxLayout>
#include <QtConcurrent/QtConcurrentRun>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "veneer/io/image_io.hpp"
#include "veneer/repaint/repaint.hpp"
#include "widgets.hpp"

namespace veneer::app {

std::shared_ptr<veneer::repaint::LiveSession> make_live_session(
    const veneer::pipeline::PreparedPair& pair, const veneer::pipeline::TransferOptions& options,
    const veneer::pipeline::TransferResult& result, const std::vector<cv::Mat>& source_photos,
    const cv::Mat& still_mask, const cv::Mat& backdrop, QString* note, const veneer::Progress& progress) {
  cv::Mat mask = still_mask;
  if (!source_photos.empty() && mask.size() != source_photos.front().size())
    cv::resize(still_mask, mask, source_photos.front().size(), 0, 0, cv::INTER_NEAREST);
  std::shared_ptr<const veneer::repaint::LiveLook> live_look;
  auto made = veneer::pipeline::live_look(pair, options, result.map, result.look, {}, progress);
  if (made)
    live_look = *made;
  else if (note)
    *note = LiveTab::tr("the live view paints the copy only: the shaded look: %1").arg(qs(made.message()));
  // the destination's photos at the map's scale lit by the lamp that lights each pixel second most, as
  // `veneer repaint --video` paints them (no lamp's shadow frozen around the object); `backdrop` when the
  // pair holds no photos
  const cv::Mat lit = pair.dst.view.images.empty() ? backdrop
                                                   : veneer::io::tonemap_picture(veneer::repaint::lit_photo(pair.dst.view.images));
  return std::make_shared<veneer::repaint::LiveSession>(source_photos, mask, result.map, result.source_size, live_look,
                                                        lit, result.blend);
}

namespace {
// `picture` (8-bit BGR) at the size a `view`-sized ImageView paints it at zoom 1.
QImage fitted_qimage(const cv::Mat& picture, QSize view) {
  if (picture.empty()) return {};
  const QSize s = ImageView::fitSize(view, QSize(picture.cols, picture.rows));
  if (s.isEmpty()) return {};
  if (s.width() == picture.cols && s.height() == picture.rows) return to_qimage(picture);
  cv::Mat small;
  cv::resize(picture, small, cv::Size(s.width(), s.height()), 0, 0,
             s.width() < picture.cols ? cv::INTER_AREA : cv::INTER_LINEAR);
  return to_qimage(small);
}
}  // namespace

int LiveTab::fittedPaints() const { return live_src_view_->fittedPaints() + live_dst_view_->fittedPaints(); }

LiveTab::LiveTab(Session& session, QWidget* parent) : QWidget(parent), session_(session) {
  live_thread_ = std::thread([this] {  // the live view's thread stays while the window lives
    for (;;) {
      live_go_.acquire();
      if (live_quit_.load()) return;
      std::function<void()> task = std::move(live_task_);
      live_task_ = nullptr;
      if (task) task();
    }
  });
  auto* layout = new QVBoxLayout(this);
  auto* top = new QHBoxLayout;
  live_btn_ = button(tr("Start live view"), "liveToggle", this);
  live_btn_->setCheckable(true);
  fps_ = named<QDoubleSpinBox>("liveFps");
  fps_->setRange(1, 60);
  fps_->setValue(15);
  connect(live_btn_, &QPushButton::toggled, this, [this](bool on) {
    live_btn_->setText(on ? tr("Stop live view") : tr("Start live view"));
    if (on) {
      live_clock_.start();
      live_frames_ = 0;
      session_.rig.startLive(fps_->value());
    } else {
      session_.rig.stopLive();
    }
  });
  top->addWidget(live_btn_);
  auto* live_cap_src = button(tr("Capture source"), "liveCaptureSource", this);
  auto* live_cap_dst = button(tr("Capture destination"), "liveCaptureDestination", this);
  connect(live_cap_src, &QPushButton::clicked, this, [this] { emit captureRequested(veneer::io::Role::source); });
  connect(live_cap_dst, &QPushButton::clicked, this, [this] { emit captureRequested(veneer::io::Role::destination); });
  top->addWidget(live_cap_src);
  top->addWidget(live_cap_dst);
  look_box_ = named<QComboBox>("liveLook");
  for (auto l : {veneer::repaint::Look::shaded, veneer::repaint::Look::copy}) look_box_->addItem(qs(veneer::repaint::look_name(l)));
  look_box_->setCurrentText(qs(veneer::repaint::look_name(look_)));
  look_box_->setToolTip(tr("shaded: each frame painted in the source's look at the light estimated in it (the "
                           "still look, live); copy: the frame's pixels pasted through the map"));
  connect(look_box_, &QComboBox::currentTextChanged, this, [this](const QString& name) {
    if (auto l = veneer::repaint::parse_look(name.toStdString())) look_ = *l;
  });
  top->addWidget(new QLabel(tr("Look")));
  top->addWidget(look_box_);
  top->addWidget(new QLabel(tr("fps")));
  top->addWidget(fps_);
  top->addWidget(new QLabel(tr("Lamps:")));
  lamp_row_ = new QHBoxLayout;
  top->addLayout(lamp_row_);
  top->addStretch();
  live_label_ = named<QLabel>("liveStatus");
  top->addWidget(live_label_);
  layout->addLayout(top);
  auto* row = new QHBoxLayout;
  live_src_view_ = new ImageView(tr("source, live"));
  live_dst_view_ = new ImageView(tr("destination, repainted live"));
  row->addWidget(live_src_view_, 3);
  row->addWidget(live_dst_view_, 3);
  auto* pad_box = new QVBoxLayout;
  pad_box->addWidget(new QLabel(tr("hand-held lamp\n(simulated rig)")));
  hand_pad_ = named<SpherePad>("handLamp");
  connect(hand_pad_, &SpherePad::directionChanged, this, [this](cv::Vec3d d) {
    // The lamp 0.6 m from the object in the chosen direction.
    session_.rig.moveHandLamp(d * 0.6);
  });
  pad_box->addWidget(hand_pad_);
  pad_box->addWidget(new QLabel(tr("light in the frame")));
  light_dial_ = named<LightDial>("liveLight");
  pad_box->addWidget(light_dial_);
  pad_box->addStretch();
  row->addLayout(pad_box, 1);
  layout->addLayout(row, 1);
  RigLink& rig = session_.rig;
  connect(&rig, &RigLink::liveFrame, this, &LiveTab::onLiveFrame);
  connect(&rig, &RigLink::statusUpdated, this, [this](veneer::rig::RigStatus) { updateLampBoxes(); });
  connect(&rig, &RigLink::rigEvent, this, [this](const veneer::rig::Event& e) {
    if (e.kind != veneer::rig::Event::Kind::lamp_state) return;
    for (size_t i = 0; i < lamp_boxes_.size() && i < e.lamps_on.size(); ++i) {
      QSignalBlocker block(lamp_boxes_[i]);
      lamp_boxes_[i]->setChecked(e.lamps_on[i]);
    }
  });
}

LiveTab::~LiveTab() {
  live_quit_.store(true);
  live_go_.release();
  live_thread_.join();
}

bool LiveTab::isLive() const { return live_btn_->isChecked(); }

void LiveTab::startLive() { live_btn_->setChecked(true); }

void LiveTab::setLook(veneer::repaint::Look look) {
  look_box_->setCurrentText(qs(veneer::repaint::look_name(look)));  // sets look_
}

void LiveTab::showLight(const std::optional<veneer::repaint::LiveLight>& light, veneer::repaint::Look painted) {
  last_painted_ = painted;
  light_dial_->setLight(light, painted);
}

void LiveTab::updateLampBoxes() {
  QStringList names, tips;
  const LoadedSet* set = session_.dst ? session_.dst.get() : session_.src.get();
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
    for (int i = 0; i < session_.rig.lastStatus().lamp_count; ++i) {
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
    auto* box = named<QCheckBox>(QString("lamp%1").arg(i + 1), names[i]);
    box->setToolTip(tips[i]);
    lamp_boxes_.push_back(box);
    lamp_row_->addWidget(box);
    connect(box, &QCheckBox::toggled, this, [this] {
      std::vector<bool> on;
      for (auto* b : lamp_boxes_) on.push_back(b->isChecked());
      // the rig takes one entry per lamp of its own
      const int lamps = session_.rig.lastStatus().lamp_count;
      if (lamps > 0) on.resize(static_cast<size_t>(lamps), false);
      session_.rig.setLamps(on, 254);
    });
  }
}

// A live frame is decoded, registered and repainted off the GUI thread (one
// at a time, on the live view's own thread; frames arriving meanwhile wait as
// the newest one only); the GUI thread only shows the pictures made there.
void LiveTab::onLiveFrame(const veneer::rig::LiveFrame& frame) {
  if (live_busy_) {
    live_next_ = frame;  // coalesced: an older waiting frame is dropped
    return;
  }
  live_busy_ = true;
  const auto& live = session_.live_session;
  auto session = live && live->ready() && session_.live_refusal.isEmpty() ? live : nullptr;
  const veneer::repaint::Look look = look_;
  const QSize src_view = live_src_view_->size(), dst_view = live_dst_view_->size();
  QPointer<LiveTab> self(this);
  live_task_ = [self, frame, session, look, src_view, dst_view] {
    auto out = std::make_shared<LiveOut>();
    out->seq = frame.seq;
    out->frame = cv::imdecode(frame.jpeg, cv::IMREAD_COLOR);
    if (!out->frame.empty()) {
      cv::Mat shown = out->frame;
      if (session) {
        session->set_look(look);  // here, on the one thread that paints with the session
        auto r = session->process(out->frame);
        if (!r) {
          out->refusal = qs(r.message());
        } else {
          out->repainted = r->repainted;
          out->repainted_image = to_qimage(r->repainted);
          out->repainted_fitted = fitted_qimage(r->repainted, dst_view);
          out->painted = r->look;
          out->light = r->light;
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
      out->shown_fitted = fitted_qimage(shown, src_view);
    }
    QMetaObject::invokeMethod(self.data(), [self, out, session] {
      if (self) self->showLiveFrame(*out, session.get());
    });
  };
  live_go_.release();
}

void LiveTab::showLiveFrame(const LiveOut& out, const veneer::repaint::LiveSession* session) {
  live_busy_ = false;
  if (out.frame.empty()) {
    session_.message(tr("live view: a frame that is not a JPEG was dropped"), true);
  } else {
    live_frame_ = out.frame;
    ++live_frames_;
    if (live_clock_.isValid() && live_clock_.elapsed() > 0) live_fps_ = live_frames_ * 1000.0 / live_clock_.elapsed();
    // the session may have been replaced meanwhile (a new map): its verdicts only for itself
    const bool current = session && session == session_.live_session.get();
    if (current && !out.refusal.isEmpty() && session_.live_refusal.isEmpty()) {
      // the live view's framing can't be related to the stills: said once, no wrong picture
      session_.live_refusal = out.refusal;
      session_.message(tr("live view: %1").arg(session_.live_refusal), true);
    }
    if (current && !out.repainted.empty()) {
      live_repainted_ = out.repainted;
      live_dst_view_->setImage(out.repainted_image, out.repainted_fitted);
      showLight(out.light, out.painted);
    }
    live_src_view_->setImage(out.shown_image, out.shown_fitted);
    const bool repainting = session_.live_session && session_.live_refusal.isEmpty();
    live_label_->setText(tr("frame %1 · %2 fps").arg(out.seq).arg(live_fps_, 0, 'f', 1) +
                         (out.state.isEmpty() || !current ? QString() : " · " + out.state));
    if (!session_.status.step().running())
      session_.status.say((repainting               ? tr("live repaint · ")
                           : session_.live_session ? tr("live view (framing not related to the stills) · ")
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
