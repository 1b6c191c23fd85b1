#!/usr/bin/env bash
# Relight benchmark across presets: bakes the embedded Cornell box and sponza-dabrovic (when
# ../shared/scenes has it) at the moderate and high presets, then runs lucent-bench on both
# backends. Prints lucent-bench's tables (per-stage ms, where the time goes, the paper's
# figures) and writes JSON (default bench/relight-results.json).
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
for preset in moderate high; do
  echo "baking cornell ($preset)..." >&2
  "$bin/lucent-bake" bake "$root/scenes/cornell-box/cornell-box.obj" -o "$tmp/cornell-$preset.lcb" \
      --quality "$preset" --quiet --no-write-glb
  bakes+=("$tmp/cornell-$preset.lcb")
  if [ -f "$shared/scenes/sponza-dabrovic/sponza.obj" ]; then
    echo "baking sponza-dabrovic ($preset)..." >&2
    "$bin/lucent-bake" bake "$shared/scenes/sponza-dabrovic/sponza.obj" -o "$tmp/sponza-$preset.lcb" \
        --quality "$preset" --quiet --no-write-glb
    bakes+=("$tmp/sponza-$preset.lcb")
  else
    echo "skip sponza-dabrovic: $shared/scenes/sponza-dabrovic absent" >&2
  fi
done
"$bin/lucent-bench" --runs "$runs" --backend both --json "$out" "${bakes[@]}"
echo "wrote $out"
