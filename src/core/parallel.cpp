#include "core/parallel.h"

#include <map>
#include <memory>
#include <mutex>

namespace mobirt::detail {

tbb::task_arena& parallel_arena(unsigned threads) {
  static std::mutex mutex;
  // Never destroyed: no exit-time destructor can race a loop still running on another thread.
  static auto* arenas = new std::map<unsigned, std::unique_ptr<tbb::task_arena>>();
  const std::lock_guard<std::mutex> lock(mutex);
  std::unique_ptr<tbb::task_arena>& arena = (*arenas)[threads];
  if (!arena) arena = std::make_unique<tbb::task_arena>(int(threads));
  return *arena;
}

}  // namespace mobirt::detail
