#pragma once
// The background: where the full-resolution job computes (issue 48). Its
// threads run below the GUI's and the live view's priority (nice
// kBackgroundNice, raised once per thread and never lowered again, so no
// privilege is needed), and its parallel loops -- TBB's and OpenCV's -- run
// only on those threads: in a TBB arena of its own that TBB's shared workers
// never join (every slot reserved), filled by background helper threads. The
// GUI thread never calls into it, and the TBB workers the live view's
// loops use never pick up its tasks.
#include <functional>

#include <QFuture>

class QThreadPool;

namespace veneer::app {

constexpr int kBackgroundNice = 10;

// The pool background jobs start on (one job at a time); its threads at
// nice kBackgroundNice. Not the pool the live-size map and loads use (job_pool).
QThreadPool* background_pool();

// How many threads a background job computes on (the job's own and its
// helpers): the machine's cores.
int background_concurrency();

// Runs `job` on the background pool, inside the background arena: every TBB
// and OpenCV parallel loop it makes runs on threads at nice kBackgroundNice.
QFuture<void> run_in_background(std::function<void()> job);

// OpenCV's parallel loops run in the calling thread's TBB arena (instead of
// OpenCV's own, which TBB's shared workers at normal priority serve), so a
// background job's OpenCV calls stay on its threads. Made once per process;
// job_pool() and background_pool() call it.
void opencv_loops_in_current_arena();

}  // namespace veneer::app
