#!/usr/bin/env bash
# Set-up for a fresh Debian 12 machine: installs the Debian packages mobirt needs that are missing
# (non-interactive; apt-get update first, only when something is missing, so a second run is a
# no-op), then configures and builds into build/. With CI=true, warnings are errors.
set -euo pipefail
cd "$(dirname "$0")/.."

PACKAGES=(
  cmake ninja-build g++ pkg-config
  libvulkan-dev mesa-vulkan-drivers vulkan-validationlayers
  glslang-tools glslang-dev spirv-tools
  libglm-dev libtinygltf-dev nlohmann-json3-dev libstb-dev libtinyobjloader-dev
  libopenimageio-dev libgtest-dev libbenchmark-dev
  libcli11-dev                # the command line's option table and --help
  libegl-dev libgles-dev libegl-mesa0
  clang libclang-rt-14-dev    # the scene fuzzer (tools/fuzz.sh): clang 14's libFuzzer, ASan, UBSan
  python3                     # tools/bad_inputs/, tests/fuzz/make_corpus.py
  python3-matplotlib          # the PNG plots of tools/accuracy_sweep.sh and tools/profile/
  libembree-dev               # the baseline of `mobirt bench`: Embree 3, what a user would pick instead
  libtbb-dev                  # parallel kd-tree build (TBB is also what Embree runs on)
)

missing=()
for p in "${PACKAGES[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done
if ((${#missing[@]})); then
  echo "setup: installing ${missing[*]}"
  SUDO=""
  if [ "$(id -u)" -ne 0 ]; then
    if command -v sudo >/dev/null; then SUDO="sudo"; else
      echo "setup: need root (or sudo) to install: ${missing[*]}" >&2; exit 1
    fi
  fi
  $SUDO apt-get update -q
  $SUDO env DEBIAN_FRONTEND=noninteractive apt-get install -y -q --no-install-recommends "${missing[@]}"
fi

WERROR=OFF
if [ "${CI:-}" = "true" ]; then WERROR=ON; fi
cmake -S . -B build -G Ninja -DCMAKE_BUILD_TYPE=Release -DMOBIRT_WERROR="$WERROR" >/dev/null
cmake --build build -j "$(nproc)"
