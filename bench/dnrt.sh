#!/usr/bin/env bash
# DNRT and DRT against the path tracer: the change dE = E(with object) - E(without) an object
# makes to the lightmap, per texel, engine against lucent-ref (`lucent-ref delta`), for the
# engine with DNRT (the default bake), with DRT (the same bake, the objects in mode clutter:
# their operators built as lucentd builds them once they rest) and without either (the bake
# with --no-transfer: placed objects only shadow the direct light). Cases on the embedded Cornell box: a white cube on
# the floor, a red cube by the wall, both side by side; with --sponza, a 1 m white cube in
# sunlit Sponza (../shared/scenes); --no-cornell skips the Cornell cases.
#
# Usage: bench/dnrt.sh [--build DIR] [--out DIR] [--spp N] [--sponza] [--no-cornell]
# Prints one table row per case and engine; writes OUT/dnrt.json.
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
build="$root/build" out="$root/bench/out/dnrt" spp=8192 sponza=0 do_cornell=1
while [ $# -gt 0 ]; do
    case "$1" in
    --build) build="$2"; shift 2 ;;
    --out) out="$2"; shift 2 ;;
    --spp) spp="$2"; shift 2 ;;
    --sponza) sponza=1; shift ;;
    --no-cornell) do_cornell=0; shift ;;
    -h | --help) sed -n '2,11p' "$0"; exit 0 ;;
    *) echo "bench/dnrt.sh: unknown argument $1 (see --help)" >&2; exit 2 ;;
    esac
done
bake="$build/bin/lucent-bake" ref="$build/bin/lucent-ref"
for t in "$bake" "$ref"; do
    [ -x "$t" ] || { echo "bench/dnrt.sh: $t missing: build first (cmake --build $build)" >&2; exit 1; }
done
mkdir -p "$out/assets"
step() { printf '\n== %s (%s)\n' "$1" "$(date +%H:%M:%S)" >&2; }

# The assets: the repository's 10 cm cube, white (no material: the importer's default
# albedo) and red (the Cornell box's red).
cp "$root/scenes/cornell-box/cube.obj" "$out/assets/white.obj"
printf 'newmtl red\nKd 0.63 0.065 0.05\n' >"$out/assets/red.mtl"
{ echo "mtllib red.mtl"; echo "usemtl red"; grep -v '^#' "$root/scenes/cornell-box/cube.obj"; } >"$out/assets/red.obj"
assets=(--asset "white=$out/assets/white.obj" --asset "red=$out/assets/red.obj")

object() { # id asset x y z scale
    printf '{"id":"%s","asset":"%s","translation":[%s,%s,%s],"rotation":[0,0,0,1],"scale":[%s,%s,%s],"visible":true}' \
        "$1" "$2" "$3" "$4" "$5" "$6" "$6" "$6"
}
state() { # file lights-json objects-json...
    local f="$1" lights="$2"
    shift 2
    local objs
    objs="$(IFS=,; echo "$*")"
    printf '{"type":"state","revision":1,"lights":[%s],"objects":[%s],"materials":[],"environment":{"type":"none"},"settings":{}}\n' \
        "$lights" "$objs" >"$f"
}

# One scene: bake with and without transfer data, a reference per state, the engine's
# converged lightmap per state and bake, then the delta rows.
run_scene() { # name source scale-flags lights-json spp case=objects...
    local name="$1" src="$2" flags="$3" lights="$4" sspp="$5"
    shift 5
    local dir="$out/$name"
    mkdir -p "$dir"
    step "$name: bakes (with and without transfer grids)"
    # shellcheck disable=SC2086
    "$bake" bake "$src" -o "$dir/dnrt.lcb" --no-write-glb --quiet $flags "${assets[@]}"
    # shellcheck disable=SC2086
    "$bake" bake "$src" -o "$dir/plain.lcb" --no-write-glb --quiet --no-transfer $flags "${assets[@]}"
    state "$dir/none.json" "$lights"
    local cases=(none)
    for c in "$@"; do
        local cname="${c%%=*}" objs="${c#*=}"
        IFS=';' read -r -a list <<<"$objs"
        state "$dir/$cname.json" "$lights" "${list[@]}"
        cases+=("$cname")
    done
    for c in "${cases[@]}"; do
        if [ ! -f "$dir/ref-$c/reference.json" ]; then
            step "$name: reference '$c' ($sspp spp)"
            "$ref" render "$dir/dnrt.lcb" --state "$dir/$c.json" --out "$dir/ref-$c" --spp "$sspp" --quiet
        fi
        # the same state with every object in mode clutter (DRT operators, PROTOCOL.md §4.5)
        sed 's/"visible":true}/"visible":true,"mode":"clutter"}/g' "$dir/$c.json" >"$dir/$c-clutter.json"
        for b in dnrt drt plain; do
            step "$name: engine '$c' ($b)"
            local lcb="$dir/$b.lcb" st="$dir/$c.json"
            [ "$b" = drt ] && lcb="$dir/dnrt.lcb" st="$dir/$c-clutter.json"
            "$ref" fidelity "$lcb" --state "$st" --reference "$dir/ref-$c" --out "$dir/fid-$b-$c" \
                --bound-rays 0 --backend cpu --quiet >"$dir/fid-$b-$c.txt"
            grep '^clutter:' "$dir/fid-$b-$c.txt" >&2 || true
        done
    done
    for c in "${cases[@]:1}"; do
        for b in dnrt drt plain; do
            "$ref" delta --reference "$dir/ref-none" --reference-with "$dir/ref-$c" \
                --lightmap "$dir/fid-$b-none/engine_lightmap.exr" --lightmap-with "$dir/fid-$b-$c/engine_lightmap.exr" \
                --out "$dir/delta-$b-$c" >"$dir/delta-$b-$c.txt"
            printf '%-10s %-14s %-6s %s\n' "$name" "$c" "$b" "$(head -1 "$dir/delta-$b-$c.txt")"
        done
    done
}

cornell="$root/scenes/cornell-box/cornell-box.obj"
if [ "$do_cornell" = 1 ]; then
    run_scene cornell "$cornell" "" "" "$spp" \
        "white=$(object w white 0.42 0 0.1 1.5)" \
        "red-wall=$(object r red 0.48 0 0.1 1.2)" \
        "two=$(object r red 0.40 0 0.22 1.2);$(object w white 0.40 0 0.08 1.2)"
fi
if [ "$sponza" = 1 ]; then
    sp="$root/../shared/scenes/sponza-dabrovic/sponza.obj"
    if [ -f "$sp" ]; then
        sun='{"id":"sun","type":"directional","color":[1,0.95,0.9],"intensity":100000,"direction":[0.3,-1,0.2]}'
        run_scene sponza "$sp" "" "$sun" 4096 "cube=$(object c white 2 0 0 10)"
    else
        echo "bench/dnrt.sh: $sp absent: Sponza skipped" >&2
    fi
fi

/usr/bin/python3 - "$out" <<'EOF'
import glob, json, os, sys
out = sys.argv[1]
rows = []
for f in sorted(glob.glob(os.path.join(out, "*", "delta-*", "delta.json"))):
    scene = f.split(os.sep)[-3]
    _, engine, case = os.path.basename(os.path.dirname(f)).split("-", 2)
    d = json.load(open(f))
    d.update(scene=scene, case=case, engine=engine)
    rows.append(d)
json.dump(rows, open(os.path.join(out, "dnrt.json"), "w"), indent=1)
print("%-8s %-9s %-6s %6s %8s %8s %6s %8s %9s %7s" % ("scene", "case", "engine", "n", "error", "bias", "sign",
      "darker", "brighter", "noise"))
for r in rows:
    print("%-8s %-9s %-6s %6d %7.1f%% %+7.1f%% %5.1f%% %8.3f %9.3f %6.1f%%" % (r["scene"], r["case"], r["engine"], r["n"],
          100 * r["error"], 100 * r["bias"], 100 * r["sign_agree"], r["darker_ratio"], r["brighter_ratio"],
          100 * r["ref_noise"]))
EOF
