// The calling thread's scheduling class: a thread that should run only where a CPU would idle.
#pragma once

namespace mobirt {

// Moves the calling thread to Linux's SCHED_IDLE class: it runs only on a CPU that no thread of a
// normal class wants, and a normal thread that wakes takes its CPU at once. Any thread may lower
// itself so, without privileges; it cannot come back (that needs CAP_SYS_NICE), so call it only on
// a thread that keeps the class for its life. Returns whether the thread now runs at SCHED_IDLE
// (false off Linux or where the call was refused).
bool lower_to_idle_priority();

// Whether the calling thread runs at SCHED_IDLE.
bool runs_at_idle_priority();

}  // namespace mobirt
