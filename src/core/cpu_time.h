// CPU time on POSIX clocks, to tell a thread's work from its waiting (milliseconds).
#pragma once

#include <time.h>

namespace mobirt {

inline double cpu_clock_ms(clockid_t clock) {
  timespec t{};
  clock_gettime(clock, &t);
  return double(t.tv_sec) * 1e3 + double(t.tv_nsec) * 1e-6;
}

inline double thread_cpu_ms() { return cpu_clock_ms(CLOCK_THREAD_CPUTIME_ID); }
inline double process_cpu_ms() { return cpu_clock_ms(CLOCK_PROCESS_CPUTIME_ID); }

}  // namespace mobirt
