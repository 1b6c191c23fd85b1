#!/usr/bin/env bash
# Runs every test: an ASan+UBSan Debug build (unit, fuzz replay and fast integration tests)
# in build-asan/, then the Release build's full suite (including bakes of ../shared/scenes
# when present) in build-release/ (build/ stays the demo's RelWithDebInfo build).
# Ends with ctest's summary of the full suite. CI (.ci/run) runs scripts/fuzz.sh first.
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
bash "$root/scripts/setup-deps.sh"
jobs="$(nproc)"

asan="$root/build-asan"
cmake -S "$root" -B "$asan" -DCMAKE_BUILD_TYPE=Debug -DLUCENT_SANITIZE=ON >/dev/null
cmake --build "$asan" -j"$jobs"
echo "== ASan+UBSan: unit, fuzz replay, fast integration tests =="
(cd "$asan" && ctest --output-on-failure -j"$jobs" -LE slow)

build="$root/build-release"
cmake -S "$root" -B "$build" -DCMAKE_BUILD_TYPE=Release >/dev/null
cmake --build "$build" -j"$jobs"
echo "== full suite (Release) =="
cd "$build" && ctest --output-on-failure -j"$jobs"
