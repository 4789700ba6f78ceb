#include "core/parallel.h"

#include <map>
#include <memory>

namespace mobirt::detail {

// One arena per calling thread (and thread count). A task_arena of N threads has one slot for a
// thread that calls execute(), the rest for TBB's workers: when two threads shared one, the
// second one's execute() found the slot taken, queued its loop and slept until another thread ran
// it. The frame pipeline's worker (at SCHED_IDLE) building light buffers held the rendering
// thread's arena that way: the toaster's primary rays waited 1-3 ms behind it in one frame of five
// (a frame timeline, session 39). TBB's workers still serve every arena. Each thread's arenas go
// with it: no other thread ever runs a loop in them.
tbb::task_arena& parallel_arena(unsigned threads) {
  thread_local std::map<unsigned, std::unique_ptr<tbb::task_arena>> arenas;
  std::unique_ptr<tbb::task_arena>& arena = arenas[threads];
  if (!arena) arena = std::make_unique<tbb::task_arena>(int(threads));
  return *arena;
}

}  // namespace mobirt::detail
