#!/usr/bin/env bash
# The speed-for-accuracy sweep: every knob that exists, one at a time from the defaults, over the
# project's scenes, each run through `mobirt accuracy` (the GPU renderer against the
# double-precision reference tracer). Writes OUT/accuracy.csv, OUT/accuracy.md (a table per
# scene: time, PSNR, max error, hit mismatch) and, when python3 can import matplotlib, a Pareto
# plot per scene (OUT/pareto_SCENE.png: frame time against error).
#
#   tools/accuracy_sweep.sh [OUT] [--quick]       (default OUT: build/accuracy)
#
# MOBIRT: the mobirt binary (default build/mobirt). SCENES: the scenes to sweep (default: the
# project's four). --quick sweeps fewer values (for a smoke run).
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
mkdir -p "$OUT"
CSV="$OUT/accuracy.csv"
rm -f "$CSV"

if ((QUICK)); then
  KNOBS=("defaults:" "--bins:4" "--stack:0" "--epsilon:1e-6" "--depth:0")
else
  KNOBS=("defaults:"
         "--bins:4" "--bins:8" "--bins:128"
         "--max-depth:4" "--max-depth:10"
         "--leaf-size:4" "--leaf-size:16"
         "--stack:0" "--stack:1" "--stack:16"
         "--epsilon:1e-6" "--epsilon:1e-5" "--epsilon:1e-3"
         "--depth:0" "--depth:1" "--depth:3"
         "--size:half")
fi

for scene in $SCENES; do
  name=$(basename "$scene" .gltf)
  size=400x240
  half=200x120
  if [ "$name" = marbles ]; then size=240x400; half=120x200; fi
  for knob in "${KNOBS[@]}"; do
    opt=${knob%%:*}
    val=${knob#*:}
    args=(--size "$size")
    label="defaults"
    if [ "$opt" = "--size" ]; then
      args=(--size "$half"); label="--size $half"
    elif [ "$opt" != defaults ]; then
      args+=("$opt" "$val"); label="$opt $val"
    fi
    echo "sweep: $name $label" >&2
    "$MOBIRT" accuracy "$scene" "${args[@]}" --repeat 3 --csv "$CSV" --label "$label" >/dev/null
  done
done

# The markdown table, one section per scene.
MD="$OUT/accuracy.md"
{
  echo "Command: \`tools/accuracy_sweep.sh $*\` ($(date -u +%Y-%m-%d), $("$MOBIRT" info | sed -n 's/^device: *//p'))"
  echo
  awk -F, 'NR > 1 {
      if ($2 != scene) {
        scene = $2
        printf "\n### %s (%s)\n\n| setting | frame ms | PSNR dB | max error | > 2/255 | hit mismatch | shadow mismatch |\n|---|---:|---:|---:|---:|---:|---:|\n", $2, $3
      }
      printf "| %s | %.1f | %.2f | %.1f/255 | %.3f%% | %.3f%% | %.3f%% |\n", $1, $10, $11, $12 * 255, 100 * $13, 100 * $14, 100 * $15
    }' "$CSV"
} >"$MD"
cat "$MD"

if python3 -c 'import matplotlib' 2>/dev/null; then
  python3 - "$CSV" "$OUT" <<'PY'
import csv, sys, collections
import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt
rows = collections.defaultdict(list)
for r in csv.DictReader(open(sys.argv[1])):
    rows[r["scene"]].append(r)
for scene, rs in rows.items():
    fig, ax = plt.subplots(figsize=(6, 4))
    pts = [(float(r["frame_ms"]), float(r["psnr_db"]), r["label"]) for r in rs]
    for t, p, l in pts:
        ax.scatter(t, p)
        ax.annotate(l, (t, p), fontsize=6)
    front = []
    for t, p, l in sorted(pts):
        if not front or p > front[-1][1]:
            front.append((t, p))
    ax.plot([f[0] for f in front], [f[1] for f in front], "k--", lw=0.8)
    ax.set_xlabel("frame time (ms)")
    ax.set_ylabel("PSNR against the reference (dB)")
    ax.set_title(scene)
    name = scene.rsplit("/", 1)[-1].rsplit(".", 1)[0]
    fig.tight_layout()
    fig.savefig(f"{sys.argv[2]}/pareto_{name}.png", dpi=120)
PY
  echo "sweep: Pareto plots in $OUT/pareto_*.png" >&2
else
  echo "sweep: python3 cannot import matplotlib: no Pareto plot (the CSV has the numbers)" >&2
fi
