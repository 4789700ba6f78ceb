// A minimal parallel loop for the CPU stages of a frame (hit decoding, the CPU ray engines).
#pragma once

#include <algorithm>
#include <atomic>
#include <cstdint>
#include <exception>
#include <mutex>
#include <thread>
#include <vector>

namespace mobirt {

// Runs f(i) for every i in [0, n) on `threads` threads (0 = all cores), the calling thread
// included, in chunks of `chunk` taken in turn: rays differ a lot in cost, so a static split
// would leave a thread idle. The first exception thrown by f stops the loop and is rethrown here.
template <class F>
void parallel_for(uint32_t n, unsigned threads, F&& f, uint32_t chunk = 64) {
  if (threads == 0) threads = std::max(1u, std::thread::hardware_concurrency());
  threads = std::min<unsigned>(threads, (n + chunk - 1) / std::max(chunk, 1u));
  if (threads <= 1) {
    for (uint32_t i = 0; i < n; ++i) f(i);
    return;
  }
  // The shared chunk counter in a cache line of its own. Both threads add to it once a chunk;
  // beside the caller's other stack slots, every add took the line away from the caller's hot
  // locals (its spills in f's loop), and whether they shared a line depended on where the stack
  // happened to start: in about a third of mobirt bench runs, for the whole run, the CPU columns'
  // shading or Embree's closest-hit loop ran at half speed (perf annotate: 85 % of the shading
  // loop's own samples on two stack loads and stores).
  struct alignas(64) Counter {
    std::atomic<uint32_t> value{0};
  };
  Counter counter;
  std::atomic<uint32_t>& next = counter.value;
  std::exception_ptr error;
  std::mutex error_mutex;
  auto work = [&] {
    try {
      for (uint32_t begin; (begin = next.fetch_add(chunk)) < n;) {
        const uint32_t end = std::min(n, begin + chunk);
        for (uint32_t i = begin; i < end; ++i) f(i);
      }
    } catch (...) {
      next.store(n);  // the others stop at their next chunk
      const std::lock_guard<std::mutex> lock(error_mutex);
      if (!error) error = std::current_exception();
    }
  };
  std::vector<std::thread> pool;
  pool.reserve(threads - 1);
  for (unsigned t = 1; t < threads; ++t) pool.emplace_back(work);
  work();
  for (std::thread& t : pool) t.join();
  if (error) std::rethrow_exception(error);
}

}  // namespace mobirt
