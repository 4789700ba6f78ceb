#!/usr/bin/env bash
# The machine code llvmpipe generated for the shaders of a `mobirt render`, with the loops and
# texture functions it contains, and optionally where the time goes (perf samples).
#
#   tools/profile/jit_dump.sh OUT MOBIRT RENDER-ARGS...      (SAMPLE=1 for perf samples)
#
# Debian's Mesa is a release build: GALLIVM_DEBUG=asm/ir and LP_DEBUG are compiled out, and the
# JIT code has no symbols for perf. So the render runs under gdb, stopped where it writes the image (the passes still exist), and every
# anonymous executable mapping (the JIT code) is dumped and disassembled (objdump) into OUT/; with
# SAMPLE=1 a second render (--repeat 200) is sampled by perf while gdb dumps its code at the end,
# so samples and code come from the same process. OUT/summary.txt lists every sampled mapping's
# share (the texel-fetch functions are small mappings of their own), then, for each mapping with 5 %
# of the samples or more (without samples: the biggest), its functions and its loops: instructions,
# calls, stack spill/reload instructions, share of samples.
set -euo pipefail
OUT=${1:?usage: tools/profile/jit_dump.sh OUT MOBIRT RENDER-ARGS...}
MOBIRT=${2:?usage: tools/profile/jit_dump.sh OUT MOBIRT RENDER-ARGS...}
shift 2
# gdb runs the program by its absolute path, which pgrep must match below.
MOBIRT=$(realpath "$MOBIRT")
mkdir -p "$OUT"
HERE=$(cd "$(dirname "$0")" && pwd)
# Dumps every executable anonymous mapping of the inferior into $OUT/jit_START.bin.
cat >"$OUT/dump.py" <<EOF
import gdb, os
pid = gdb.selected_inferior().pid
for line in open(f"/proc/{pid}/maps"):
    f = line.split()
    if "x" in f[1] and len(f) < 6:
        start, end = f[0].split("-")
        gdb.execute(f"dump binary memory $OUT/jit_{start}.bin 0x{start} 0x{end}")
EOF
rm -f "$OUT"/jit_*.bin "$OUT/ips.txt"
if [ "${SAMPLE:-0}" = 1 ]; then
  # gdb starts the render, perf samples it (by pid) for 4 s once it runs, gdb dumps at exit.
  gdb -q -batch -ex "set pagination off" -ex "break mobirt::write_image" -ex "run" -ex "source $OUT/dump.py" \
    --args "$MOBIRT" render "$@" --timings --repeat 200 >"$OUT/gdb.txt" 2>&1 &
  GDB=$!
  sleep 6
  PID=$(pgrep -n -f "^$MOBIRT render" || true)
  [ -n "$PID" ] && perf record -F 1999 -p "$PID" -o "$OUT/perf.data" -- sleep 4 >/dev/null 2>&1 || true
  wait $GDB || true
  perf script -i "$OUT/perf.data" -F ip,dso 2>/dev/null | awk '/perf-|JIT/ {print $1}' >"$OUT/ips.txt" || true
else
  gdb -q -batch -ex "set pagination off" -ex "break mobirt::write_image" -ex "run" -ex "source $OUT/dump.py" \
    --args "$MOBIRT" render "$@" >"$OUT/gdb.txt" 2>&1
fi
python3 "$HERE/jit_summary.py" "$OUT" | tee "$OUT/summary.txt"
