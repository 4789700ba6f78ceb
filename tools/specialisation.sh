#!/usr/bin/env bash
# Specialised against general passes, per project scene: the static SPIR-V instruction count of
# each shader variant after the driver-equivalent folding (spirv-opt freezes the specialization
# constants and optimises), and the frame time of both from one run.
#   tools/specialisation.sh [FRAMES]   (default 20; needs build/mobirt, glslangValidator, spirv-opt)
set -euo pipefail
cd "$(dirname "$0")/.."
FRAMES=${1:-20}
MOBIRT=${MOBIRT:-build/mobirt}
[ -x "$MOBIRT" ] || { echo "specialisation: $MOBIRT not found: build first (tools/setup.sh)" >&2; exit 2; }
WORK=$(mktemp -d)
trap 'rm -rf "$WORK"' EXIT
for s in trace shade; do
  glslangValidator --quiet -V --target-env vulkan1.1 -Iglsl -o "$WORK/$s.spv" "glsl/$s.frag"
done

# instructions SHADER "id:value ...": instructions left once the constants are frozen and folded.
instructions() {
  # --fold-spec-const-op-composite: expressions of the constants (LIGHT_COUNT > 0, ...) fold too.
  spirv-opt --set-spec-const-default-value "$2" --freeze-spec-const --fold-spec-const-op-composite -O --loop-unroll -O \
    "$WORK/$1.spv" -o "$WORK/v.spv"
  spirv-dis --no-header "$WORK/v.spv" | grep -c 'Op'
}
# Spec ids (glsl/layout.h): 0 lights, 1 stack depth, 2 max steps, 3 packing, 4 textures, 9 atlas pages.
fps() {  # scene size extra-args...
  local scene=$1 size=$2
  shift 2
  "$MOBIRT" render "$scene" --size "$size" --frames "0:$FRAMES" -o "$WORK/f_%04d.png" --timings "$@" 2>/dev/null |
    awk '/^frame /{print $2}'
}

echo "| scene | lights | textures | trace instr. spec. / general | shade instr. spec. / general | frame ms spec. | frame ms general | general / spec. |"
echo "|---|---|---|---|---|---|---|---|"
for entry in default:400x240 toaster:400x240 marbles:240x400 fish:400x240; do
  name=${entry%%:*}
  size=${entry##*:}
  info=$("$MOBIRT" info "scenes/$name.gltf")
  lights=$(awk '/^lights:/{print $2}' <<<"$info")
  textures=$(awk '/^textures:/{print $2}' <<<"$info")
  pages=$(sed -n 's/.*ATLAS_PAGES \([0-9]*\).*/\1/p' <<<"$info")
  general_lights=8
  [ "$lights" -gt 8 ] && general_lights=16
  ts=$(instructions trace "0:$lights 1:4 2:2048 3:0")
  tg=$(instructions trace "0:$general_lights 1:4 2:2048 3:0")
  ss=$(instructions shade "0:$lights 4:$textures 9:${pages:-0}")
  sg=$(instructions shade "0:$general_lights 4:48 9:3")
  fs=$(fps "scenes/$name.gltf" "$size")
  fg=$(fps "scenes/$name.gltf" "$size" --general)
  ratio=$(awk -v a="$fg" -v b="$fs" 'BEGIN{printf "%.2f", a / b}')
  echo "| $name | $lights | $textures | $ts / $tg | $ss / $sg | $fs | $fg | $ratio |"
done
