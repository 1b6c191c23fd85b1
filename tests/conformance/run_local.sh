#!/bin/bash
# Run the lucent/1 conformance suite against this repository's lucentd: start it on a free
# port with a temporary state dir and a config holding a controller and a viewer token, run
# lucent-conformance, stop the daemon. Exit 77 (skip) when lucentd or lucent-bake is not
# built; exit 1 when the Cornell bake with its asset fails.
# Extra arguments go to lucent-conformance (e.g. -k frames, --json out.json).
# LUCENT_CONF_CLUSTER=1: the daemon is a replica of a cluster (lucentd --cluster, PROTOCOL.md
# §9) whose log is a redis-server started here; to a client it must be a plain lucent/1 server.
set -u
HERE="$(cd "$(dirname "$0")" && pwd)"
BIN="${LUCENT_BINARY_DIR:-$HERE/../../build}"
LUCENTD="$BIN/bin/lucentd"
LUCENT_BAKE="$BIN/bin/lucent-bake"
SCENE="$HERE/../../scenes/cornell-box"
if [ ! -x "$LUCENTD" ] || [ ! -x "$LUCENT_BAKE" ]; then
  echo "SKIP: $LUCENTD or $LUCENT_BAKE is not built"
  exit 77
fi

TMP="$(mktemp -d)"
PID=""
REDIS_PID=""
cleanup() {
  [ -n "$REDIS_PID" ] && kill -TERM "$REDIS_PID" 2>/dev/null && wait "$REDIS_PID" 2>/dev/null
  if [ -n "$PID" ] && kill -0 "$PID" 2>/dev/null; then
    kill -TERM "$PID" 2>/dev/null
    for _ in $(seq 1 100); do kill -0 "$PID" 2>/dev/null || break; sleep 0.1; done
    kill -KILL "$PID" 2>/dev/null
    wait "$PID" 2>/dev/null
  fi
  rm -rf "$TMP"
}
trap cleanup EXIT INT TERM

# Serve the Cornell box baked here (draft) with one dynamic-object asset, so
# object.set/object.remove are testable, and with both solvers (PIC the default), so
# settings.solver probes is too. A failed bake fails the run: a fallback to another
# bake would hide the failure, and a bake without the asset would only skip the object cases.
BAKE="$TMP/scene.lcb"
if ! "$LUCENT_BAKE" bake "$SCENE/cornell-box.obj" -o "$BAKE" --quality draft --asset cube="$SCENE/cube.obj" \
     --solver both --probes 8 --probe-bands 4 --quiet --no-write-glb > "$TMP/bake.log" 2>&1 || [ ! -s "$BAKE" ]; then
  echo "FAIL: the conformance bake failed (lucent-bake bake $SCENE/cornell-box.obj --asset cube=$SCENE/cube.obj);"
  echo "      without its asset the object cases (object.set / object.remove) cannot run. lucent-bake said:"
  sed 's/^/      /' "$TMP/bake.log"
  exit 1
fi

CTL="ctl-$RANDOM$RANDOM"
VIEW="view-$RANDOM$RANDOM"
cat > "$TMP/lucentd.json" <<EOF
{"controller-tokens": ["$CTL"], "viewer-tokens": ["$VIEW"]}
EOF

CLUSTER=()
if [ "${LUCENT_CONF_CLUSTER:-0}" = 1 ]; then
  command -v redis-server >/dev/null || { echo "FAIL: LUCENT_CONF_CLUSTER=1 needs redis-server"; exit 1; }
  RPORT="$(/usr/bin/python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])')"
  mkdir -p "$TMP/redis"
  redis-server --port "$RPORT" --bind 127.0.0.1 --dir "$TMP/redis" --appendonly yes --appendfsync always \
    --save "" > "$TMP/redis.log" 2>&1 &
  REDIS_PID=$!
  CLUSTER=(--cluster "redis://127.0.0.1:$RPORT/conformance")
fi

mkfifo "$TMP/out"
"$LUCENTD" --config "$TMP/lucentd.json" --bake "$BAKE" --port 0 --state-dir "$TMP/state" \
  --backend cpu --log-level warn "${CLUSTER[@]}" > "$TMP/out" 2> "$TMP/lucentd.log" &
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

# A replica is ready once it caught up with its log (/healthz 200).
if [ ${#CLUSTER[@]} -gt 0 ] && ! /usr/bin/python3 - "$PORT" <<'PY'
import sys, time, urllib.request
end = time.time() + 30
while time.time() < end:
    try:
        if urllib.request.urlopen("http://127.0.0.1:%s/healthz" % sys.argv[1], timeout=2).status == 200:
            sys.exit(0)
    except Exception:
        pass
    time.sleep(0.1)
sys.exit(1)
PY
then
  echo "the cluster replica never became ready:"
  cat "$TMP/lucentd.log"
  exit 1
fi

# lucent-bake's defaults give the cube asset a DNRT transfer grid of 32^3 vertices, 4 SH
# coefficients: welcome.scene.asset_info must say so (test_messages.test_welcome_asset_info).
LUCENT_CONF_EXPECT_TRANSFER="cube=32x4" \
/usr/bin/python3 "$HERE/lucent-conformance" "ws://127.0.0.1:$PORT/" --token "$CTL" \
  --controller-token "$CTL" --viewer-token "$VIEW" "$@"
RC=$?
if ! kill -0 "$PID" 2>/dev/null; then
  echo "lucentd died during the run:"
  cat "$TMP/lucentd.log"
  RC=1
fi
exit $RC
