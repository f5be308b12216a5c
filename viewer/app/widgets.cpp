#include <tbb/task_arena.h>  // before Qt: its `emit` macro breaks TBB's headers

#include "widgets.hpp"

#include <QAbstractSlider>
#include <QAbstractSpinBox>
#include <QComboBox>
#include <QEvent>
#include <QThread>

#include <algorithm>

#include "veneer/io/image_io.hpp"

namespace veneer::app {

cv::Mat picture_of(const cv::Mat& linear) { return linear.empty() ? cv::Mat() : io::tonemap_picture(linear); }

void gui_work(const std::function<void()>& f) { tbb::this_task_arena::isolate(f); }

QThreadPool* job_pool() {
  static QThreadPool pool;
  static const bool sized = [] {
    // jobs spend their time in TBB's loops or on the disk: more jobs than cores may wait side by side
    pool.setMaxThreadCount(std::max(4, QThread::idealThreadCount()));
    return true;
  }();
  (void)sized;
  return &pool;
}

namespace {
class WheelGuard : public QObject {
 public:
  using QObject::QObject;
  bool eventFilter(QObject* watched, QEvent* event) override {
    auto* w = qobject_cast<QWidget*>(watched);
    if (event->type() == QEvent::Wheel && w && !w->hasFocus()) {
      event->ignore();  // not for this field: on to the scroll area around it
      return true;
    }
    return false;
  }
};
}  // namespace

void guard_wheel(QWidget* root) {
  auto* guard = new WheelGuard(root);
  auto fence = [guard](QWidget* w) {
    w->setFocusPolicy(Qt::StrongFocus);  // focus by click or tab, not by the wheel
    w->installEventFilter(guard);
  };
  for (auto* w : root->findChildren<QAbstractSpinBox*>()) fence(w);
  for (auto* w : root->findChildren<QComboBox*>()) fence(w);
  for (auto* w : root->findChildren<QAbstractSlider*>()) fence(w);
}

}  // namespace veneer::app
