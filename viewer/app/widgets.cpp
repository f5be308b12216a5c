#include <tbb/task_arena.h>  // before Qt: its `emit` macro breaks TBB's headers

#include "widgets.hpp"

namespace veneer::app {

void gui_work(const std::function<void()>& f) { tbb::this_task_arena::isolate(f); }

}  // namespace veneer::app
