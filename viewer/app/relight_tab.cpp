#include "relight_tab.hpp"

#include <cmath>

#include <QHBoxLayout>
#include <QLabel>
#include <QVBoxLayout>

#include "widgets.hpp"

namespace veneer::app {

RelightTab::RelightTab(Session& session, QWidget* parent) : QWidget(parent), session_(session) {
  auto* layout = new QHBoxLayout(this);
  auto* left = new QVBoxLayout;
  left->addWidget(new QLabel(tr("Drag the light over the sphere")));
  relight_pad_ = named<SpherePad>("relightPad");
  relight_pad_->setDirection(cv::Vec3d(-0.4, 0.4, std::sqrt(1 - 0.32)));
  connect(relight_pad_, &SpherePad::directionChanged, this, [this] {
    refresh();
    emit lightChanged();
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
}

void RelightTab::refresh() {
  if (session_.result && !session_.relight_error.isEmpty()) {
    relight_label_->setText(session_.relight_error);
    return;
  }
  if (!session_.result || !session_.relighter || !session_.dst) {
    relight_label_->setText(tr("compute a transfer first"));
    return;
  }
  const cv::Vec3d d = relight_pad_->direction();
  cv::Mat backdrop = session_.dst->median * 0.25;  // the destination dimmed where nothing is mapped
  relight_view_->setImage(to_qimage(session_.relighter->render(session_.result->map, d, backdrop)));
  relight_src_view_->setImage(to_qimage(session_.relighter->render_source(d)));
  updateLabel(d);
}

void RelightTab::showRelit(const QImage& relit, const QImage& relit_source, const cv::Vec3d& light) {
  if (!session_.relighter || relit.isNull() || light != relight_pad_->direction()) return refresh();
  relight_view_->setImage(relit);
  relight_src_view_->setImage(relit_source);
  updateLabel(light);
}

void RelightTab::updateLabel(const cv::Vec3d& d) {
  relight_label_->setText(tr("light (%1, %2, %3)\n%4 fit, RMS %5")
                              .arg(d[0], 0, 'f', 2).arg(d[1], 0, 'f', 2).arg(d[2], 0, 'f', 2)
                              .arg(session_.relighter->basis_name())
                              .arg(session_.relighter->fit_rms(), 0, 'f', 4));
}

}  // namespace veneer::app
