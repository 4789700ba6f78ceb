#!/usr/bin/env bash
# Where --primary auto's rule comes from: the frame with the primary hits traced against rasterized,
# ray casting with shadows, the tree kept (a still scene, so the primary hits are the only
# difference), interleaved, two rounds, median of 5 frames each, at several triangles per pixel.
# Usage: tools/profile/primary_crossover.sh [MOBIRT]   (default build/mobirt; the SPD sphereflake
# is read from ../shared/scenes and skipped where it is absent)
set -euo pipefail
cd "$(dirname "$0")/../.."
mobirt=${1:-build/mobirt}
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
run() {  # LABEL SCENE-ARGS...
  local label=$1; shift
  for round in 1 2; do
    for p in trace raster; do
      t=$("$mobirt" render "$@" -o "$out/o.png" --depth 0 --timings --repeat 5 --primary "$p" 2>&1)
      echo "$label round $round $p: frame $(echo "$t" | awk '/^frame/{print $2}') ms," \
           "traversal passes $(echo "$t" | awk '/^traversal passes/{print $3}') ms," \
           "upload $(echo "$t" | awk '/^upload/{print $2}') ms"
    done
  done
}
for s in 400x240 200x120 140x84 100x60; do run "toaster $s" scenes/toaster.gltf --size "$s"; done
balls=../shared/scenes/spd/balls_s2.nff
if [ -f "$balls" ]; then
  for s in 1200x720 800x480 560x336 400x240; do run "balls_s2 tessellated $s" "$balls" --primitives tessellated --size "$s"; done
else
  echo "skipped balls_s2: $balls is absent" >&2
fi
