#!/usr/bin/env bash
# Bounded fuzzing of every tests/fuzz/fuzz_<target>.c with clang's libFuzzer (ASan+UBSan),
# run by CI (.ci/run) before the test suite; also by hand: `bash scripts/fuzz.sh [TARGET...]`.
#
# Each target runs LUCENT_FUZZ_SECONDS (default 60) seconds starting from its checked-in
# corpus tests/fuzz/corpus/<target>/; the inputs it finds are then merged (-merge=1: only
# those that add coverage) into that checked-in directory, so a developer's run leaves
# new files there to commit (`git status tests/fuzz/corpus`). In CI's fresh clone the growth
# is simply dropped. LUCENT_FUZZ_JOBS targets run at once (default: the number of cores).
#
# A crash, leak, UBSan report, timeout (> 10 s for one input) or out-of-memory fails the
# script (exit 1) after every target ran: the input is kept as
# $LUCENT_FUZZ_BUILD_DIR/fuzz-run/<target>/artifacts/crash-* (timeout-*, leak-*, oom-*) and
# printed in base64 with the sanitizer report. Reproduce with
#   build-fuzz/tests/fuzz/fuzz_<target> FILE
# and, once fixed, add FILE to tests/fuzz/corpus/<target>/ so the replay test keeps it.
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
bash "$root/scripts/setup-deps.sh"
build="${LUCENT_FUZZ_BUILD_DIR:-$root/build-fuzz}"
secs="${LUCENT_FUZZ_SECONDS:-60}"
jobs="${LUCENT_FUZZ_JOBS:-$(nproc)}"

targets=("$@")
if [ ${#targets[@]} -eq 0 ]; then
  for src in "$root"/tests/fuzz/fuzz_*.c; do
    t="$(basename "$src" .c)"
    targets+=("${t#fuzz_}")
  done
fi

start=$(date +%s)
CC=clang CXX=clang++ cmake -S "$root" -B "$build" -DCMAKE_BUILD_TYPE=RelWithDebInfo -DLUCENT_FUZZ=ON >/dev/null
cmake --build "$build" -j"$(nproc)" --target "${targets[@]/#/fuzz_}" >"$build/fuzz-build.log" 2>&1 ||
  { tail -n 40 "$build/fuzz-build.log"; echo "fuzz: build failed" >&2; exit 1; }
echo "== fuzz: built ${#targets[@]} targets in $(($(date +%s) - start)) s; ${secs} s each, $jobs at once"

# Sanitizer reports go to files (a target may silence its stderr, as fuzz_ctlscript does).
asan="detect_leaks=1:abort_on_error=0"
ubsan="print_stacktrace=1:halt_on_error=1"

# fuzz_one TARGET: fuzz, then merge; writes $run/status (0 ok) and $run/summary.
fuzz_one() {
  local t="$1" bin="$build/tests/fuzz/fuzz_$1" corpus="$root/tests/fuzz/corpus/$1"
  local run="$build/fuzz-run/$1" rc=0
  rm -rf "$run"
  mkdir -p "$run/new" "$run/artifacts" "$corpus"
  local before
  before=$(find "$corpus" -type f | wc -l)
  ASAN_OPTIONS="$asan:log_path=$run/sanitizer" UBSAN_OPTIONS="$ubsan:log_path=$run/sanitizer" \
    "$bin" -max_total_time="$secs" -timeout=10 -rss_limit_mb=2048 -print_final_stats=1 \
    -artifact_prefix="$run/artifacts/" "$run/new" "$corpus" >"$run/log" 2>&1 || rc=$?
  if [ "$rc" -eq 0 ]; then
    ASAN_OPTIONS="$asan:log_path=$run/sanitizer" UBSAN_OPTIONS="$ubsan:log_path=$run/sanitizer" \
      "$bin" -merge=1 -timeout=10 -rss_limit_mb=2048 "$corpus" "$run/new" >"$run/merge.log" 2>&1 || rc=$?
  fi
  local after execs
  after=$(find "$corpus" -type f | wc -l)
  execs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$run/log" | tail -n 1)
  echo "$rc" >"$run/status"
  echo $((after - before)) >"$run/added"
  printf '%-12s %s  %8s execs  corpus %4d -> %4d\n' "$t" "$([ "$rc" -eq 0 ] && echo ok || echo "FAILED (exit $rc)")" \
    "${execs:--}" "$before" "$after" >"$run/summary"
}

running=0
for t in "${targets[@]}"; do
  [ -x "$build/tests/fuzz/fuzz_$t" ] || { echo "fuzz: no target fuzz_$t" >&2; exit 1; }
  fuzz_one "$t" &
  running=$((running + 1))
  if [ "$running" -ge "$jobs" ]; then
    wait -n || true
    running=$((running - 1))
  fi
done
wait

failed=0 added=0
for t in "${targets[@]}"; do
  run="$build/fuzz-run/$t"
  cat "$run/summary" 2>/dev/null || echo "$t: no result"
  added=$((added + $(cat "$run/added" 2>/dev/null || echo 0)))
done
for t in "${targets[@]}"; do
  run="$build/fuzz-run/$t"
  [ "$(cat "$run/status" 2>/dev/null || echo missing)" = 0 ] && continue
  failed=1
  echo "---- fuzz_$t failed; libFuzzer's output:"
  { grep -v '^#[0-9]*[[:space:]]*\(NEW\|REDUCE\|pulse\|INITED\)' "$run/log" || true; } | tail -n 40
  for r in "$run"/sanitizer*; do
    [ -f "$r" ] || continue
    echo "---- sanitizer report ($r):"
    head -n 45 "$r"
  done
  for a in "$run"/artifacts/*; do
    [ -f "$a" ] || continue
    echo "---- input kept as $a ($(stat -c %s "$a") bytes), base64 (decode: base64 -d > input):"
    head -c 65536 "$a" | base64
  done
done
echo "== fuzz: $(($(date +%s) - start)) s in all"
if [ "$failed" -ne 0 ]; then
  echo "fuzz: FAILED (reproduce: $build/tests/fuzz/fuzz_<target> <input>)" >&2
  exit 1
fi
echo "fuzz: no crashes; $added new input(s) merged into tests/fuzz/corpus/ (commit them to keep the coverage)"
