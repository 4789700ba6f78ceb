#include "backend/driver_threads.h"

#if defined(__linux__)
#include <sched.h>
#include <sys/types.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#endif

namespace mobirt {

std::vector<int> allowed_cpus() {
  std::vector<int> cpus;
#if defined(__linux__)
  cpu_set_t allowed;
  CPU_ZERO(&allowed);
  if (sched_getaffinity(0, sizeof allowed, &allowed) != 0) return cpus;
  for (int c = 0; c < CPU_SETSIZE; ++c) {
    if (CPU_ISSET(c, &allowed)) cpus.push_back(c);
  }
#endif
  return cpus;
}

int pin_driver_threads() {
#if defined(__linux__)
  const std::vector<int> cpus = allowed_cpus();
  if (cpus.size() < 2) return 0;
  static constexpr char kPrefix[] = "llvmpipe-";  // mesa/src/gallium/drivers/llvmpipe/lp_rast.c
  int pinned = 0;
  std::error_code error;
  for (const auto& task : std::filesystem::directory_iterator("/proc/self/task", error)) {
    std::ifstream comm(task.path() / "comm");
    std::string name;
    if (!std::getline(comm, name) || name.rfind(kPrefix, 0) != 0) continue;
    char* end = nullptr;
    const long n = std::strtol(name.c_str() + sizeof kPrefix - 1, &end, 10);
    if (end == name.c_str() + sizeof kPrefix - 1 || *end != '\0' || n < 0) continue;
    const pid_t tid = pid_t(std::strtol(task.path().filename().c_str(), nullptr, 10));
    cpu_set_t one;
    CPU_ZERO(&one);
    CPU_SET(cpus[size_t(n) % cpus.size()], &one);
    if (sched_setaffinity(tid, sizeof one, &one) == 0) ++pinned;  // a thread that just ended is skipped
  }
  return pinned;
#else
  return 0;
#endif
}

}  // namespace mobirt
