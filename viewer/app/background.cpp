#include <tbb/blocked_range.h>  // before Qt: its `emit` macro breaks TBB's headers
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>
#include <tbb/task_group.h>

#include "background.hpp"

#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <memory>
#include <thread>
#include <vector>

#include <QThread>
#include <QThreadPool>
#include <QtConcurrent/QtConcurrentRun>

#include <opencv2/core/parallel/parallel_backend.hpp>

namespace veneer::app {

namespace {

// The calling thread at nice kBackgroundNice (Linux: per thread). Raising
// needs no privilege; it is never lowered again (that would).
void lower_this_thread() {
  const auto tid = static_cast<id_t>(::gettid());
  errno = 0;
  const int now = ::getpriority(PRIO_PROCESS, tid);
  if (errno == 0 && now >= kBackgroundNice) return;
  (void)::setpriority(PRIO_PROCESS, tid, kBackgroundNice);
}

// OpenCV's parallel_for_ as tbb::parallel_for in the caller's arena.
class CurrentArenaLoops : public cv::parallel::ParallelForAPI {
 public:
  void parallel_for(int tasks, FN_parallel_for_body_cb_t body, void* data) override {
    tbb::parallel_for(tbb::blocked_range<int>(0, tasks),
                      [body, data](const tbb::blocked_range<int>& r) { body(r.begin(), r.end(), data); });
  }
  int getThreadNum() const override { return std::max(0, tbb::this_task_arena::current_thread_index()); }
  int getNumThreads() const override { return tbb::this_task_arena::max_concurrency(); }
  int setNumThreads(int) override { return getNumThreads(); }  // the arenas decide
  const char* getName() const override { return "veneer-current-arena"; }
};

}  // namespace

void opencv_loops_in_current_arena() {
  static const bool made = [] {
    cv::parallel::setParallelForBackend(std::make_shared<CurrentArenaLoops>(), false);
    return true;
  }();
  (void)made;
}

int background_concurrency() { return std::max(1, QThread::idealThreadCount()); }

QThreadPool* background_pool() {
  opencv_loops_in_current_arena();
  static QThreadPool pool;
  static const bool sized = [] {
    pool.setMaxThreadCount(1);  // one background job at a time; its helpers are its own threads
    return true;
  }();
  (void)sized;
  return &pool;
}

QFuture<void> run_in_background(std::function<void()> job) {
  return QtConcurrent::run(background_pool(), [job = std::move(job)] {
    lower_this_thread();
    const int n = background_concurrency();
    // every slot reserved for the threads entering it: TBB's workers never join
    tbb::task_arena arena(n, static_cast<unsigned>(n), tbb::task_arena::priority::low);
    arena.initialize();
    // The helpers enter the arena and wait there on a task group held open
    // (a deferred task), taking the job's tasks meanwhile.
    tbb::task_group held;
    auto hold = std::make_unique<tbb::task_handle>(held.defer([] {}));
    std::vector<std::thread> helpers;
    for (int i = 1; i < n; ++i)
      helpers.emplace_back([&arena, &held] {
        lower_this_thread();
        arena.execute([&held] { held.wait(); });
      });
    struct Release {  // however the job ends
      tbb::task_arena& arena;
      tbb::task_group& held;
      std::unique_ptr<tbb::task_handle>& hold;
      std::vector<std::thread>& helpers;
      ~Release() {
        arena.execute([&] {
          held.run(std::move(*hold));
          held.wait();
        });
        for (auto& h : helpers) h.join();
      }
    } release{arena, held, hold, helpers};
    arena.execute(job);
  });
}

}  // namespace veneer::app
