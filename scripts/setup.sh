#!/usr/bin/env bash
# Installs cutsim's dependencies from Debian's packages (and the Khronos
# glTF validator from npm, for the tests) and builds in Release into build/.
set -euo pipefail
cd "$(dirname "$0")/.."

SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi

PKGS=(cmake ninja-build g++ libopenvdb-dev libembree-dev libeigen3-dev libtbb-dev
      libtinygltf-dev libboost-iostreams-dev libboost-dev libcli11-dev libtomlplusplus-dev
      nlohmann-json3-dev libgtest-dev libgmock-dev libbenchmark-dev)
missing=()
for p in "${PKGS[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if ! command -v node >/dev/null || ! command -v npm >/dev/null; then missing+=(nodejs npm); fi
if [ ${#missing[@]} -gt 0 ]; then
  echo "setup: installing ${missing[*]}"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq "${missing[@]}" >/dev/null
fi

if [ ! -f build/npm/node_modules/gltf-validator/package.json ]; then
  echo "setup: installing gltf-validator (npm) into build/npm"
  mkdir -p build/npm
  npm install --silent --no-audit --no-fund --prefix build/npm gltf-validator@2.0.0-dev.3.10 >/dev/null
fi

cmake -S . -B build -G Ninja -DCMAKE_BUILD_TYPE=Release >/dev/null
cmake --build build -j "$(nproc)"
