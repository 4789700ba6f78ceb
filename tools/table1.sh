#!/usr/bin/env bash
# A first reading of the MobiRT paper's Table 1 on this machine: frames per second of each scene,
# animation playing, the kd-tree rebuilt every frame (--always-rebuild: static scenes too, as in the paper), for ray casting, + shadows, + 1 and + 2 bounces.
# Median frame time over FRAMES frames (the first, which compiles the shaders, left out).
#   tools/table1.sh [FRAMES]        (default 30; needs build/mobirt)
set -euo pipefail
cd "$(dirname "$0")/.."
FRAMES=${1:-30}
MOBIRT=${MOBIRT:-build/mobirt}
[ -x "$MOBIRT" ] || { echo "table1: $MOBIRT not found: build first (tools/setup.sh)" >&2; exit 2; }
OUT=$(mktemp -d)
trap 'rm -rf "$OUT"' EXIT

fps() {  # scene size extra-args...: prints the median fps
  local scene=$1 size=$2
  shift 2
  "$MOBIRT" render "$scene" --size "$size" --frames "0:$FRAMES" -o "$OUT/f_%04d.png" --timings --always-rebuild "$@" 2>/dev/null |
    awk '/^frame /{gsub(/[()]/, "", $3); print $3}'
}

echo "lavapipe: $("$MOBIRT" info | awk -F': +' '/^device/{print $2}'), LP_NUM_THREADS=${LP_NUM_THREADS:-$(nproc)}"
echo
echo "| scene | size | ray casting | + shadow | + 1 bounce | + 2 bounces |"
echo "|---|---|---|---|---|---|"
row() {
  local name=$1 scene=$2 size=$3
  shift 3
  printf "| %s | %s | %s | %s | %s | %s |\n" "$name" "$size" \
    "$(fps "$scene" "$size" --depth 0 --no-shadows "$@")" \
    "$(fps "$scene" "$size" --depth 0 "$@")" \
    "$(fps "$scene" "$size" --depth 1 "$@")" \
    "$(fps "$scene" "$size" --depth 2 "$@")"
}
row toaster scenes/toaster.gltf 400x240
row marbles scenes/marbles.gltf 240x400
row fish scenes/fish.gltf 400x240
if [ -f ../shared/scenes/utah-toasters/Toasters004.obj ]; then
  row "Utah toasters" ../shared/scenes/utah-toasters/Toasters004.obj 400x240 --mtl scenes/utah-toasters.mtl \
    --camera "0,260,480:0,20,0:0,1,0:40" --light "point pos=150,500,300 intensity=300000"
fi
if [ -d ../shared/scenes/utah-wooddoll ]; then
  row "Utah wood doll" "../shared/scenes/utah-wooddoll/wooddoll_%02d.obj" 400x240 \
    --light "point pos=5,20,20 intensity=400"
fi
