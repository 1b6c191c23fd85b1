#!/usr/bin/env bash
# MR sessions (LightSkin, issue 18) against the path tracer, as a client gets them: the
# embedded Cornell box is the "real room"; `lucent-ref capture` records it as an RGB-D
# camera (the room without the virtual object); lucentd (its defaults) lights a virtual cube
# placed inside from `lucentctl mr replay` of that recording; the irradiance each of the
# cube's sparse points gets from the mr.vpl stream (E_d = I_d cos / d^2, what a client's
# Phong term gives there) is compared with `lucent-ref mr-truth` at the same points:
#   (i)  server vs visible: a path trace whose only emitters are the patches the camera saw
#        (LightSkin's own error: filter, disc lights, averaging, occlusion, pixel merging);
#   (ii) visible vs full: the capture's limit (what the camera cannot see: rear sides,
#        surfaces outside the view, the light that reaches them);
# and the temporal stability under camera jitter (frame-to-frame change of each point's E
# against the change of its visible truth), the upload bytes per frame and the server's
# time per frame.
#
# Usage: bench/mr.sh [--build DIR] [--out DIR] [--spp N] [--quick]
# Prints the tables; writes OUT/mr.json.
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
build="$root/build" out="$root/bench/out/mr" spp=4096 frames=10 cspp=64
while [ $# -gt 0 ]; do
    case "$1" in
    --build) build="$2"; shift 2 ;;
    --out) out="$2"; shift 2 ;;
    --spp) spp="$2"; shift 2 ;;
    --quick) spp=1024 frames=4 cspp=16; shift ;;
    -h | --help) sed -n '2,17p' "$0"; exit 0 ;;
    *) echo "bench/mr.sh: unknown argument $1 (see --help)" >&2; exit 2 ;;
    esac
done
ref="$build/bin/lucent-ref" ctl="$build/bin/lucentctl" lucentd="$build/bin/lucentd" lcb="$build/cornell.lcb"
for t in "$ref" "$ctl" "$lucentd" "$lcb"; do
    [ -e "$t" ] || { echo "bench/mr.sh: $t missing: build first (cmake --build $build)" >&2; exit 1; }
done
rm -rf "$out" && mkdir -p "$out"
step() { printf '\n== %s (%s)\n' "$1" "$(date +%H:%M:%S)" >&2; }
eye=0.278,0.273,-0.8 target=0.278,0.273,0
# the virtual cube: 15 cm, its base 10 cm above the floor, in the free space in front of the tall
# block and beside the short one (the real blocks must not hold it)
place='"asset": "cube", "translation": [0.42, 0.1, 0.12], "rotation": [0, 0, 0, 1], "scale": 1.5'

step "captures of the Cornell box (256x192, $cspp paths per pixel): one still, $frames jittered (5 mm, 0.5 deg)"
"$ref" capture "$lcb" --out "$out/still" --eye $eye --target $target --spp "$cspp" --quiet
"$ref" capture "$lcb" --out "$out/jitter" --eye $eye --target $target --spp "$cspp" --frames "$frames" \
    --jitter-mm 5 --jitter-deg 0.5 --seed 7 --quiet

start_lucentd() { # name flags...: sets pid and url, the cube placed
    local name="$1"
    shift
    "$lucentd" --bake "$lcb" --port 0 --state-dir "$out/state-$name" --backend cpu --log-level warn "$@" \
        >"$out/lucentd-$name.out" 2>"$out/lucentd-$name.err" &
    pid=$!
    trap 'kill $pid 2>/dev/null || true' EXIT
    local port=""
    for _ in $(seq 100); do
        port="$(sed -n 's/^lucentd listening port=\([0-9]*\).*/\1/p' "$out/lucentd-$name.out")"
        [ -n "$port" ] && break
        sleep 0.1
    done
    [ -n "$port" ] || { echo "bench/mr.sh: lucentd did not start: $(tail -3 "$out/lucentd-$name.err")" >&2; exit 1; }
    url="ws://127.0.0.1:$port/"
    "$ctl" --url "$url" object set mrcube --asset cube --position 0.42,0.1,0.12 --scale 1.5 >/dev/null
}

step "lucentd with one light per pixel (--mr-max-lights 49152: no merging) and lucentctl mr replay"
start_lucentd nomerge --mr-max-lights 49152
"$ctl" --url "$url" mr replay "$out/still" --objects mrcube --quiet --vpl-out "$out/still-nomerge.vpl.jsonl" \
    >"$out/still-nomerge.summary"
kill $pid && wait $pid || true

step "lucentd (defaults) and lucentctl mr replay"
start_lucentd default
"$ctl" --url "$url" mr replay "$out/still" --objects mrcube --quiet --vpl-out "$out/still.vpl.jsonl" \
    >"$out/still.summary"
"$ctl" --url "$url" mr replay "$out/still" --objects mrcube --quiet --zlib >"$out/still-zlib.summary"
"$ctl" --url "$url" mr replay "$out/jitter" --objects mrcube --quiet --vpl-out "$out/jitter.vpl.jsonl" \
    >"$out/jitter.summary"
"$ctl" --url "$url" mr replay "$out/jitter" --objects mrcube --quiet --smoothing 0.5 \
    --vpl-out "$out/jitter-smooth.vpl.jsonl" >"$out/jitter-smooth.summary"
kill $pid && wait $pid || true
trap - EXIT

step "truths at the cube's 256 sparse points ($spp samples each): full and visible, frame 1 of each recording"
printf '{"occluders": {"objects": [{%s, "sparse_points": true}]}}\n' "$place" >"$out/points.json"
"$ref" mr-truth "$lcb" --capture "$out/still" --points "$out/points.json" --out "$out/truth-still.json" \
    --spp "$spp" --quiet
for k in $(seq "$frames"); do
    "$ref" mr-truth "$lcb" --capture "$out/jitter" --frame "$k" --points "$out/points.json" \
        --out "$out/truth-jitter-$k.json" --spp "$((spp / 4))" --quiet
done

step "comparison"
/usr/bin/python3 "$root/bench/mr_compare.py" "$out" "$frames"
