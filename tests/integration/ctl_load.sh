# lucentctl load against a live lucentd (Cornell bake): 50 viewers on one client context,
# 5 updates/s for 3 s; the JSON report's counts, latency, drops and final revision; the
# orbiting light removed afterwards; --json on stdout; usage errors name the flag.
. "$(dirname "$0")/lib.sh"
BIN="${LUCENT_BINARY_DIR:?run through ctest}/bin"
CTL="$BIN/lucentctl"
LCB="$LUCENT_BINARY_DIR/cornell.lcb"
if [ ! -x "$BIN/lucentd" ] || [ ! -x "$CTL" ] || [ ! -f "$LCB" ]; then echo "lucentd/lucentctl/cornell.lcb not built: skip"; exit 77; fi
command -v jq >/dev/null || { echo "jq not installed: skip"; exit 77; }
start_lucentd "$TMP/d" --bake "$LCB" || exit 1
DPID=$LUCENTD_PID
trap 'kill "$DPID" 2>/dev/null; wait "$DPID" 2>/dev/null; rm -rf "$TMP"' EXIT
export LUCENT_URL="ws://127.0.0.1:$LUCENTD_PORT/"
T="timeout 60"

# jcheck FILE JQ_EXPR: the expression is true for the report in FILE
jcheck() { jq -e "$2" "$1" >/dev/null 2>&1 || fail "report check '$2' failed on: $(jq -c . "$1" 2>&1 | head -c 900)"; }

# --- the run ------------------------------------------------------------------------------
expect_exit 0 "50/50 viewers connected" $T "$CTL" load --clients 50 --rate 5 --duration 3 --json "$TMP/load.json"
[ -s "$TMP/load.json" ] || fail "load wrote no JSON report"
grep -q "^latency ms   p50 " "$TMP/out" || fail "the table lacks the latency line: $(head -c 400 "$TMP/out")"
grep -q "lucentctl: load: .* sent .* acked" "$TMP/err" || fail "no progress lines on stderr: $(head -c 400 "$TMP/err")"
jcheck "$TMP/load.json" '.clients.requested == 50 and .clients.connected == 50 and .clients.failed == 0'
jcheck "$TMP/load.json" '.clients.dropped == 0 and .clients.measured == 50'
jcheck "$TMP/load.json" '.updates.sent == 15 and .updates.acknowledged >= 10 and .updates.errors == 0'
jcheck "$TMP/load.json" '.updates.final_revision > .updates.warmup_revision'
jcheck "$TMP/load.json" '(.latency_ms.p50 | type) == "number" and .latency_ms.p50 > 0 and .latency_ms.p50 < 2000'
jcheck "$TMP/load.json" '.latency_ms.p50 <= .latency_ms.p90 and .latency_ms.p90 <= .latency_ms.p99 and .latency_ms.p99 <= .latency_ms.max'
jcheck "$TMP/load.json" '.latency_ms.missing == 0 and .latency_ms.samples == .updates.acknowledged * 50'
jcheck "$TMP/load.json" '.final.fraction == 1 and .final.on_final == 50'
jcheck "$TMP/load.json" '.bytes.total > 0 and .bytes.per_client_per_s > 0 and .frames.per_client_per_s > 0'
jcheck "$TMP/load.json" '.frames.bad == 0 and .frames.seq_gaps == 0 and .frames.keyframes >= 50'
jcheck "$TMP/load.json" '.load_client.cpu_s > 0 and .load_client.max_rss_kb > 0'
# the orbiting light is gone again
$T "$CTL" state --json >"$TMP/state.json" 2>/dev/null || fail "state failed"
jq -e '[.lights[].id] | index("load-orbit") == null' "$TMP/state.json" >/dev/null || fail "load-orbit is still in the state"

# global --json: the report on stdout; another encoding
expect_exit 0 "" $T "$CTL" --json load --clients 5 --rate 5 --duration 1 --encoding f32 --warmup 0
jcheck "$TMP/out" '.clients.connected == 5 and .encoding == "f32" and .latency_ms.missing == 0'

# --- usage errors name the flag; connection failure -------------------------------------
expect_exit 0 "" $T "$CTL" load --help
grep -q "usage: lucentctl load --clients N --rate R --duration S" "$TMP/out" || fail "load --help: $(head -c 200 "$TMP/out")"
expect_exit 2 "load: --clients '0'" $T "$CTL" load --clients 0 --rate 5 --duration 3
expect_exit 2 "load: --rate '-1'" $T "$CTL" load --clients 5 --rate -1 --duration 3
expect_exit 2 "load: --duration S is required" $T "$CTL" load --clients 5 --rate 5
expect_exit 2 "load: unknown option '--frob'" $T "$CTL" load --clients 5 --rate 5 --duration 1 --frob 1
expect_exit 2 "load: --encoding rgb9e5 is for the lightmap" $T "$CTL" load --clients 5 --rate 5 --duration 1 --stream shgrid --encoding rgb9e5
expect_exit 2 "load: --json needs a value" $T "$CTL" load --clients 5 --rate 5 --duration 1 --json
expect_exit 3 "controller connection" $T "$CTL" --url ws://127.0.0.1:1/ load --clients 5 --rate 5 --duration 1
finish
