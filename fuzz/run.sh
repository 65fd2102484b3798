#!/usr/bin/env bash
# Runs each fuzz target for a fixed time (default 60 s each) with
# AddressSanitizer and UndefinedBehaviorSanitizer. Seeds: the conformance
# corpus, the reference programs and the regression inputs. Crashes land in
# build-fuzz/artifacts/; fix them and copy the input to
# tests/fuzz_regressions/<target>/ (a test replays every file there).
#   bash fuzz/run.sh [SECONDS]
set -euo pipefail
cd "$(dirname "$0")/.."
SECONDS_EACH=${1:-60}
if ! command -v clang++ >/dev/null || [ ! -e /usr/lib/llvm-14/lib/clang/14.0.6/lib/linux/libclang_rt.fuzzer-x86_64.a ]; then
  apt-get install -y -qq clang libclang-rt-14-dev >/dev/null
fi
cmake -S . -B build-fuzz -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DCMAKE_CXX_COMPILER=clang++ \
  -DCUTSIM_FUZZ=ON -DCUTSIM_BUILD_TESTS=OFF -DCUTSIM_BUILD_BENCH=OFF >/dev/null
cmake --build build-fuzz --target fuzz_gcode fuzz_job fuzz_machine fuzz_environment fuzz_mesh fuzz_tools
mkdir -p build-fuzz/artifacts build-fuzz/corpus/gcode build-fuzz/corpus/job build-fuzz/corpus/machine build-fuzz/corpus/environment build-fuzz/corpus/mesh build-fuzz/corpus/tools
# Seeds for the G-code target carry a first byte choosing dialect and block delete.
for f in tests/conformance/*.nc ncprograms/*.nc; do
  d=0; grep -q fanuc "${f%.nc}.expected" 2>/dev/null && d=1
  { printf "\\x0$d"; cat "$f"; } > "build-fuzz/corpus/gcode/seed-$(basename "$f")"
done
cp ncprograms/*.toml build-fuzz/corpus/job/ 2>/dev/null || true
cp models/machines/*.toml build-fuzz/corpus/machine/
printf '\x00solid t\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\nendloop\nendfacet\nendsolid t\n' > build-fuzz/corpus/mesh/seed.stl
printf '\x01v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 2 3 4\nf 3 1 4\n' > build-fuzz/corpus/mesh/seed.obj
printf '\x02ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n' > build-fuzz/corpus/mesh/seed.ply
cp tests/fuzz_regressions/mesh/seed-triangle.gltf build-fuzz/corpus/mesh/
printf 'time_s,temperature_c,humidity_pct,pressure_hpa\n0,20,50,1013.25\n60,20.1,49,1013.6\n' > build-fuzz/corpus/environment/seed.csv
printf '\x01T1 P1 D6.0 Z+12.5 ;6 mm flat end mill\nT2 P2 D1 ;ball l=2 shank_d=4\nT3 D2 ;bull r=0.2\n' > build-fuzz/corpus/tools/seed.tbl
printf '\x00[[tool]]\nnumber = 1\nkind = "ball"\ndiameter = 1\n[[tool]]\nnumber = 2\nspec = "vtool:angle=90,clearance=7"\n[[tool]]\nnumber = 3\nkind = "flycutter"\nswing_radius = 18\nnose_radius = 2\n' > build-fuzz/corpus/tools/seed.toml
status=0
for t in gcode job machine environment mesh tools; do
  echo "fuzz_$t: ${SECONDS_EACH}s"
  ./build-fuzz/fuzz/fuzz_$t -max_total_time="$SECONDS_EACH" -timeout=10 -rss_limit_mb=2048 -max_len=4096 -use_value_profile=1 \
    -artifact_prefix=build-fuzz/artifacts/$t- -print_final_stats=1 \
    build-fuzz/corpus/$t tests/fuzz_regressions/$t 2>&1 | grep -E 'stat::number_of_executed_units|ERROR|SUMMARY|Test unit written' || status=$?
  if ls build-fuzz/artifacts/$t-* >/dev/null 2>&1; then echo "fuzz_$t: crashes in build-fuzz/artifacts/"; status=1; fi
done
exit $status
