#!/usr/bin/env bash
# Bake benchmark: time per stage, peak memory and file size for the embedded Cornell box
# and each shared scene present, at a preset (default moderate). Prints a table and writes
# JSON (default bench/bake-results.json). Usage: bake_bench.sh [--quality Q] [--out FILE]
set -euo pipefail
root="$(cd "$(dirname "$0")/../.." && pwd)"
shared="${LUCENT_SHARED_DIR:-$root/../shared}"
quality=moderate
out="$root/bench/bake-results.json"
while [ $# -gt 0 ]; do
  case "$1" in
    --quality) quality="$2"; shift 2 ;;
    --out) out="$2"; shift 2 ;;
    *) echo "usage: $0 [--quality draft|moderate|high] [--out FILE]" >&2; exit 2 ;;
  esac
done
bake="${LUCENT_BAKE:-$root/build/bin/lucent-bake}"
[ -x "$bake" ] || { echo "build first: bash scripts/build.sh" >&2; exit 1; }
tmp="$(mktemp -d)"; trap 'rm -rf "$tmp"' EXIT
mkdir -p "$(dirname "$out")"

scenes=(
  "cornell|$root/scenes/cornell-box/cornell-box.obj|"
  "sponza-dabrovic|$shared/scenes/sponza-dabrovic/sponza.obj|"
  "sibenik|$shared/scenes/sibenik/sibenik.obj|"
  "conference-room|$shared/scenes/conference-room/conference.obj|--scale 0.003"
)
results=()
for entry in "${scenes[@]}"; do
  IFS='|' read -r name file extra <<<"$entry"
  if [ ! -f "$file" ]; then echo "skip $name ($file absent)" >&2; continue; fi
  echo "baking $name ($quality)..." >&2
  # shellcheck disable=SC2086
  "$bake" bake "$file" -o "$tmp/$name.lcb" --quality "$quality" --stats-json "$tmp/$name.json" $extra
  results+=("$tmp/$name.json")
done
/usr/bin/python3 - "$out" "$quality" "${results[@]}" <<'PY'
import json, sys, platform, os
out, quality, files = sys.argv[1], sys.argv[2], sys.argv[3:]
rows = [json.load(open(f)) for f in files]
stages = []
for r in rows:
    for s in r["stages_s"]:
        if s not in stages: stages.append(s)
name = lambda r: os.path.basename(r["output"]).rsplit(".", 1)[0]
print(f"bake benchmark, preset {quality}, {os.cpu_count()} cores, {platform.processor() or platform.machine()}")
print(f"{'stage (s)':<14}" + "".join(f"{name(r):>17}" for r in rows))
for s in stages:
    print(f"{s:<14}" + "".join(f"{r['stages_s'].get(s, 0):>17.2f}" for r in rows))
for key, fmt in [("total_s", "{:.2f}"), ("peak_rss_mib", "{:.0f}"), ("file_bytes", None), ("triangles", "{}"),
                 ("surfels", "{}"), ("caches", "{}"), ("links_per_cache", "{}"), ("atlas_usage", "{:.2f}")]:
    vals = [(f"{r[key]/2**20:.1f} MiB" if key == "file_bytes" else fmt.format(r[key])) for r in rows]
    print(f"{key:<14}" + "".join(f"{v:>17}" for v in vals))
print("targets: sponza-dabrovic moderate <= 60 s and <= 2048 MiB peak")
json.dump({"quality": quality, "cores": os.cpu_count(), "scenes": {name(r): r for r in rows}}, open(out, "w"), indent=2)
print(f"wrote {out}")
PY
