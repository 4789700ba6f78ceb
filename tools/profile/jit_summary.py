#!/usr/bin/env python3
"""Summary of llvmpipe JIT code dumped by jit_dump.sh: every sampled code mapping with its share
of the samples, then the functions and loops of each mapping that holds 5 % of them or more (or,
without samples, of the biggest one), with instruction counts, calls, stack spills and perf sample
shares. With samples the texel-fetch functions (small mappings of their own, called from the
shaders) and the shader bodies are told apart: on the fish at 2 bounces the fetch functions held
42 % of the samples (docs/performance-history.md, Session 47).

  tools/profile/jit_summary.py DIR      (DIR/jit_START.bin, optional DIR/ips.txt)

Writes DIR/jit_START.s (objdump) for each mapping it summarises. A loop is a backward jump over
more than 300 bytes (smaller ones are per-lane scalar loops inside a vector operation).
"""
import collections
import glob
import os
import re
import subprocess
import sys


def disassemble(path, start):
    out = subprocess.run(["objdump", "-D", "-b", "binary", "-mi386:x86-64", f"--adjust-vma={start:#x}", path],
                         check=True, capture_output=True, text=True).stdout
    insns = []
    for line in out.splitlines():
        m = re.match(r"\s*([0-9a-f]+):\s+((?:[0-9a-f]{2} )+)\s*\t?(.*)", line)
        if m and m.group(3):
            insns.append((int(m.group(1), 16), m.group(3).strip()))
    return out, insns


def main():
    d = sys.argv[1]
    samples = collections.Counter()
    if os.path.exists(os.path.join(d, "ips.txt")):
        for line in open(os.path.join(d, "ips.txt")):
            try:
                samples[int(line.split()[0], 16)] += 1
            except (ValueError, IndexError):
                pass
    maps = []
    for f in glob.glob(os.path.join(d, "jit_*.bin")):
        start = int(os.path.basename(f)[4:-4], 16)
        size = os.path.getsize(f)
        hits = sum(n for a, n in samples.items() if start <= a < start + size)
        maps.append((hits, size, start, f))
    if not maps:
        sys.exit("jit_summary: no jit_*.bin in " + d)
    total = sum(samples.values())
    if total:
        sampled = [m for m in sorted(maps, reverse=True) if m[0]]  # the most samples first
        print(f"sampled mappings: start, bytes, samples, % of {total}")
        for hits, size, start, path in sampled:
            print(f"  {start:#x} {size:9d} {hits:6d} {100.0 * hits / total:6.1f}")
        chosen = [m for m in sampled if 100.0 * m[0] / total >= 5.0]
    else:
        # Without samples, the biggest mapping below 1 MiB (the shader code; bigger anonymous
        # executable mappings are allocator arenas).
        chosen = [max(maps, key=lambda m: m[1] if m[1] < (1 << 20) else 0)]
    for hits, size, start, path in chosen:
        summarise(samples, total, hits, size, start, path)


def summarise(samples, total, hits, size, start, path):
    text, insns = disassemble(path, start)
    with open(path[:-4] + ".s", "w") as f:
        f.write(text)

    def share(lo, hi):
        return 100.0 * sum(n for a, n in samples.items() if lo <= a <= hi) / (total or 1)

    print(f"mapping {start:#x}, {size} bytes, {len(insns)} instructions, {hits} of {total} samples")
    print("functions: start, instructions, calls, samples %")
    first = 0
    for i, (a, t) in enumerate(insns):
        if t.startswith("ret"):
            body = insns[first:i + 1]
            calls = sum(x[1].startswith("call") for x in body)
            if len(body) > 20:
                print(f"  {insns[first][0]:#x} {len(body):6d} {calls:4d} {share(insns[first][0], a):6.1f}")
            first = i + 1
    print("loops: head, tail, instructions, calls, spill/reload (rsp), samples %")
    for a, t in insns:
        m = re.match(r"j[a-z]+\s+0x([0-9a-f]+)", t)
        if m:
            head = int(m.group(1), 16)
            if head < a and a - head > 300:
                body = [x for x in insns if head <= x[0] <= a]
                print(f"  {head:#x} {a:#x} {len(body):6d} {sum(x[1].startswith('call') for x in body):4d} "
                      f"{sum('rsp' in x[1] for x in body):5d} {share(head, a):6.1f}")


if __name__ == "__main__":
    main()
