#!/usr/bin/env bash
# Runs every test: an ASan+UBSan build (unit, fuzz replay and fast integration tests), then
# the release build's full suite (including bakes of ../shared/scenes when present).
# Ends with ctest's summary of the full suite.
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
bash "$root/scripts/setup-deps.sh"
jobs="$(nproc)"

asan="$root/build-asan"
cmake -S "$root" -B "$asan" -DCMAKE_BUILD_TYPE=Debug -DLUCENT_SANITIZE=ON >/dev/null
cmake --build "$asan" -j"$jobs"
echo "== ASan+UBSan: unit, fuzz replay, fast integration tests =="
(cd "$asan" && ctest --output-on-failure -j"$jobs" -LE slow)

build="$root/build"
cmake -S "$root" -B "$build" -DCMAKE_BUILD_TYPE=RelWithDebInfo >/dev/null
cmake --build "$build" -j"$jobs"
echo "== full suite =="
cd "$build" && ctest --output-on-failure -j"$jobs"
