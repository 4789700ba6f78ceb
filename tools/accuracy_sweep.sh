#!/usr/bin/env bash
# The speed-for-accuracy sweep: every knob, one at a time from the defaults (and two combinations),
# over the project's scenes, each run through `mobirt accuracy` (the GPU renderer against the
# double-precision reference tracer). Writes OUT/accuracy.csv, then tools/accuracy_report.py
# writes OUT/accuracy.md (a table per scene: time, PSNR, max error, hit mismatch, Pareto front)
# and a Pareto plot per scene (OUT/pareto_SCENE.png: frame time against error) when python3 can
# import matplotlib.
#
#   tools/accuracy_sweep.sh [OUT] [--quick]       (default OUT: build/accuracy)
#
# MOBIRT: the mobirt binary (default build/mobirt). SCENES: the scenes to sweep (default: the
# project's four). REPEAT: frames timed per setting (default 5). ROUNDS: times the whole sweep is
# run (default 1); on a machine shared with other work, 2 rounds minutes apart let the report keep
# each setting's fastest frame over both. --quick sweeps a few settings (a smoke run). One round
# takes about 5 minutes on 2 cores.
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=build/accuracy
QUICK=0
for a in "$@"; do
  case "$a" in
    --quick) QUICK=1 ;;
    *) OUT="$a" ;;
  esac
done
MOBIRT=${MOBIRT:-build/mobirt}
SCENES=${SCENES:-"scenes/default.gltf scenes/toaster.gltf scenes/marbles.gltf scenes/fish.gltf"}
REPEAT=${REPEAT:-5}
ROUNDS=${ROUNDS:-1}
mkdir -p "$OUT"
CSV="$OUT/accuracy.csv"
rm -f "$CSV"

# label|options. SIZE, HALF and DOUBLE stand for the scene's resolution, half and twice it. Every
# run traces its primary rays (--primary trace, PRIMARY below), so that the knobs act on every ray
# as in the paper's passes; the --primary raster row is the default's rasterized primaries (the
# default --primary auto rasterizes every project scene at these sizes).
PRIMARY="--primary trace"
if ((QUICK)); then
  SETTINGS=("defaults|" "--intersect watertight|--intersect watertight" "--precision mediump|--precision mediump"
            "--colour 16|--colour 16" "--depth 0|--depth 0" "--primary raster|--primary raster")
else
  SETTINGS=("defaults|"
            "--bins 8|--bins 8" "--bins 128|--bins 128"
            "--max-depth 10|--max-depth 10"
            "--leaf-size 4|--leaf-size 4" "--leaf-size 16|--leaf-size 16"
            "--stack 0|--stack 0" "--stack 1|--stack 1" "--stack 16|--stack 16"
            "--intersect watertight|--intersect watertight"
            "--precision mediump|--precision mediump"
            "--precision mediump --intersect watertight|--precision mediump --intersect watertight"
            "--epsilon 1e-5|--epsilon 1e-5" "--epsilon 1e-3|--epsilon 1e-3"
            "--offset fixed --epsilon 1e-4|--offset fixed --epsilon 1e-4"
            "--offset fixed --epsilon 1e-2|--offset fixed --epsilon 1e-2"
            "--offset normal-ulp|--offset normal-ulp"
            "--colour 16|--colour 16"
            "--colour 16 --intersect watertight|--colour 16 --intersect watertight"
            "--depth 0|--depth 0" "--depth 1|--depth 1" "--depth 3|--depth 3"
            "--size HALF|--size HALF" "--size DOUBLE|--size DOUBLE"
            "--primary raster|--primary raster"
            "defaults (again: timing noise)|")
fi

for round in $(seq "$ROUNDS"); do
for scene in $SCENES; do
  name=$(basename "$scene" .gltf)
  size=400x240 half=200x120 double=800x480
  if [ "$name" = marbles ]; then size=240x400 half=120x200 double=480x800; fi
  for setting in "${SETTINGS[@]}"; do
    label=${setting%%|*}
    options=${setting#*|}
    label=${label/HALF/$half}
    label=${label/DOUBLE/$double}
    options=${options/HALF/$half}
    options=${options/DOUBLE/$double}
    # shellcheck disable=SC2086 # options are words
    if [[ "$options" == *--size* ]]; then args=($options); else args=(--size "$size" $options); fi
    echo "sweep: round $round, $name: $label" >&2
    [[ "$options" == *--primary* ]] || args+=($PRIMARY)
    "$MOBIRT" accuracy "$scene" "${args[@]}" --repeat "$REPEAT" --csv "$CSV" --label "$label" >/dev/null
  done
done
done

DEVICE=$("$MOBIRT" info | sed -n 's/^device: *//p')
# The first python3 that imports matplotlib (a pyenv or venv python3 on PATH may lack Debian's).
PYTHON=python3
for candidate in python3 /usr/bin/python3; do
  if command -v "$candidate" >/dev/null && "$candidate" -c 'import matplotlib' 2>/dev/null; then
    PYTHON=$candidate
    break
  fi
done
"$PYTHON" tools/accuracy_report.py "$CSV" "$OUT" \
  --command "MOBIRT=$MOBIRT REPEAT=$REPEAT ROUNDS=$ROUNDS tools/accuracy_sweep.sh $*" --device "$DEVICE"
