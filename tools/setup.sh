#!/usr/bin/env bash
# Installs every Debian package tetrig needs to build, test and benchmark, skipping what is present.
# Used by both README commands and by .ci/run. Runs apt-get as root, or through sudo.
set -euo pipefail

packages=(
  # toolchain
  g++ cmake ninja-build pkg-config git
  # runtime and drivers
  libeigen3-dev libusb-1.0-0-dev libhidapi-dev
  # tests and benchmarks
  libgtest-dev libgmock-dev libbenchmark-dev umockdev libumockdev-dev
  # offline tools (tools/: rig builder)
  libtet1.5-dev libassimp-dev libnanoflann-dev libcli11-dev nlohmann-json3-dev
  # decimation with edge-length and aspect-ratio guards (tools/rigbuild/decimate_surface.cpp)
  libopenmesh-dev
  # tetrig export: glTF 2.0 (tools/export_formats.cpp)
  libtinygltf-dev
  # the Blender add-on's headless tests (tests/tools/test_blender.cpp; numpy for its fast path)
  blender python3-numpy
  # the default character's skin (tools/character: OpenVDB level set -> mesh; its CMake module needs Boost.Iostreams)
  libopenvdb-dev libboost-iostreams-dev
  # headless pictures and tetrig view (tools/render, tools/view): GL loader, EGL surfaceless + Mesa, GLFW, PNG, captions
  libepoxy-dev libegl-dev libegl1 libegl-mesa0 libgl1-mesa-dri libglfw3-dev libpng-dev libfreetype-dev libfontconfig-dev
  fonts-dejavu-core
  # tetrig view's tests under a virtual display
  xvfb xauth
  # the demo report's latency plot (tools/demo_report.cpp)
  gnuplot-nox
  # fuzzing and sanitizers (clang, libFuzzer, LeakSanitizer runtime)
  clang libclang-rt-14-dev
  # frames to other machines over Eclipse Cyclone DDS (dds/: the C library and its CMake package; idlc generates
  # the types from dds/idl/tetrig_frames.idl)
  cyclonedds-dev cyclonedds-tools
  # the latency harness's table (bench/latency.sh); the C API's ctypes test and the install test
  # (tests/capi, tests/install: nm from binutils)
  python3 binutils
)

missing=()
for p in "${packages[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done

if [ ${#missing[@]} -eq 0 ]; then
  echo "setup: all ${#packages[@]} packages present"
  exit 0
fi

echo "setup: installing ${#missing[@]} missing packages: ${missing[*]}"
sudo_cmd=()
if [ "$(id -u)" -ne 0 ]; then
  if command -v sudo >/dev/null 2>&1; then sudo_cmd=(sudo); else
    echo "setup: not root and no sudo; install these packages by hand: ${missing[*]}" >&2
    exit 1
  fi
fi
export DEBIAN_FRONTEND=noninteractive
"${sudo_cmd[@]}" apt-get update -qq
"${sudo_cmd[@]}" apt-get install -y -qq --no-install-recommends "${missing[@]}"
echo "setup: done"
