#!/usr/bin/env bash
# The main job on the embedded default scene: build (which bakes the Cornell box), start
# lucentd on it, drive it with a scripted light animation and a walking object through
# lucentctl while another lucentctl saves the lightmap frames it streams, then print the
# update->frame latencies, and the viewer's URL. On a terminal it then keeps lucentd and the
# light animation running until Ctrl-C, so the printed link shows the light moving
# (LUCENT_DEMO_ONCE=1: stop after the latencies). Everything lands in build/demo/ (override:
# LUCENT_DEMO_DIR).
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
bash "$root/scripts/build.sh"
build="${LUCENT_BUILD_DIR:-$root/build}"
bin="$build/bin"
out="${LUCENT_DEMO_DIR:-$build/demo}"
rm -rf "$out"
mkdir -p "$out"

echo "== the bake: $build/cornell.lcb"
"$bin/lucent-bake" info "$build/cornell.lcb" | head -n 12

echo "== starting lucentd (embedded Cornell box, CPU backend)"
"$bin/lucentd" --port 0 --state-dir "$out/state" --backend cpu --log-level warn \
    >"$out/lucentd.out" 2>"$out/lucentd.log" &
daemon=$!
watcher=""
cleanup() {
    [ -n "$watcher" ] && kill "$watcher" 2>/dev/null && wait "$watcher" 2>/dev/null
    kill "$daemon" 2>/dev/null && wait "$daemon" 2>/dev/null
    return 0
}
trap cleanup EXIT
port=""
for _ in $(seq 1 400); do
    port="$(sed -n 's/^lucentd listening port=\([0-9]*\).*/\1/p' "$out/lucentd.out" 2>/dev/null)"
    [ -n "$port" ] && break
    kill -0 "$daemon" 2>/dev/null || { cat "$out/lucentd.log" >&2; exit 1; }
    sleep 0.05
done
[ -n "$port" ] || { echo "lucentd did not start; see $out/lucentd.log" >&2; exit 1; }
export LUCENT_URL="ws://127.0.0.1:$port/"
echo "   listening on $LUCENT_URL"

echo "== lucentctl watch: saving lightmap frames (EXR + PNG, at most 4 per second) to $out/frames"
"$bin/lucentctl" watch --stream lightmap --out "$out/frames" --max-rate 4 >"$out/watch.log" 2>&1 &
watcher=$!
sleep 0.5

echo "== lucentctl script examples/orbit.jsonl (a point light orbiting the box)"
"$bin/lucentctl" script "$root/examples/orbit.jsonl"
echo "== lucentctl script examples/walking-object.jsonl (a cube walking across the floor)"
"$bin/lucentctl" script --speed 2 "$root/examples/walking-object.jsonl"

echo "== lucentctl snapshot: the final frames of every stream"
"$bin/lucentctl" snapshot --out "$out/snapshot"

echo "== lucentctl latency: update -> frame at the client (50 light updates at 10 per second)"
"$bin/lucentctl" latency --count 50 --interval 0.1

kill "$watcher" 2>/dev/null && wait "$watcher" 2>/dev/null || true
watcher=""
frames=$(find "$out/frames" -name 'lightmap-*.png' | wc -l)
echo "== done: $frames lightmap frames in $out/frames (frames.jsonl indexes them),"
echo "   final snapshot in $out/snapshot, daemon log $out/lucentd.log"

viewer="http://127.0.0.1:$port/"
if [ ! -f "$build/share/lucent/www/index.html" ]; then
  echo "== no viewer in this build (node and npm were missing when it was configured)"
  viewer=""
fi
if [ -t 1 ] && [ -z "${LUCENT_DEMO_ONCE:-}" ]; then
  [ -n "$viewer" ] && echo "== open $viewer in a browser to watch the light move"
  echo "== lucentd keeps running on $LUCENT_URL with the orbit animation; Ctrl-C stops both"
  while kill -0 "$daemon" 2>/dev/null; do
    "$bin/lucentctl" script "$root/examples/orbit.jsonl" >/dev/null || break
  done
elif [ -n "$viewer" ]; then
  echo "== viewer: $viewer (lucentd stops with this script: run it on a terminal to keep it)"
fi
