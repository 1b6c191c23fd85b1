#!/usr/bin/env bash
# Fidelity of the PIC relight engine against the path-traced reference (lucent-ref):
#   1. the embedded Cornell box, moderate preset (the build's bake), its own ceiling lamp
#      (emissive material, the daemon's initial state): mean / p95 / max relative error;
#   2. the trade-off on the Cornell box: error vs links per cache, surfels and SH bands;
#   3. sponza-dabrovic, moderate, under a sun-like directional light, and its variants;
#   4. sibenik and the conference room, moderate, under point lights (neither has emitters).
# Steps 3 and 4 skip the scenes that ../shared/scenes lacks.
# Served rows (issue 16: what a client receives): for every scene of steps 1, 3 and 4 the same bake
# served by lucentd with its defaults (no quality or refinement flags), the state applied with
# lucentctl, lucentctl snapshot once the refinement is over, lucent-ref compare against the same
# reference (bench/served.py row; rows NAME-served, "served": true); and on Cornell and Sponza
# the time to converge after one light change as a client sees it (bench/served.py converge;
# fidelity.json "convergence").
# Usage: bench/fidelity.sh BUILD_DIR [OUT_JSON]   (default OUT_JSON: bench/out/fidelity.json)
# Environment: CORNELL_SPP (8192), SPONZA_SPP (8192), OTHER_SPP (4096: sibenik, conference),
#              THREADS (0 = all cores), TRADEOFF=0 to skip step 2, SHARED (../shared),
#              PRESETS (high ultra: the presets baked beside sibenik's and the conference
#              room's moderate for the preset trade-off rows, "scene-preset-P"; "" for none),
#              FIDELITY_WORK (bench/out/fidelity: the per-step outputs),
#              SERVED=0 to skip the served rows, SERVED_BACKEND (cpu), SERVED_FLAGS (extra lucentd
#              flags for the served runs, e.g. "--refine-passes 4 --refine-tolerance 0"; default none).
# Each step's lucent-ref output (reference EXR, error heat maps, per-texel CSV) stays in
# bench/out/fidelity/. Runtime on 2 cores: ~45 min (2026-12-06: Cornell and its trade-off 4 min,
# Sponza and its variants 25 min, sibenik and the conference room with their presets 16 min).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
build="${1:?usage: bench/fidelity.sh BUILD_DIR [OUT_JSON]}"
build="$(cd "$build" && pwd)"
out_json="${2:-$root/bench/out/fidelity.json}"
shared="${SHARED:-$root/../shared}"
bin="$build/bin"
threads="${THREADS:-0}"
cornell_spp="${CORNELL_SPP:-8192}"
sponza_spp="${SPONZA_SPP:-8192}"
other_spp="${OTHER_SPP:-4096}"
served="${SERVED:-1}"
tools=(lucent-bake lucent-ref)
[ "$served" = 0 ] || tools+=(lucentd lucentctl)
for tool in "${tools[@]}"; do
  [ -x "$bin/$tool" ] || { echo "fidelity: $bin/$tool missing (build first, or SERVED=0)" >&2; exit 1; }
done
command -v jq >/dev/null || { echo "fidelity: needs jq" >&2; exit 1; }
work="${FIDELITY_WORK:-$root/bench/out/fidelity}"
mkdir -p "$work" "$(dirname "$out_json")"
tmp="$(mktemp -d)"; trap 'rm -rf "$tmp"' EXIT

cornell_obj="$root/scenes/cornell-box/cornell-box.obj"
# The build's embedded bake: moderate, 64x64 lightmap, 1024 grid samples, seed 1.
cornell_flags=(--quality moderate --atlas-size 64 --grid-max-samples 1024 --seed 1 --quiet --no-write-glb
               --threads "$threads")

bake() { # OUT.lcb SCENE flags...; OUT.lcb.time: wall seconds and peak RSS KiB of the bake
  local out="$1" scene="$2"; shift 2
  /usr/bin/time -f '%e %M' -o "$out.time" "$bin/lucent-bake" bake "$scene" -o "$out" "$@" >/dev/null
}

fidelity() { # NAME BAKE REFDIR [extra lucent-ref flags]; prints the fidelity.json path
  local name="$1" lcb="$2" ref="$3"; shift 3
  "$bin/lucent-ref" fidelity "$lcb" --reference "$ref" --out "$work/$name" --quiet --threads "$threads" "$@" \
      >"$work/$name.txt" 2>&1 || { cat "$work/$name.txt" >&2; return 1; }
  echo "$work/$name/fidelity.json"
}

results=()
convergence=()
# The fields lucent-ref adds when it evaluates texels at their surface points (null before).
surface_fields='lightmap_moved: (.lightmap_moved // null), lightmap_unmoved: (.lightmap_unmoved // null),
  blotch: (.blotch // null), texel_spacing_m: (.texel_spacing_m // null)'
# The preset trade-off (issue 16: error against relight time and memory, per scene): the presets
# baked beside each scene's moderate, against the same reference.
# draft is not among them: its caches differ (a coarser grid, fewer relocation passes), so the
# scene's reference, rendered for moderate's caches, refuses it; high and ultra share moderate's
# caches except where their atlas differs (sibenik: refused too, measured 2026-12-06).
read -r -a other_presets <<<"${PRESETS-high ultra}"

preset_row() { # SCENE PRESET BAKE FIDELITY_JSON: error (the converged engine), relight, memory, bake cost
  local scene="$1" preset="$2" lcb="$3" f="$4" bench="$work/$1-preset-$2-bench.json" bake_s bake_kb
  "$bin/lucent-bench" --runs 9 --backend cpu --grid needed --no-dnrt --json "$bench" "$lcb" >"$bench.txt" 2>&1 ||
    { cat "$bench.txt" >&2; return 1; }
  read -r bake_s bake_kb <"$lcb.time"
  results+=("$(jq -c --arg sc "$scene" --arg p "$preset" --argjson bs "$bake_s" --argjson bk "$bake_kb" \
    --argjson fb "$(stat -c %s "$lcb")" --slurpfile b "$bench" '{name: ($sc + "-preset-" + $p), scene: $sc,
    preset: $p, tradeoff: true, links: .links_per_cache, surfels: .surfels, bands: .bands, texel_caches,
    lightmap, grid, bound, blotch: (.blotch // null), relight_cpu_ms: $b[0].results[0].total_ms,
    relight_peak_rss_mib: $b[0].results[0].peak_rss_mib, file_mib: ($fb / 1048576), bake_s: $bs,
    bake_peak_rss_mib: ($bk / 1024)}' "$f")")
  jq -r '"  preset \(.preset): lightmap mean \(.lightmap.mean*100)% grid \(.grid.mean*100)% relight \(.relight_cpu_ms) ms"' \
    <<<"${results[-1]}" >&2
}

served_flags=()
for fl in ${SERVED_FLAGS:-}; do served_flags+=("--daemon-arg=$fl"); done

served_row() { # NAME CONVERGED_ROW SCENE BAKE REFDIR [STATE]: lucentd's defaults, as a client receives them
  local name="$1" conv="$2" scene="$3" lcb="$4" ref="$5" state="${6:-}"
  [ "$served" = 0 ] && return 0
  echo "fidelity: $name: served by lucentd (its defaults)..." >&2
  /usr/bin/python3 "$root/bench/served.py" row --bin "$bin" --bake "$lcb" --reference "$ref" --out "$work/$name" \
      --backend "${SERVED_BACKEND:-cpu}" ${state:+--state "$state"} ${served_flags[@]+"${served_flags[@]}"} \
      2>"$work/$name.txt" || { cat "$work/$name.txt" >&2; return 1; }
  results+=("$(jq -c --arg n "$name" --arg c "$conv" --arg sc "$scene" "{name: \$n, scene: \$sc, served: true,
    converged_row: \$c, daemon, encoding, revision, pass, converged, refine_ms, frames, lightmap, grid, stream, reference,
    $surface_fields}" "$work/$name/served.json")")
  jq -r '"  served: pass \(.pass) lightmap mean \(.lightmap.mean*100)% p95 \(.lightmap.p95*100)% bias \(.lightmap.bias*100)%"' \
    "$work/$name/served.json" >&2
}

converge_row() { # NAME BAKE MASK CHANGE_JSON [STATE]: time to converge after one change, at a client
  local name="$1" lcb="$2" mask="$3" change="$4" state="${5:-}"
  [ "$served" = 0 ] && return 0
  echo "fidelity: $name: time to converge after one change, as a client sees it..." >&2
  /usr/bin/python3 "$root/bench/served.py" converge --bin "$bin" --bake "$lcb" --mask "$mask" --change "$change" \
      --out "$work/$name-converge.json" --backend "${SERVED_BACKEND:-cpu}" ${state:+--state "$state"} \
      ${served_flags[@]+"${served_flags[@]}"} 2>"$work/$name-converge.txt" || { cat "$work/$name-converge.txt" >&2; return 1; }
  convergence+=("$(jq -c --arg n "$name" '{name: $n} + .' "$work/$name-converge.json")")
  cat "$work/$name-converge.txt" >&2
}

# --- 1. Cornell box, moderate ------------------------------------------------------------------
echo "fidelity: Cornell box: bake + reference ($cornell_spp spp)..." >&2
bake "$tmp/cornell.lcb" "$cornell_obj" "${cornell_flags[@]}"
"$bin/lucent-ref" render "$tmp/cornell.lcb" --out "$work/cornell-reference" --spp "$cornell_spp" --batch 1024 \
    --quiet --threads "$threads" 2>"$work/cornell-reference.txt"
f="$(fidelity cornell-moderate "$tmp/cornell.lcb" "$work/cornell-reference")"
results+=("$(jq -c '{name: "cornell-moderate", scene: "cornell-box (embedded)", state: "daemon initial state (ceiling lamp, emissive 17/12/4 nits)",
  preset: "moderate", links: .links_per_cache, surfels: .surfels, bands: .bands,
  lightmap, grid, bound, reference, relights, b0_power_engine, b0_power_reference, '"$surface_fields"'}' "$f")")
jq -r '"  lightmap mean \(.lightmap.mean*100)% p95 \(.lightmap.p95*100)% (ref noise \(.lightmap.ref_noise*100)%)"' "$f" >&2
preset_row cornell moderate "$tmp/cornell.lcb" "$f" || echo "fidelity: cornell preset moderate failed" >&2
# served: the daemon's initial state is the reference's (the lamp, no lights); one change: a point
# light added under the ceiling, off the lamp
served_row cornell-served cornell-moderate "cornell-box (embedded)" "$tmp/cornell.lcb" "$work/cornell-reference" ||
  echo "fidelity: cornell-served failed" >&2
converge_row cornell-served "$tmp/cornell.lcb" "$work/cornell-reference/reference_texels.bin" \
  '{"type": "light.set", "light": {"id": "served-probe", "type": "point", "position": [0.15, 0.4, 0.2], "color": [1, 0.9, 0.8], "intensity": 0.05}}' ||
  echo "fidelity: cornell-served convergence failed" >&2

# Bounce-by-bounce (diagnostics): only the lamp seen directly (0) and one reflection (1).
for b in 0 1; do
  "$bin/lucent-ref" render "$tmp/cornell.lcb" --out "$work/cornell-reference-b$b" --spp 4096 --batch 1024 \
      --bounce-limit "$b" --quiet --threads "$threads" 2>/dev/null
  f="$(fidelity "cornell-moderate-b$b" "$tmp/cornell.lcb" "$work/cornell-reference-b$b" --bounce-limit "$b")"
  results+=("$(jq -c --arg b "$b" '{name: ("cornell-moderate-bounces" + $b), bounce_limit: ($b|tonumber), lightmap, grid, bound}' "$f")")
done

# --- 2. Trade-off: links, surfels, bands (the paper's Figure 10, measured here) -----------------
if [ "${TRADEOFF:-1}" != 0 ]; then
  variants=("links=32:--links 32" "links=64:--links 64" "links=256:--links 256" "links=512:--links 512"
            "surfels=8192:--surfels 8192" "surfels=16384:--surfels 16384" "surfels=65536:--surfels 65536"
            "surfels=131072:--surfels 131072"
            "bands=1:--bands 1" "bands=2:--bands 2" "bands=4:--bands 4"
            "high:--quality high --atlas-size 64 --grid-max-samples 1024"
            "ultra:--quality ultra --atlas-size 64 --grid-max-samples 1024")
  for v in "${variants[@]}"; do
    name="${v%%:*}"; flags="${v#*:}"
    echo "fidelity: Cornell trade-off $name..." >&2
    # shellcheck disable=SC2086
    bake "$tmp/cornell-v.lcb" "$cornell_obj" "${cornell_flags[@]}" $flags
    f="$(fidelity "cornell-$name" "$tmp/cornell-v.lcb" "$work/cornell-reference")" || continue
    results+=("$(jq -c --arg n "cornell-$name" --arg fl "$flags" '{name: $n, bake_flags: $fl, links: .links_per_cache,
      surfels: .surfels, bands: .bands, ms_first_relight, lightmap, grid, bound}' "$f")")
    case "$name" in high|ultra)
      preset_row cornell "$name" "$tmp/cornell-v.lcb" "$f" || echo "fidelity: cornell preset $name failed" >&2 ;;
    esac
  done
fi

# --- 3. Sponza under the sun --------------------------------------------------------------------
sponza="$shared/scenes/sponza-dabrovic/sponza.obj"
if [ -f "$sponza" ]; then
  echo "fidelity: sponza-dabrovic: bake + reference ($sponza_spp spp)..." >&2
  cat >"$tmp/sun.json" <<'EOF'
{"type": "state", "revision": 1,
 "lights": [{"id": "sun", "type": "directional", "color": [1, 0.95, 0.9], "intensity": 100000,
             "direction": [0.3, -1, 0.2]}],
 "objects": [], "materials": [], "environment": {"type": "none"}, "settings": {}}
EOF
  cp "$tmp/sun.json" "$work/sponza-sun-state.json"
  bake "$tmp/sponza.lcb" "$sponza" --quality moderate --quiet --no-write-glb --threads "$threads"
  "$bin/lucent-ref" render "$tmp/sponza.lcb" --state "$tmp/sun.json" --out "$work/sponza-reference" \
      --spp "$sponza_spp" --batch 1024 --quiet --threads "$threads" 2>"$work/sponza-reference.txt"
  f="$(fidelity sponza-moderate "$tmp/sponza.lcb" "$work/sponza-reference" --state "$tmp/sun.json")"
  results+=("$(jq -c '{name: "sponza-moderate-sun", scene: "sponza-dabrovic", state: "directional (0.3,-1,0.2), 100000 lux, colour (1,0.95,0.9)",
    preset: "moderate", links: .links_per_cache, surfels: .surfels, bands: .bands, lightmap, grid, bound, reference,
    relights, b0_power_engine, b0_power_reference, '"$surface_fields"'}' "$f")")
  jq -r '"  lightmap mean \(.lightmap.mean*100)% (ref noise \(.lightmap.ref_noise*100)%)"' "$f" >&2
  preset_row sponza-dabrovic moderate "$tmp/sponza.lcb" "$f" || echo "fidelity: sponza preset moderate failed" >&2
  served_row sponza-sun-served sponza-moderate-sun sponza-dabrovic "$tmp/sponza.lcb" "$work/sponza-reference" \
    "$tmp/sun.json" || echo "fidelity: sponza-sun-served failed" >&2
  # one change: the sun 10 degrees lower (elevation 70.2 -> 60.2 degrees, same azimuth)
  converge_row sponza-served "$tmp/sponza.lcb" "$work/sponza-reference/reference_texels.bin" \
    '{"type": "light.set", "light": {"id": "sun", "type": "directional", "color": [1, 0.95, 0.9], "intensity": 100000, "direction": [0.4136, -0.8678, 0.2757]}}' \
    "$tmp/sun.json" || echo "fidelity: sponza-served convergence failed" >&2
  for v in "list-refine=0:--list-refine 0" "surfels=65536:--surfels 65536" "surfels=131072:--surfels 131072" \
           "links=512:--links 512" "exposure:--exposure" "links=256:--links 256" \
           "high:--quality high" "ultra:--quality ultra"; do
    name="${v%%:*}"; flags="${v#*:}"
    echo "fidelity: sponza $name..." >&2
    # shellcheck disable=SC2086
    bake "$tmp/sponza-v.lcb" "$sponza" --quality moderate --quiet --no-write-glb --threads "$threads" $flags
    f="$(fidelity "sponza-$name" "$tmp/sponza-v.lcb" "$work/sponza-reference" --state "$tmp/sun.json")" || continue
    results+=("$(jq -c --arg n "sponza-$name" --arg fl "$flags" '{name: $n, bake_flags: $fl, links: .links_per_cache,
      surfels: .surfels, bands: .bands, lightmap, grid, bound}' "$f")")
    case "$name" in high|ultra)
      preset_row sponza-dabrovic "$name" "$tmp/sponza-v.lcb" "$f" || echo "fidelity: sponza preset $name failed" >&2 ;;
    esac
  done
else
  echo "fidelity: skip sponza-dabrovic: $sponza absent" >&2
fi

# --- 4. Sibenik and the conference room: interiors under point lights ---------------------------
# name | scene | bake flags | lights (state JSON "lights" array; positions in metres after --scale)
others=(
  'sibenik|sibenik/sibenik.obj||[{"id": "nave-a", "type": "point", "position": [-10, -9, 0], "color": [1, 0.9, 0.75], "intensity": 3000}, {"id": "nave-b", "type": "point", "position": [0, -9, 0], "color": [1, 0.9, 0.75], "intensity": 3000}, {"id": "nave-c", "type": "point", "position": [10, -9, 0], "color": [1, 0.9, 0.75], "intensity": 3000}]'
  'conference-room|conference-room/conference.obj|--scale 0.003|[{"id": "ceiling-a", "type": "point", "position": [0, 1.6, -0.6], "color": [1, 0.95, 0.85], "intensity": 50}, {"id": "ceiling-b", "type": "point", "position": [2.5, 1.6, -0.6], "color": [1, 0.95, 0.85], "intensity": 50}]'
)
for entry in "${others[@]}"; do
  IFS='|' read -r name scene flags lights <<<"$entry"
  file="$shared/scenes/$scene"
  if [ ! -f "$file" ]; then
    echo "fidelity: skip $name: $file absent" >&2
    continue
  fi
  echo "fidelity: $name: bake + reference ($other_spp spp)..." >&2
  printf '{"type": "state", "revision": 1, "lights": %s, "objects": [], "materials": [], "environment": {"type": "none"}, "settings": {}}\n' \
    "$lights" >"$work/$name-points-state.json"
  # shellcheck disable=SC2086
  bake "$tmp/$name.lcb" "$file" --quality moderate --quiet --no-write-glb --threads "$threads" $flags
  "$bin/lucent-ref" render "$tmp/$name.lcb" --state "$work/$name-points-state.json" --out "$work/$name-reference" \
      --spp "$other_spp" --batch 1024 --quiet --threads "$threads" 2>"$work/$name-reference.txt"
  f="$(fidelity "$name-moderate" "$tmp/$name.lcb" "$work/$name-reference" --state "$work/$name-points-state.json")" || continue
  results+=("$(jq -c --arg n "$name-moderate-points" --arg sc "$name" '{name: $n, scene: $sc, state: "point lights (bench/fidelity.sh)",
    preset: "moderate", links: .links_per_cache, surfels: .surfels, bands: .bands, lightmap, grid, bound, reference,
    relights, '"$surface_fields"'}' "$f")")
  jq -r '"  lightmap mean \(.lightmap.mean*100)% bound \(.bound.mean*100)% (ref noise \(.lightmap.ref_noise*100)%)"' "$f" >&2
  preset_row "$name" moderate "$tmp/$name.lcb" "$f" || echo "fidelity: $name preset moderate failed" >&2
  served_row "$name-points-served" "$name-moderate-points" "$name" "$tmp/$name.lcb" "$work/$name-reference" \
    "$work/$name-points-state.json" || echo "fidelity: $name-points-served failed" >&2
  rm -f "$tmp/$name.lcb"
  for preset in ${other_presets[@]+"${other_presets[@]}"}; do
    echo "fidelity: $name $preset..." >&2
    # shellcheck disable=SC2086
    bake "$tmp/$name-v.lcb" "$file" --quality "$preset" --quiet --no-write-glb --threads "$threads" $flags
    f="$(fidelity "$name-$preset" "$tmp/$name-v.lcb" "$work/$name-reference" --state "$work/$name-points-state.json")" ||
      continue
    preset_row "$name" "$preset" "$tmp/$name-v.lcb" "$f" || echo "fidelity: $name preset $preset failed" >&2
    rm -f "$tmp/$name-v.lcb"
  done
done

conv_file="$tmp/convergence.jsonl"
printf '%s\n' ${convergence[@]+"${convergence[@]}"} >"$conv_file"
printf '%s\n' "${results[@]}" | jq -s --arg date "$(date -u +%FT%TZ)" --arg host "$(uname -n)" \
  --slurpfile conv "$conv_file" \
  '{bench: "fidelity", date: $date, host: $host,
    metric: "relative error of luminance per texel (owners, > 1% of the brightest reference texel); grid: sum over 14 directions of |dE| / sum E",
    targets: {scene_mean: 0.12, scene_bias: 0.05, scene_p95: 0.35, scene_grid_mean: 0.12,
              cornell_mean: 0.04, cornell_p95: 0.10, cornell_bias: 0.02, texel_spacing_m: 0.5, blotch_ratio: 1.2,
              t_within_1pct_ms: 500},
    results: ., convergence: $conv}' >"$out_json"
echo "fidelity: wrote $out_json" >&2
