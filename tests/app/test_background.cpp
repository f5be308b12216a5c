// The background the full-resolution job computes in (background.hpp): every
// thread that runs its TBB and OpenCV loops is at the background's lower
// priority, the job's loops get more than its one thread, and the threads
// the rest of the viewer uses (the GUI thread, TBB's shared workers) keep
// their priority. Structural: nothing here is timed.
#include <sys/resource.h>
#include <unistd.h>

#include <tbb/parallel_for.h>  // before Qt: its `emit` macro breaks TBB's headers

#include <atomic>
#include <chrono>
#include <map>
#include <mutex>
#include <thread>

#include <QThread>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>

#include "background.hpp"

namespace {

int nice_of_this_thread() {
  errno = 0;
  return ::getpriority(PRIO_PROCESS, static_cast<id_t>(::gettid()));
}

// Thread id -> its nice value, for every thread a loop body ran on.
struct Seen {
  std::mutex m;
  std::map<pid_t, int> nice;
  void note() {
    const int n = nice_of_this_thread();
    std::lock_guard lock(m);
    nice[::gettid()] = n;
  }
  size_t threads() {
    std::lock_guard lock(m);
    return nice.size();
  }
};

// A loop whose first iterations wait (up to 20 s, not a speed bound) until a
// second thread took part, so a pool that has one shows it.
template <class Loop>
void loop_until_two_threads(Seen& seen, Loop loop) {
  const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(20);
  loop([&] {
    seen.note();
    while (seen.threads() < 2 && std::chrono::steady_clock::now() < until)
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
  });
}

}  // namespace

TEST(Background, TheJobsLoopsRunOnlyOnThreadsBelowTheGuis) {
  veneer::app::opencv_loops_in_current_arena();
  const int gui_nice = nice_of_this_thread();
  ASSERT_LT(gui_nice, veneer::app::kBackgroundNice) << "the test runs at nice " << gui_nice;
  Seen tbb_seen, cv_seen;
  int job_nice = -100;
  veneer::app::run_in_background([&] {
     job_nice = nice_of_this_thread();
     loop_until_two_threads(tbb_seen, [](auto body) { tbb::parallel_for(0, 64, [&](int) { body(); }); });
     loop_until_two_threads(cv_seen, [](auto body) {
       cv::parallel_for_(cv::Range(0, 64), [&](const cv::Range& r) {
         for (int i = r.start; i < r.end; ++i) body();
       });
     });
   }).waitForFinished();
  EXPECT_EQ(job_nice, veneer::app::kBackgroundNice);
  for (auto* seen : {&tbb_seen, &cv_seen}) {
    for (const auto& [tid, n] : seen->nice) EXPECT_EQ(n, veneer::app::kBackgroundNice) << "thread " << tid;
    // the job computes on as many threads as the machine has cores (its own and its helpers)
    EXPECT_EQ(seen->threads(), static_cast<size_t>(std::min(2, veneer::app::background_concurrency())));
  }
  // the rest keeps its priority: this thread, and every thread a loop made outside runs on
  EXPECT_EQ(nice_of_this_thread(), gui_nice);
  Seen outside;
  loop_until_two_threads(outside, [](auto body) { tbb::parallel_for(0, 64, [&](int) { body(); }); });
  for (const auto& [tid, n] : outside.nice) EXPECT_EQ(n, gui_nice) << "thread " << tid;
  Seen outside_cv;
  loop_until_two_threads(outside_cv, [](auto body) {
    cv::parallel_for_(cv::Range(0, 64), [&](const cv::Range& r) {
      for (int i = r.start; i < r.end; ++i) body();
    });
  });
  for (const auto& [tid, n] : outside_cv.nice) EXPECT_EQ(n, gui_nice) << "thread " << tid;
}

TEST(Background, AJobThatThrowsLetsItsHelpersGo) {
  // the helpers are released however the job ends; the next job runs
  bool ran = false;
  try {
    veneer::app::run_in_background([] { throw std::runtime_error("job failed"); }).waitForFinished();
  } catch (...) {
  }
  veneer::app::run_in_background([&] { ran = true; }).waitForFinished();
  EXPECT_TRUE(ran);
}
