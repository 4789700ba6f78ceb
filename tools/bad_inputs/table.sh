#!/usr/bin/env bash
# The README's bad-input table: makes every bad input (make_bad.py), runs build/mobirt on each and
# prints one markdown row per input: what mobirt says and its exit code.
#   tools/bad_inputs/table.sh > table.md        (MOBIRT overrides build/mobirt)
cd "$(dirname "$0")/../.."
MOBIRT=${MOBIRT:-build/mobirt}
WORK=$(mktemp -d)
trap 'rm -rf "$WORK"' EXIT
IN=$WORK/in
OUT=$WORK/out
mkdir -p "$IN" "$OUT"
python3 tools/bad_inputs/make_bad.py "$IN"
row() {  # description, args...
  local what="$1"; shift
  "$MOBIRT" "$@" > $OUT/.msg 2>&1; local code=$?
  local msg; msg=$(grep -v '^mobirt: warning' $OUT/.msg | tr '\n' ' ' | sed 's/ *$//')
  msg=${msg//$IN\//}; msg=${msg//$OUT\//}; msg=${msg//|/\\|}
  echo "| $what | \`$msg\` | $code |"
}
{
echo "| bad input | what mobirt prints (one line, on stderr) | exit code |"
echo "|---|---|---|"
row "scene file missing" render $IN/missing.gltf -o $OUT/a.png
row "unknown scene extension (.xyz)" render $IN/scene.xyz -o $OUT/a.png
row "empty .gltf" render $IN/empty.gltf -o $OUT/a.png
row "truncated JSON" render $IN/truncated.gltf -o $OUT/a.png
row "not JSON at all" render $IN/not-json.gltf -o $OUT/a.png
row ".glb with a broken header" render $IN/bad-magic.glb -o $OUT/a.png
row "accessor count beyond its bufferView" render $IN/accessor-out-of-bounds.gltf -o $OUT/a.png
row "bufferView beyond its buffer" render $IN/bufferview-outside-buffer.gltf -o $OUT/a.png
row "buffer byteLength larger than its data" render $IN/buffer-too-short.gltf -o $OUT/a.png
row "external .bin missing" render $IN/missing-buffer.gltf -o $OUT/a.png
row "index beyond the vertex count" render $IN/index-out-of-range.gltf -o $OUT/a.png
row "NaN vertex position" render $IN/nan-position.gltf -o $OUT/a.png
row "infinite vertex position" render $IN/inf-position.gltf -o $OUT/a.png
row "POSITION of the wrong component type" render $IN/position-wrong-type.gltf -o $OUT/a.png
row "primitive without POSITION" render $IN/no-position.gltf -o $OUT/a.png
row "primitive mode POINTS" render $IN/points-mode.gltf -o $OUT/a.png
row "primitive mode LINES" render $IN/lines-mode.gltf -o $OUT/a.png
row "extensionsRequired: an unsupported extension" render $IN/draco-required.gltf -o $OUT/a.png
row "node hierarchy with a cycle" render $IN/node-cycle.gltf -o $OUT/a.png
row "animation key times not increasing" render $IN/keys-not-increasing.gltf -o $OUT/a.png
row "embedded texture that is not an image" render $IN/undecodable-texture.gltf -o $OUT/a.png
row "embedded texture in an unsupported format (webp)" render $IN/webp-texture.gltf -o $OUT/a.png
row "texture file missing" render $IN/missing-texture.gltf -o $OUT/a.png
row "49 textures (more than the atlas' 3 pages of 16)" render $IN/49-textures.gltf -o $OUT/a.png
row "empty .obj" render $IN/empty.obj -o $OUT/a.png
row ".obj with vertices but no faces" render $IN/no-faces.obj -o $OUT/a.png
row ".obj face index out of range" render $IN/face-out-of-range.obj -o $OUT/a.png
row ".obj NaN vertex ('nan', which tinyobjloader would read as 0)" render $IN/nan-vertex.obj -o $OUT/a.png
row ".obj infinite vertex (1e999)" render $IN/inf-vertex.obj -o $OUT/a.png
row ".mtl map_Kd with a path name too long" render $IN/long-texture-name.obj -o $OUT/a.png
row ".obj of binary garbage" render $IN/binary-garbage.obj -o $OUT/a.png
row "empty .nff" render $IN/empty.nff -o $OUT/a.png
row "truncated .nff (inside a polygon)" render $IN/truncated.nff -o $OUT/a.png
row ".nff unknown entity" render $IN/unknown-entity.nff -o $OUT/a.png
row ".nff field that is not a number" render $IN/bad-number.nff -o $OUT/a.png
row ".nff polygon over the vertex limit" render $IN/polygon-too-many.nff -o $OUT/a.png
row ".nff cone with base = apex" render $IN/cone-coincident.nff -o $OUT/a.png
row ".nff view without an angle" render $IN/view-no-angle.nff -o $OUT/a.png
row ".nff of binary garbage" render $IN/binary-garbage.nff -o $OUT/a.png
row "empty .ply" render $IN/empty.ply -o $OUT/a.png
row ".ply that is not PLY (STL text)" render $IN/not-ply.ply -o $OUT/a.png
row "truncated .ply header" render $IN/truncated-header.ply -o $OUT/a.png
row "truncated binary .ply" render $IN/truncated-binary.ply -o $OUT/a.png
row ".ply element count over what the file holds" render $IN/count-over-limit.ply -o $OUT/a.png
row ".ply face index out of range" render $IN/face-out-of-range.ply -o $OUT/a.png
row ".ply unknown format" render $IN/unknown-format.ply -o $OUT/a.png
row "--mtl file missing" render $IN/no-faces.obj --mtl $IN/missing.mtl -o $OUT/a.png
row "OBJ sequence pattern matching no file" render "$IN/frame_%02d.obj" -o $OUT/a.png
row "output folder missing" render $IN/ok-triangle.gltf -o $OUT/nofolder/a.png
row "output format unknown (.xyz)" render $IN/ok-triangle.gltf -o $OUT/a.xyz
row "--frames with an output that is not a pattern" render $IN/ok-triangle.gltf --frames 0:3 -o $OUT/a.png
row "--size out of range" render $IN/ok-triangle.gltf --size 0x10 -o $OUT/a.png
row "--depth not a number" render $IN/ok-triangle.gltf --depth x -o $OUT/a.png
row "unknown option" render $IN/ok-triangle.gltf --frobnicate -o $OUT/a.png
row "malformed --light" render $IN/ok-triangle.gltf --light "point pos=1,2" -o $OUT/a.png
row "malformed --camera" render $IN/ok-triangle.gltf --camera "1,2,3" -o $OUT/a.png
row "no such --device" render $IN/ok-triangle.gltf --device nosuchgpu -o $OUT/a.png
row "unknown command" frobnicate
} | sed -E "s/x{20,}/xxx…/; s/y{20,}/yyy…/"
# Every bad input must have left no output file behind.
leftover=$(find "$OUT" -type f ! -name .msg | head -1)
if [ -n "$leftover" ]; then echo "bad-input table: an output file was left behind: $leftover" >&2; exit 1; fi
