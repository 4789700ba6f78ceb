#!/usr/bin/env bash
# Set-up for a fresh Debian 12 machine: installs the Debian packages mobirt needs that are missing
# (non-interactive; apt-get update first, only when something is missing, so a second run is a
# no-op), then configures and builds into build/. With CI=true, warnings are errors.
# Mesa comes at 25.0 or later, Vulkan and EGL/GLES alike so that both backends run on one Mesa:
# its lavapipe has VK_KHR_ray_query and VK_KHR_acceleration_structure (the ray-query peer of
# `mobirt bench`), 22.3.6 has neither. Debian 12 has it in bookworm-backports, used for those
# packages only (and what they need); Debian 13 has it in main.
set -euo pipefail
cd "$(dirname "$0")/.."

PACKAGES=(
  cmake ninja-build g++ pkg-config
  libvulkan-dev vulkan-validationlayers
  glslang-tools glslang-dev spirv-tools
  libglm-dev libtinygltf-dev nlohmann-json3-dev libstb-dev libtinyobjloader-dev
  libopenimageio-dev libgtest-dev libbenchmark-dev
  libcli11-dev                # the command line's option table and --help
  libegl-dev libgles-dev
  clang libclang-rt-14-dev    # the scene fuzzer (tools/fuzz.sh): clang 14's libFuzzer, ASan, UBSan
  python3                     # tools/bad_inputs/, tests/fuzz/make_corpus.py
  python3-matplotlib          # the PNG plots of tools/accuracy_sweep.sh and tools/profile/
  libembree-dev               # the baseline of `mobirt bench`: Embree 3, what a user would pick instead
  libtbb-dev                  # parallel kd-tree build (TBB is also what Embree runs on)
)

# Mesa's Vulkan driver (lavapipe) and its EGL/GLES side (llvmpipe), at MESA_MIN or later.
MESA_PACKAGES=(mesa-vulkan-drivers libegl-mesa0 libgl1-mesa-dri)
MESA_MIN=25.0

# Prints the installed version, or nothing. Never fails: dpkg-query exits 1 for a package it has
# never seen, which under pipefail would make `v=$(installed_version ...)` end the script silently.
installed_version() { { dpkg-query -W -f='${Status} ${Version}' "$1" 2>/dev/null || true; } | sed -n 's/^install ok installed //p'; }

missing=()
for p in "${PACKAGES[@]}"; do
  if [ -z "$(installed_version "$p")" ]; then missing+=("$p"); fi
done
mesa_old=()
for p in "${MESA_PACKAGES[@]}"; do
  v=$(installed_version "$p")
  if [ -z "$v" ] || dpkg --compare-versions "$v" lt "$MESA_MIN"; then mesa_old+=("$p"); fi
done

if ((${#missing[@]} + ${#mesa_old[@]})); then
  SUDO=""
  if [ "$(id -u)" -ne 0 ]; then
    if command -v sudo >/dev/null; then SUDO="sudo"; else
      echo "setup: need root (or sudo) to install: ${missing[*]} ${mesa_old[*]}" >&2; exit 1
    fi
  fi
  mesa_targets=("${mesa_old[@]}")
  codename=$(. /etc/os-release && echo "${VERSION_CODENAME:-}")
  if ((${#mesa_old[@]})) && [ "$codename" = bookworm ]; then
    # apt's target release for these packages only: name/suite picks the suite for each named
    # package and, where they need newer versions, for its dependencies (libdrm); nothing else moves.
    mesa_targets=("${mesa_old[@]/%//bookworm-backports}")
    if ! grep -rqs "bookworm-backports" /etc/apt/sources.list /etc/apt/sources.list.d/; then
      echo "setup: adding Debian's bookworm-backports suite to apt's sources, for Mesa ${MESA_MIN} (lavapipe with ray queries)"
      printf 'Types: deb\nURIs: http://deb.debian.org/debian\nSuites: bookworm-backports\nComponents: main\nSigned-By: /usr/share/keyrings/debian-archive-keyring.gpg\n' |
        $SUDO tee /etc/apt/sources.list.d/mobirt-bookworm-backports.sources >/dev/null
    fi
  fi
  if ((${#missing[@]})); then echo "setup: installing ${missing[*]}"; fi
  if ((${#mesa_old[@]})); then echo "setup: installing Mesa >= ${MESA_MIN}: ${mesa_targets[*]}"; fi
  $SUDO apt-get update -q
  $SUDO env DEBIAN_FRONTEND=noninteractive apt-get install -y -q --no-install-recommends \
    "${missing[@]}" "${mesa_targets[@]}"
  for p in "${MESA_PACKAGES[@]}"; do
    v=$(installed_version "$p")
    if [ -z "$v" ] || dpkg --compare-versions "$v" lt "$MESA_MIN"; then
      echo "setup: $p is at '${v:-absent}' after installing, mobirt needs Mesa >= ${MESA_MIN}: on Debian 12 enable bookworm-backports, on Debian 13 its main suite has it" >&2
      exit 1
    fi
  done
fi

WERROR=OFF
if [ "${CI:-}" = "true" ]; then WERROR=ON; fi
cmake -S . -B build -G Ninja -DCMAKE_BUILD_TYPE=Release -DMOBIRT_WERROR="$WERROR" >/dev/null
cmake --build build -j "$(nproc)"
