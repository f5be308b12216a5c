#include <tbb/task_arena.h>  // before Qt: its `emit` macro breaks TBB's headers

#include "widgets.hpp"

#include <QAbstractSlider>
#include <QAbstractSpinBox>
#include <QComboBox>
#include <QEvent>
#include <QThread>

#include <algorithm>

#include "veneer/io/image_io.hpp"
#include "veneer/pipeline/prepare.hpp"

namespace veneer::app {

cv::Mat picture_of(const cv::Mat& linear) { return linear.empty() ? cv::Mat() : io::tonemap_picture(linear); }

void gui_work(const std::function<void()>& f) { tbb::this_task_arena::isolate(f); }

// The pool is made after the engine's statics its jobs use (the result
// cache's pending writes, and with them the log's registry), so that at exit
// it is destroyed first: its destructor waits for a job still running (a
// set's normals being prepared when the window closed), and the cache writes
// that job started are then joined by the pending writes' own destructor.
// Made the other way round, such a job wrote to a destroyed registry
// (app/Viewer tests crashed at exit, 1 run in 3).
QThreadPool* job_pool() {
  static const bool engine_first = (static_cast<void>(pipeline::finish_cache_writes()), true);
  (void)engine_first;
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
