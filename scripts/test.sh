#!/usr/bin/env bash
# The README's second command: install, build, and run the whole test suite
# (Release), then the sanitizer build (AddressSanitizer + UBSan) of the suite
# without Sweep.* (dense arithmetic references, already run above, 100x
# slower under ASan) and Interrupt.* (they time the exit, which means
# nothing under sanitizers).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
(cd build && ctest --output-on-failure -j "$(nproc)")
cmake --preset asan >/dev/null
cmake --build --preset asan
ctest --preset asan -j "$(nproc)" -E '^(Sweep\.|Interrupt\.)'
