#include "core/thread_priority.h"

#if defined(__linux__)
#include <pthread.h>
#include <sched.h>
#endif

namespace mobirt {

bool lower_to_idle_priority() {
#if defined(__linux__) && defined(SCHED_IDLE)
  sched_param param{};
  param.sched_priority = 0;  // the only priority SCHED_IDLE takes
  return pthread_setschedparam(pthread_self(), SCHED_IDLE, &param) == 0 && runs_at_idle_priority();
#else
  return false;
#endif
}

bool runs_at_idle_priority() {
#if defined(__linux__) && defined(SCHED_IDLE)
  int policy = 0;
  sched_param param{};
  return pthread_getschedparam(pthread_self(), &policy, &param) == 0 && policy == SCHED_IDLE;
#else
  return false;
#endif
}

}  // namespace mobirt
