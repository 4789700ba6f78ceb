#!/usr/bin/env bash
# Everything tools/profile/ measures, into one folder, in bounded time (about 8 minutes on 2 cores;
# the parameter sweeps stop starting runs after SWEEP_BUDGET seconds, default 360).
#
#   tools/profile/profile.sh OUT [--callgrind]
#
# OUT/spirv.csv        static SPIR-V instructions per shader variant          (spirv_counts.py)
# OUT/simd_SCENE.csv   SIMD lane occupancy of the traversal loops per ray generation
#                      (mobirt_simd_stats)
# OUT/sweep.csv        per-pass times against stack depth, bins, resolution, light count, bounce
#                      depth, LP_NUM_THREADS and the loop cap, per scene        (sweep.py)
# OUT/jit.txt          with --callgrind: instructions executed by the JIT-compiled shaders per frame
#                      (jit_instructions.sh, about a minute per scene)
# OUT/*.png            plots of the above                                        (plot.py)
# OUT/machine.txt      the machine and driver the numbers come from
#
# Needs build/mobirt and build/mobirt_simd_stats (cmake --build build --target mobirt
# mobirt_simd_stats), glslangValidator, spirv-opt, spirv-dis; matplotlib for the plots; valgrind
# for --callgrind. MOBIRT=... and SIMD_STATS=... point at other builds.
set -euo pipefail
HERE=$(cd "$(dirname "$0")" && pwd)
ROOT=$(cd "$HERE/../.." && pwd)
OUT=${1:?usage: tools/profile/profile.sh OUT [--callgrind]}
CALLGRIND=${2:-}
MOBIRT=${MOBIRT:-$ROOT/build/mobirt}
SIMD_STATS=${SIMD_STATS:-$ROOT/build/mobirt_simd_stats}
SHARED=${MOBIRT_SHARED_SCENES:-$ROOT/../../shared/scenes}
[ -d "$SHARED" ] || SHARED=$ROOT/../shared/scenes
UTAH=$SHARED/utah-toasters/Toasters004.obj
UTAH_VIEW=(--camera "0,260,480:0,20,0:0,1,0:40" --light "point pos=150,500,300 intensity=300000")
for tool in "$MOBIRT" "$SIMD_STATS"; do
  [ -x "$tool" ] || { echo "profile: $tool not found: cmake --build build --target mobirt mobirt_simd_stats" >&2; exit 2; }
done
mkdir -p "$OUT"
# A python with matplotlib (Debian's python3-matplotlib lives in /usr/bin/python3).
PLOT_PY=
for py in python3 /usr/bin/python3; do
  if "$py" -c 'import matplotlib' 2>/dev/null; then PLOT_PY=$py; break; fi
done

{
  echo "date: $(date -u +%Y-%m-%dT%H:%MZ)"
  echo "commit: $(git -C "$ROOT" rev-parse --short HEAD 2>/dev/null || echo unknown)"
  echo "cpu: $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2-) x $(nproc)"
  echo "load: $(cut -d' ' -f1-3 /proc/loadavg)"
  "$MOBIRT" info | grep -E '^(device|driver)'
} >"$OUT/machine.txt"
cat "$OUT/machine.txt"

echo "== SPIR-V instruction counts"
python3 "$HERE/spirv_counts.py" "$OUT/spirv.csv" >/dev/null

echo "== SIMD occupancy (CPU replay of the traversal)"
if [ -f "$UTAH" ]; then
  "$SIMD_STATS" "$UTAH" "${UTAH_VIEW[@]}" --csv "$OUT/simd_utah.csv" 2>/dev/null
fi
"$SIMD_STATS" "$ROOT/scenes/toaster.gltf" --depth 2 --csv "$OUT/simd_toaster.csv"
"$SIMD_STATS" "$ROOT/scenes/fish.gltf" --depth 2 --csv "$OUT/simd_fish.csv"

echo "== parameter sweeps"
python3 "$HERE/sweep.py" "$OUT/sweep.csv" --mobirt "$MOBIRT" --budget "${SWEEP_BUDGET:-360}"

if [ "$CALLGRIND" = "--callgrind" ]; then
  echo "== JIT instructions per frame (callgrind)"
  : >"$OUT/jit.txt"
  if [ -f "$UTAH" ]; then
    echo "utah $("$HERE/jit_instructions.sh" "$MOBIRT" "$UTAH" -o "$OUT/jit.png" --depth 0 "${UTAH_VIEW[@]}")" | tee -a "$OUT/jit.txt"
  fi
  echo "toaster $("$HERE/jit_instructions.sh" "$MOBIRT" "$ROOT/scenes/toaster.gltf" -o "$OUT/jit.png")" | tee -a "$OUT/jit.txt"
  rm -f "$OUT/jit.png"
fi

if [ -n "$PLOT_PY" ]; then
  echo "== plots"
  "$PLOT_PY" "$HERE/plot.py" "$OUT"
else
  echo "profile: no python with matplotlib (apt-get install python3-matplotlib): no plots" >&2
fi
