#!/usr/bin/env bash
# Relight benchmark across presets: bakes the embedded Cornell box and sponza-dabrovic (when
# ../shared/scenes has it) at the moderate, high and ultra presets, sibenik and the conference room
# (when present) at moderate, then runs lucent-bench on both backends (and once more on the CPU
# with --grid needed, as lucentd relights: FILE-grid-needed.json). Prints lucent-bench's tables
# (per-stage ms, where the time goes, the paper's figures) and writes JSON (default
# bench/relight-results.json). The --grid needed runs use lucentd's own --bounces 0 (an update's
# relight is one transport pass; refinement adds the bounces after its frame) and, beside it,
# the tables' 1 feedback bounce (FILE-grid-needed-b1.json).
# Usage: relight_bench.sh [--runs N] [--out FILE]
set -euo pipefail
root="$(cd "$(dirname "$0")/../.." && pwd)"
shared="${LUCENT_SHARED_DIR:-$root/../shared}"
runs=15
out="$root/bench/relight-results.json"
while [ $# -gt 0 ]; do
  case "$1" in
    --runs) runs="$2"; shift 2 ;;
    --out) out="$2"; shift 2 ;;
    *) echo "usage: $0 [--runs N] [--out FILE]" >&2; exit 2 ;;
  esac
done
bin="${LUCENT_BUILD_DIR:-$root/build}/bin"
[ -x "$bin/lucent-bench" ] || { echo "build first: bash scripts/build.sh" >&2; exit 1; }
tmp="$(mktemp -d)"; trap 'rm -rf "$tmp"' EXIT
mkdir -p "$(dirname "$out")"
bakes=()
for preset in moderate high ultra; do
  # the moderate bakes carry the 10 cm cube with its DNRT transfer grid: lucent-bench's DNRT rows
  asset=()
  [ "$preset" = moderate ] && asset=(--asset "cube=$root/scenes/cornell-box/cube.obj")
  echo "baking cornell ($preset)..." >&2
  "$bin/lucent-bake" bake "$root/scenes/cornell-box/cornell-box.obj" -o "$tmp/cornell-$preset.lcb" \
      --quality "$preset" --quiet --no-write-glb "${asset[@]}"
  bakes+=("$tmp/cornell-$preset.lcb")
  if [ -f "$shared/scenes/sponza-dabrovic/sponza.obj" ]; then
    echo "baking sponza-dabrovic ($preset)..." >&2
    "$bin/lucent-bake" bake "$shared/scenes/sponza-dabrovic/sponza.obj" -o "$tmp/sponza-$preset.lcb" \
        --quality "$preset" --quiet --no-write-glb "${asset[@]}"
    bakes+=("$tmp/sponza-$preset.lcb")
  else
    echo "skip sponza-dabrovic: $shared/scenes/sponza-dabrovic absent" >&2
  fi
done
# The other shared scenes at the moderate preset only (their high bakes add little).
for entry in "sibenik|$shared/scenes/sibenik/sibenik.obj|" \
             "conference-room|$shared/scenes/conference-room/conference.obj|--scale 0.003"; do
  IFS='|' read -r name file extra <<<"$entry"
  if [ ! -f "$file" ]; then echo "skip $name: $file absent" >&2; continue; fi
  echo "baking $name (moderate)..." >&2
  # shellcheck disable=SC2086
  "$bin/lucent-bake" bake "$file" -o "$tmp/$name-moderate.lcb" --quality moderate --quiet --no-write-glb $extra
  bakes+=("$tmp/$name-moderate.lcb")
done
"$bin/lucent-bench" --runs "$runs" --backend both --json "$out" "${bakes[@]}"
echo "wrote $out"
# As lucentd relights an update while no client takes the shgrid stream (only the grid cells
# objects and surfels read, lucentd's --bounces 0): the CPU rows issue 16's relight target is
# judged on; then the same with one feedback bounce, as the tables above.
needed="${out%.json}-grid-needed.json"
"$bin/lucent-bench" --runs "$runs" --backend cpu --grid needed --bounces 0 --no-dnrt --json "$needed" "${bakes[@]}"
echo "wrote $needed"
"$bin/lucent-bench" --runs "$runs" --backend cpu --grid needed --bounces 1 --no-dnrt \
    --json "${out%.json}-grid-needed-b1.json" "${bakes[@]}"
echo "wrote ${out%.json}-grid-needed-b1.json"
