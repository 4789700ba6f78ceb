// Mesa's software rasterizer threads (lavapipe's and llvmpipe's alike, named "llvmpipe-N") pinned
// one per CPU.
//
// Why: each pass wakes those threads, and the Linux scheduler places a woken thread by the recent
// load of each CPU, not by what runs there now. When the rendering thread has just kept one CPU
// busy (in mobirt bench: the Embree column's frame), both rasterizer threads can wake on the other
// CPU and share it for the whole pass while the first CPU idles: perf sched showed llvmpipe-0 and
// llvmpipe-1 taking turns on CPU 1 through a shading pass while the rendering thread slept on
// CPU 0. Their CPU time was the same as in a run without Embree; their wall time was not
// (toaster ray casting, serial, Embree interleaved: traversal 8.2-9.1 -> 7.2-7.3 ms, shading
// 2.9-3.3 -> 1.8-2.0 ms; README, *Driver threads pinned*). llvmpipe hands out a pass's tiles to
// whichever thread asks next, so a thread on a busier CPU simply takes fewer of them.
#pragma once

#include <vector>

namespace mobirt {

// The CPUs this process may run on (its own CPU set: a cpuset or taskset, not the machine's
// count), in increasing order; empty off Linux or when the set cannot be read.
std::vector<int> allowed_cpus();

// Pins every thread of this process named "llvmpipe-N" to the (N mod count)-th CPU of the
// process's own CPU set (so a cpuset or taskset still holds). Threads pinned by an earlier call
// are pinned again to the same CPU, so it is safe to call after every device or context is made.
// Returns how many threads it pinned: 0 off Linux, on a single CPU, or without Mesa's threads
// (a hardware driver).
int pin_driver_threads();

}  // namespace mobirt
