// A minimal parallel loop for the CPU stages of a frame (hit decoding, the CPU ray engines).
#pragma once

#include <algorithm>
#include <atomic>
#include <cstdint>
#include <exception>
#include <mutex>
#include <thread>
#include <vector>

#if defined(__linux__)
#include <sched.h>
#endif

namespace mobirt {

namespace detail {

#if defined(__linux__)
// The CPUs this process may run on (its affinity mask at first use), in increasing order.
inline const std::vector<int>& process_cpus() {
  static const std::vector<int> cpus = [] {
    std::vector<int> list;
    cpu_set_t allowed;
    CPU_ZERO(&allowed);
    if (sched_getaffinity(0, sizeof allowed, &allowed) == 0) {
      for (int c = 0; c < CPU_SETSIZE; ++c) {
        if (CPU_ISSET(c, &allowed)) list.push_back(c);
      }
    }
    return list;
  }();
  return cpus;
}
#endif

// The CPU parallel_for's k-th thread (k >= 1) starts on: the k-th after the caller's in the
// process's CPU set; -1 when there is no choice to make (one CPU, not Linux).
inline int worker_cpu(unsigned k) {
#if defined(__linux__)
  const std::vector<int>& cpus = process_cpus();
  const int here = sched_getcpu();
  if (cpus.size() < 2 || here < 0) return -1;
  const auto mine = std::find(cpus.begin(), cpus.end(), here);
  if (mine == cpus.end()) return -1;
  return cpus[(size_t(mine - cpus.begin()) + k) % cpus.size()];
#else
  (void)k;
  return -1;
#endif
}

// Run by a new thread of parallel_for: moves it to `cpu`, then lets it run on any CPU of the
// process again (it stays where it is unless the load balancer moves it). Linux places a new
// thread by each CPU's recent load, not by what runs there now: on 2 cores it could put a loop's
// second thread on the caller's CPU, where the two then ran in turn while the other CPU idled
// (in mobirt bench, the Embree column's CPU shading ran 9.5-15.6 ms instead of 5.2-8.6 ms in
// 4 of 8 runs, for a whole run).
inline void start_on(int cpu) {
#if defined(__linux__)
  if (cpu < 0) return;
  cpu_set_t one;
  CPU_ZERO(&one);
  CPU_SET(cpu, &one);
  if (sched_setaffinity(0, sizeof one, &one) != 0) return;
  cpu_set_t all;
  CPU_ZERO(&all);
  for (const int c : process_cpus()) CPU_SET(c, &all);
  sched_setaffinity(0, sizeof all, &all);
#else
  (void)cpu;
#endif
}

}  // namespace detail

// Runs f(i) for every i in [0, n) on `threads` threads (0 = all cores), the calling thread
// included, in chunks of `chunk` taken in turn: rays differ a lot in cost, so a static split
// would leave a thread idle. Each new thread starts on a CPU other than the caller's
// (detail::start_on). The first exception thrown by f stops the loop and is rethrown here.
template <class F>
void parallel_for(uint32_t n, unsigned threads, F&& f, uint32_t chunk = 64) {
  if (threads == 0) threads = std::max(1u, std::thread::hardware_concurrency());
  threads = std::min<unsigned>(threads, (n + chunk - 1) / std::max(chunk, 1u));
  if (threads <= 1) {
    for (uint32_t i = 0; i < n; ++i) f(i);
    return;
  }
  std::atomic<uint32_t> next{0};
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
  for (unsigned t = 1; t < threads; ++t) {
    pool.emplace_back([&work, cpu = detail::worker_cpu(t)] {
      detail::start_on(cpu);  // a CPU other than the caller's
      work();
    });
  }
  work();
  for (std::thread& t : pool) t.join();
  if (error) std::rethrow_exception(error);
}

}  // namespace mobirt
