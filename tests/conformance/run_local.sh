#!/bin/bash
# Run the lucent/1 conformance suite against this repository's lucentd: start it on a free
# port with a temporary state dir and a config holding a controller and a viewer token, run
# lucent-conformance, stop the daemon. Exit 77 (skip) when lucentd or the bake is not built.
# Extra arguments go to lucent-conformance (e.g. -k frames, --json out.json).
set -u
HERE="$(cd "$(dirname "$0")" && pwd)"
BIN="${LUCENT_BINARY_DIR:-$HERE/../../build}"
LUCENTD="$BIN/bin/lucentd"
BAKE="$BIN/cornell.lcb"
if [ ! -x "$LUCENTD" ] || [ ! -f "$BAKE" ]; then
  echo "SKIP: $LUCENTD or $BAKE is not built"
  exit 77
fi

TMP="$(mktemp -d)"
PID=""
cleanup() {
  if [ -n "$PID" ] && kill -0 "$PID" 2>/dev/null; then
    kill -TERM "$PID" 2>/dev/null
    for _ in $(seq 1 100); do kill -0 "$PID" 2>/dev/null || break; sleep 0.1; done
    kill -KILL "$PID" 2>/dev/null
    wait "$PID" 2>/dev/null
  fi
  rm -rf "$TMP"
}
trap cleanup EXIT INT TERM

# Serve the Cornell box with one dynamic-object asset, so object.set/object.remove are
# testable (the embedded bake has no assets).
if [ -x "$BIN/bin/lucent-bake" ]; then
  if "$BIN/bin/lucent-bake" bake "$HERE/../../scenes/cornell-box/cornell-box.obj" -o "$TMP/scene.lcb" \
       --quality draft --asset cube="$HERE/../../scenes/cornell-box/cube.obj" --quiet --no-write-glb; then
    BAKE="$TMP/scene.lcb"
  fi
fi

CTL="ctl-$RANDOM$RANDOM"
VIEW="view-$RANDOM$RANDOM"
cat > "$TMP/lucentd.json" <<EOF
{"controller-tokens": ["$CTL"], "viewer-tokens": ["$VIEW"]}
EOF

mkfifo "$TMP/out"
"$LUCENTD" --config "$TMP/lucentd.json" --bake "$BAKE" --port 0 --state-dir "$TMP/state" \
  --backend cpu --log-level warn > "$TMP/out" 2> "$TMP/lucentd.log" &
PID=$!
exec 3< "$TMP/out"
PORT=""
if read -r -t 30 line <&3; then
  case "$line" in *port=*) PORT="${line##*port=}"; PORT="${PORT%%[!0-9]*}" ;; esac
fi
# keep draining the daemon's stdout so it never blocks on a full pipe
cat <&3 > /dev/null &
if [ -z "$PORT" ]; then
  echo "lucentd did not start: ${line:-no output}"
  cat "$TMP/lucentd.log"
  exit 1
fi

/usr/bin/python3 "$HERE/lucent-conformance" "ws://127.0.0.1:$PORT/" --token "$CTL" \
  --controller-token "$CTL" --viewer-token "$VIEW" "$@"
RC=$?
if ! kill -0 "$PID" 2>/dev/null; then
  echo "lucentd died during the run:"
  cat "$TMP/lucentd.log"
  RC=1
fi
exit $RC
