#!/usr/bin/env bash
# The README's first command: install, build, and simulate the reference
# program ncprograms/ball_raster.nc into build/out/.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
./build/apps/cutsim/cutsim run ncprograms/ball_raster.nc -o build/out
