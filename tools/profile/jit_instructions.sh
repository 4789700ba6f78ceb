#!/usr/bin/env bash
# Instructions executed by llvmpipe's JIT-compiled shaders in one frame: a repeatable cost measure
# of the GPU passes on lavapipe (timings on a shared 2-core machine drift by 10-30 %; this does not).
#
#   tools/profile/jit_instructions.sh MOBIRT RENDER-ARGS...
#
# Runs `MOBIRT render RENDER-ARGS --timings --repeat 1` (a warm-up frame and a timed frame) under
# callgrind with LP_NUM_THREADS=0 (rasterisation in the calling thread) and sums the instructions
# executed in code without a file or symbol: the JIT code of the shaders (and nothing else: LLVM,
# Mesa and mobirt all have symbols or a library name). Prints "jit_instructions_per_frame N", half
# the sum, since both frames run the same passes. Takes about a minute for 400x240 rays.
set -euo pipefail
MOBIRT=$1
shift
# KEEP=DIR keeps the callgrind profile (DIR/cg.out) for callgrind_annotate.
if [ -n "${KEEP:-}" ]; then OUT=$KEEP; mkdir -p "$OUT"; else OUT=$(mktemp -d); trap 'rm -rf "$OUT"' EXIT; fi
LP_NUM_THREADS=0 valgrind --tool=callgrind --callgrind-out-file="$OUT/cg.out" \
  "$MOBIRT" render "$@" --timings --repeat 1 >"$OUT/render.txt" 2>"$OUT/valgrind.txt" ||
  { cat "$OUT/valgrind.txt" >&2; exit 1; }
callgrind_annotate --threshold=100 "$OUT/cg.out" 2>/dev/null |
  awk '/\?\?\?:0x[0-9a-f]+ \[\?\?\?\]/ { gsub(",", "", $1); sum += $1 }
       END { printf "jit_instructions_per_frame %.0f\n", sum / 2 }'
