#!/usr/bin/env bash
# Vulkan against OpenGL ES 2.0, per project scene, at ray casting and at + 2 bounces: the frame
# time and each stage, both backends in one run of this script (median of FRAMES frames each).
#   tools/backends.sh [FRAMES]     (default 10; needs build/mobirt)
# GLES pass times are CPU time around glFinish (llvmpipe has no timer queries); Vulkan's are
# timestamp queries.
set -euo pipefail
cd "$(dirname "$0")/.."
FRAMES=${1:-10}
MOBIRT=${MOBIRT:-build/mobirt}
[ -x "$MOBIRT" ] || { echo "backends: $MOBIRT not found: build first (tools/setup.sh)" >&2; exit 2; }
WORK=$(mktemp -d)
trap 'rm -rf "$WORK"' EXIT

stage() {  # the timings text, a stage name: its milliseconds
  awk -v name="$2" 'index($0, name) == 1 { for (i = 1; i <= NF; ++i) if ($i ~ /^[0-9.]+$/) { print $i; exit } }' <<<"$1"
}
echo "| scene | depth | backend | build | upload | traversal | read-back | decoding | shading | secondary | frame ms |"
echo "|---|---|---|---|---|---|---|---|---|---|---|"
for entry in default:400x240 toaster:400x240 marbles:240x400 fish:400x240; do
  name=${entry%%:*}
  size=${entry##*:}
  for depth in 0 2; do
    for backend in vulkan gles; do
      t=$("$MOBIRT" render "scenes/$name.gltf" --size "$size" --depth "$depth" --backend "$backend" \
            --always-rebuild --timings --repeat "$FRAMES" -o "$WORK/x.png" 2>/dev/null)
      printf "| %s | %s | %s | %s | %s | %s | %s | %s | %s | %s | %s |\n" "$name" "$depth" "$backend" \
        "$(stage "$t" "kd-tree build")" "$(stage "$t" "upload")" "$(stage "$t" "traversal passes")" \
        "$(stage "$t" "read-back")" "$(stage "$t" "hit decoding")" "$(stage "$t" "shading passes")" \
        "$(stage "$t" "secondary rays")" "$(stage "$t" "frame")"
    done
  done
done
