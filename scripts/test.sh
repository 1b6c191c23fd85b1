#!/usr/bin/env bash
# Runs every test: an ASan+UBSan Debug build (unit, fuzz replay and fast integration tests)
# in build-asan/, a ThreadSanitizer build's daemon tests in build-tsan/, then the Release
# build's full suite (including bakes of ../shared/scenes
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

# ThreadSanitizer over the daemon's threads (service, compute, engine workers, clutter worker, the
# cluster log's reader and writer): its unit
# tests and the integration tests that drive a live lucentd. daemon_basic runs alone after
# them: beside another TSan daemon on 2 cores one run in ~11 lost an HTTP GET to a reset
# connection (no TSan report); alone it passed every run, a CPU hog beside it included.
tsan="$root/build-tsan"
cmake -S "$root" -B "$tsan" -DCMAKE_BUILD_TYPE=RelWithDebInfo -DLUCENT_TSAN=ON >/dev/null
cmake --build "$tsan" -j"$jobs" --target lucentd lucentctl lucent-bake cornell_bake client_live \
  test_compute test_state test_journal test_frames test_cluster
echo "== ThreadSanitizer: the daemon's unit and live integration tests =="
(cd "$tsan" && ctest --output-on-failure -j"$jobs" \
  -R '^(unit\.daemon\.|integration\.(daemon_hardening|client_live|journal_faults|lucentctl_basic|daemon_clutter|daemon_cluster)$)' &&
  ctest --output-on-failure -R '^integration\.daemon_basic$')

build="$root/build-release"
cmake -S "$root" -B "$build" -DCMAKE_BUILD_TYPE=Release >/dev/null
cmake --build "$build" -j"$jobs"
echo "== full suite (Release) =="
cd "$build" && ctest --output-on-failure -j"$jobs"
