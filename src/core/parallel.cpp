#include "core/parallel.h"

#include <map>
#include <memory>
#include <mutex>

namespace mobirt::detail {

tbb::task_arena& parallel_arena(unsigned threads) {
  static std::mutex mutex;
  static std::map<unsigned, std::unique_ptr<tbb::task_arena>> arenas;
  const std::lock_guard<std::mutex> lock(mutex);
  std::unique_ptr<tbb::task_arena>& arena = arenas[threads];
  if (!arena) arena = std::make_unique<tbb::task_arena>(int(threads));
  return *arena;
}

}  // namespace mobirt::detail
