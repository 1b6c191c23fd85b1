# lucentctl against a live lucentd: ping, light set/rm, state, errors and exit codes.
. "$(dirname "$0")/lib.sh"
BIN="${LUCENT_BINARY_DIR:?run through ctest}/bin"
CTL="$BIN/lucentctl"
if [ ! -x "$BIN/lucentd" ] || [ ! -x "$CTL" ]; then echo "lucentd/lucentctl not built: skip"; exit 77; fi

"$BIN/lucentd" --port 0 --state-dir "$TMP/state" --backend cpu --log-level warn >"$TMP/d.out" 2>"$TMP/d.err" &
DPID=$!
trap 'kill "$DPID" 2>/dev/null; wait "$DPID" 2>/dev/null; rm -rf "$TMP"' EXIT
PORT=""
for _ in $(seq 1 200); do
  PORT="$(sed -n 's/^lucentd listening port=\([0-9]*\).*/\1/p' "$TMP/d.out")"
  [ -n "$PORT" ] && break
  kill -0 "$DPID" 2>/dev/null || break
  sleep 0.05
done
if [ -z "$PORT" ]; then echo "FAIL: lucentd did not start: $(head -c 400 "$TMP/d.err")" >&2; exit 1; fi
export LUCENT_URL="ws://127.0.0.1:$PORT/"

expect_exit 0 "" timeout 20 "$CTL" ping
expect_exit 0 "" timeout 20 "$CTL" light set key --type point --position 0.2,0.4,0.3 --intensity 2
expect_exit 0 "" timeout 20 "$CTL" state --json
grep -q '"id":"key"' "$TMP/out" || fail "state lacks the light: $(head -c 400 "$TMP/out")"
expect_exit 0 "" timeout 20 "$CTL" --json state
grep -q '"intensity":2' "$TMP/out" || fail "state lacks the light's intensity: $(head -c 400 "$TMP/out")"
expect_exit 1 "out_of_range.*/light/intensity" timeout 20 "$CTL" light set bad --type point --position 0,0,0 --intensity -1
expect_exit 1 "unknown_id" timeout 20 "$CTL" light rm nope
expect_exit 0 "" timeout 20 "$CTL" light rm key
expect_exit 3 "" timeout 20 "$CTL" --url ws://127.0.0.1:1/ ping
expect_exit 2 "" timeout 20 "$CTL" frob
expect_exit 2 "" timeout 20 "$CTL" light set x --type point --intensity abc
expect_exit 0 "" timeout 20 "$CTL" --help
expect_exit 0 "" timeout 20 "$CTL" send '{"type":"ping","t":1}'
grep -q '"pong"' "$TMP/out" || fail "send ping printed no pong: $(head -c 400 "$TMP/out")"
expect_exit 1 "bad_json" timeout 20 "$CTL" send 'not json'
printf '%s\n' '{"type":"ping","t":2}' '{"type":"state.get"}' >"$TMP/in.jsonl"
expect_exit 0 "" sh -c "timeout 20 '$CTL' --json send - <'$TMP/in.jsonl'"
[ "$(grep -c '"type"' "$TMP/out")" = 2 ] || fail "send - expected two replies: $(head -c 400 "$TMP/out")"
kill -0 "$DPID" 2>/dev/null || fail "lucentd died during the test: $(head -c 400 "$TMP/d.err")"
finish
