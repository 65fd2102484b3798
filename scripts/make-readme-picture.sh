#!/usr/bin/env bash
# Makes docs/slot_demo.png, the README's picture: the comparison demo
# (ncprograms/slot_demo.nc against models/demo/slot_target.stl) rendered
# by scripts/render.sh. Needs the Release build (scripts/setup.sh).
set -euo pipefail
cd "$(dirname "$0")/.."
./build/apps/cutsim/cutsim run ncprograms/slot_demo.nc -o build/picture >/dev/null
mkdir -p docs
bash scripts/render.sh build/picture/slot_demo.glb docs/slot_demo.png 1000 600 30 38
