#!/usr/bin/env python3
"""Where a machine's idle time falls: which thread ran on the other CPUs while one CPU idled.

Reads the kernel's sched_switch tracepoint, which records every CPU (`perf sched` recorded only
one on the project's 2-core VM):

  perf record -e sched:sched_switch -a -o /tmp/ss.data -- build/mobirt bench scenes/toaster.gltf \\
      --levels cast --backend vulkan --no-baseline --frames 150 --warmup 3
  perf script -i /tmp/ss.data -F cpu,time,event,trace > /tmp/ss.txt
  tools/profile/sched_idle.py /tmp/ss.txt [--from 0.3] [--to 0.95]

Prints, over a window of the recording (by default from 30 % to 95 % of it, past the start-up),
the share of one CPU each kind of thread ran, and, for the time in which exactly one CPU idled,
which kind of thread the other ran; then the time in which every CPU idled. Kinds: `idle`,
Mesa's rasterizer threads by name (`llvmpipe-N`), `main` (the process's first thread: mobirt's
rendering thread), `short-lived` (threads that lived less than 0.2 s: the frame pipeline's
worker, one per frame), `pool` (other long-lived threads of the process: TBB's), `other`
(everything else on the machine). Made for 2 CPUs; with more, "one CPU idle" means any one.
The tracepoint view counts more idle time than /proc/stat does on that VM: compare shares.
"""
import argparse
import collections
import re
import sys

LINE = re.compile(r"\s*\[(\d+)\]\s+([\d.]+):\s+sched:sched_switch:\s+prev_comm=(.*?) prev_pid=(-?\d+) .*?"
                  r" ==> next_comm=(.*?) next_pid=(-?\d+)")


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("trace", help="perf script output (-F cpu,time,event,trace)")
    parser.add_argument("--from", dest="start", type=float, default=0.3, help="window start, share of the recording")
    parser.add_argument("--to", dest="end", type=float, default=0.95, help="window end, share of the recording")
    parser.add_argument("--process", default="mobirt", help="the traced process's thread name")
    args = parser.parse_args()

    events = []
    for line in open(args.trace):
        m = LINE.match(line)
        if m:
            events.append((float(m[2]), int(m[1]), m[3], int(m[4]), m[5], int(m[6])))
    if not events:
        sys.exit(f"{args.trace}: no sched_switch events")
    events.sort()
    first, last, name = {}, {}, {}
    for t, _, prev_comm, prev_pid, next_comm, next_pid in events:
        for comm, pid in ((prev_comm, prev_pid), (next_comm, next_pid)):
            first.setdefault(pid, t)
            last[pid] = t
            name[pid] = comm
    ours = [pid for pid, comm in name.items() if comm.startswith(args.process) and pid > 0]
    if not ours:
        sys.exit(f"{args.trace}: no thread named {args.process}")
    main_pid = min(ours)

    def kind(pid):
        comm = name.get(pid, "?")
        if pid == 0:
            return "idle"
        if comm.startswith("llvmpipe"):
            return comm
        if pid == main_pid:
            return "main"
        if comm.startswith(args.process):
            return "short-lived" if last[pid] - first[pid] < 0.2 else "pool"
        return "other"

    t0, t1 = events[0][0], events[-1][0]
    w0, w1 = t0 + args.start * (t1 - t0), t0 + args.end * (t1 - t0)
    cpus = sorted({e[1] for e in events})
    running = {}
    ran = collections.Counter()
    beside_idle = collections.Counter()
    all_idle = 0.0
    prev = None
    for t, cpu, _, _, _, next_pid in events:
        if prev is not None and len(running) == len(cpus):
            a, b = max(prev, w0), min(t, w1)
            if b > a:
                kinds = [kind(running[c]) for c in cpus]
                for k in kinds:
                    ran[k] += b - a
                idle = kinds.count("idle")
                if idle == len(cpus):
                    all_idle += b - a
                elif idle == 1:
                    for k in kinds:
                        if k != "idle":
                            beside_idle[k] += (b - a) / (len(cpus) - 1)
        running[cpu] = next_pid
        prev = t
    span = w1 - w0
    print(f"window {span:.2f} s of {t1 - t0:.2f} s, {len(cpus)} CPUs")
    print("share of one CPU each kind of thread ran:")
    for k, v in ran.most_common():
        print(f"  {k:<14} {100 * v / span:6.1f} %")
    total = sum(beside_idle.values())
    print("while one CPU idled, the others ran (share of that time):")
    for k, v in beside_idle.most_common():
        print(f"  {k:<14} {100 * v / total if total else 0:6.1f} %")
    print(f"every CPU idle: {100 * all_idle / span:.1f} % of the window")


if __name__ == "__main__":
    main()
