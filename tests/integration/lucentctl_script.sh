# lucentctl script against a live lucentd: the examples reach their final state, --loop,
# --keep-going, --json, stdin, validation of malformed files (no connection), a refused line,
# roles, and a connection lost mid-script (kill -9 of a second daemon).
. "$(dirname "$0")/lib.sh"
BIN="${LUCENT_BINARY_DIR:?run through ctest}/bin"
CTL="$BIN/lucentctl"
EX="$SRC/examples"
if [ ! -x "$BIN/lucentd" ] || [ ! -x "$CTL" ]; then echo "lucentd/lucentctl not built: skip"; exit 77; fi

start_lucentd "$TMP/d" || exit 1
DPID=$LUCENTD_PID
D2PID=""
trap 'kill "$DPID" $D2PID 2>/dev/null; wait 2>/dev/null; rm -rf "$TMP"' EXIT
export LUCENT_URL="ws://127.0.0.1:$LUCENTD_PORT/"
DEAD="ws://127.0.0.1:1/" # nothing listens: a command that connects exits 3
T="timeout 30"

state() { $T "$CTL" state --json >"$TMP/state.json" 2>"$TMP/state.err" || fail "state failed: $(head -c 300 "$TMP/state.err")"; }
revision() { state; "$PY" -c 'import json,sys; print(json.load(open(sys.argv[1]))["revision"])' "$TMP/state.json"; }
# last_line FILE: the last message line of a script, "at" removed
last_line() { grep -v '^#' "$1" | tail -n 1 | "$PY" -c 'import json,sys; m=json.load(sys.stdin); m.pop("at", None); print(json.dumps(m))'; }

# --- help and usage -----------------------------------------------------------------------
expect_exit 0 "" $T "$CTL" script --help
for f in --speed --loop --keep-going --dry-run --verbose --json '"at"'; do
  grep -q -- "$f" "$TMP/out" || fail "script --help lacks $f"
done
expect_exit 0 "" $T "$CTL" help script
expect_exit 2 "script: missing FILE" $T "$CTL" script
expect_exit 2 "script: one FILE only" $T "$CTL" script a.jsonl b.jsonl
expect_exit 2 "script: --speed '0'" $T "$CTL" script "$EX/orbit.jsonl" --speed 0
expect_exit 2 "script: --speed 'fast'" $T "$CTL" script "$EX/orbit.jsonl" --speed fast
expect_exit 2 "script: --loop '0'" $T "$CTL" script "$EX/orbit.jsonl" --loop=0
expect_exit 2 "script: unknown option '--frob'" $T "$CTL" script "$EX/orbit.jsonl" --frob
expect_exit 2 "cannot open $TMP/none.jsonl" $T "$CTL" script "$TMP/none.jsonl"

# --- validation without a connection --------------------------------------------------------
for f in orbit door-light walking-object; do
  expect_exit 0 "" $T "$CTL" --url "$DEAD" script "$EX/$f.jsonl" --dry-run
  grep -qE "^$EX/$f.jsonl: [0-9]+ messages over [0-9.]+ s: ok$" "$TMP/out" || fail "dry run of $f: $(head -c 300 "$TMP/out")"
done
expect_exit 0 "" $T "$CTL" --url "$DEAD" script "$EX/orbit.jsonl" --dry-run --json --speed 2
json_check "$TMP/out" 'j["messages"] == 72 and j["duration_s"] == 3'
cat >"$TMP/bad.jsonl" <<'EOF'
# a comment, then a blank line

{"at": 0.5, "type": "ping", "t": 1
{"at": 0.5, "type": "ping", "t": 2}
{"at": 1, "t": 3}
{"type": "ping", "t": 4}
{"at": 0.25, "type": "ping", "t": 5}
{"at": 2, "type": "ping", "t": 6}
EOF
expect_exit 2 "bad.jsonl:3: not valid JSON" $T "$CTL" --url "$DEAD" script "$TMP/bad.jsonl"
grep -q "bad.jsonl:5: missing \"type\"" "$TMP/err" || fail "bad.jsonl:5 not reported: $(head -c 600 "$TMP/err")"
grep -q "bad.jsonl:7: \"at\" 0.25 is before 0.5" "$TMP/err" || fail "bad.jsonl:7 not reported: $(head -c 600 "$TMP/err")"
[ "$(grep -c '^.*bad.jsonl:[0-9]*:' "$TMP/err")" = 3 ] || fail "bad.jsonl: expected exactly 3 errors: $(head -c 600 "$TMP/err")"
grep -q "3 malformed lines; nothing sent" "$TMP/err" || fail "bad.jsonl: no count"
grep -q "cannot connect" "$TMP/err" && fail "bad.jsonl: tried to connect"
printf '%s\n' '{"at": -1, "type": "ping"}' '{"at": "soon", "type": "ping"}' '[1]' '{"type": 7}' \
  '{"type": "ping"} {"type": "ping"}' >"$TMP/bad2.jsonl"
expect_exit 2 "bad2.jsonl:1: \"at\" must be a finite number" $T "$CTL" --url "$DEAD" script "$TMP/bad2.jsonl" --dry-run
for l in 2 3 4 5; do grep -q "bad2.jsonl:$l: " "$TMP/err" || fail "bad2.jsonl:$l not reported: $(head -c 600 "$TMP/err")"; done
printf '# nothing\n\n' >"$TMP/empty.jsonl"
expect_exit 2 "no messages" $T "$CTL" --url "$DEAD" script "$TMP/empty.jsonl"

# --- the examples reach their final state -----------------------------------------------------
R0="$(revision)"
expect_exit 0 "" $T "$CTL" script "$EX/orbit.jsonl" --speed 20
grep -qE "orbit.jsonl: 72 messages sent, 0 failed, .*final revision $((R0 + 72))" "$TMP/out" ||
  fail "orbit summary: $(head -c 300 "$TMP/out")"
R1="$(revision)"
[ "$R1" = $((R0 + 72)) ] || fail "orbit: revision $R0 -> $R1, expected +72"
echo "$(last_line "$EX/orbit.jsonl")" >"$TMP/last.json"
json_check "$TMP/state.json" "[l['position'] for l in j['lights'] if l['id'] == 'orbit'] == [json.load(open('$TMP/last.json'))['light']['position']]"

expect_exit 0 "" $T "$CTL" script "$EX/orbit.jsonl" --speed 20 --loop 2 --json
[ "$(grep -c '"type":"ok"' "$TMP/out")" = 144 ] || fail "--loop 2: expected 144 ok replies on stdout"
grep -q "144 messages sent" "$TMP/err" || fail "--loop 2 --json: summary not on stderr: $(head -c 300 "$TMP/err")"
R2="$(revision)"
[ "$R2" = $((R1 + 144)) ] || fail "--loop 2: revision $R1 -> $R2, expected +144"

expect_exit 0 "" $T "$CTL" script "$EX/walking-object.jsonl" --speed 20 --verbose
grep -q "walking-object.jsonl:3 object.set walker: ok (revision" "$TMP/err" || fail "--verbose: no progress line: $(head -c 300 "$TMP/err")"
[ "$(grep -c ': ok' "$TMP/err")" = 50 ] || fail "--verbose: expected 50 progress lines"
state
json_check "$TMP/state.json" 'j["objects"] == []'
[ "$(revision)" = $((R2 + 50)) ] || fail "walking-object: expected 50 revisions"

expect_exit 0 "" $T "$CTL" script "$EX/door-light.jsonl" --speed 20
state
json_check "$TMP/state.json" '[l["id"] for l in j["lights"]] == ["orbit"]'

# --- timing: due times on the monotonic clock (only a lower bound is checked) --------------
printf '%s\n' '{"type": "ping", "t": 0}' '{"at": 0.6, "type": "ping", "t": 1}' '{"at": 1.2, "type": "ping", "t": 2}' >"$TMP/timed.jsonl"
t0="$(date +%s.%N)"
expect_exit 0 "" $T "$CTL" script - --speed 2 <"$TMP/timed.jsonl"   # stdin; 1.2 s at speed 2 = 0.6 s
t1="$(date +%s.%N)"
"$PY" -c "import sys; sys.exit(0 if $t1 - $t0 >= 0.6 else 1)" || fail "script - --speed 2 finished before its last due time"
grep -q "<stdin>: 3 messages sent" "$TMP/out" || fail "script -: $(head -c 300 "$TMP/out")"

# --- a refused line: stop (exit 1, line number), or --keep-going -------------------------------
cat >"$TMP/refuse.jsonl" <<'EOF'
{"type": "light.set", "light": {"id": "a", "type": "point", "position": [0.2, 0.3, 0.2]}}
# line 3 is refused
{"type": "light.set", "light": {"id": "b", "type": "point", "position": [0.2, 0.3, 0.2], "intensity": -5}}
{"type": "batch", "ops": [{"type": "light.remove", "light_id": "a"}, {"type": "light.set", "light": {"id": "c", "type": "directional", "direction": [0, -1, 0]}}]}
EOF
expect_exit 1 "refuse.jsonl:3: server error out_of_range at /light/intensity: " $T "$CTL" script "$TMP/refuse.jsonl"
grep -q "2 messages sent, 1 failed" "$TMP/out" || fail "refused: summary $(head -c 300 "$TMP/out")"
state
json_check "$TMP/state.json" 'sorted(l["id"] for l in j["lights"]) == ["a", "orbit"]'
expect_exit 1 "refuse.jsonl:3: server error out_of_range" $T "$CTL" script "$TMP/refuse.jsonl" --keep-going --json
[ "$(wc -l <"$TMP/out")" = 3 ] || fail "--keep-going --json: expected 3 reply lines: $(head -c 400 "$TMP/out")"
sed -n 2p "$TMP/out" >"$TMP/reply2.json"
json_check "$TMP/reply2.json" 'j["type"] == "error" and j["pointer"] == "/light/intensity"'
state
json_check "$TMP/state.json" 'sorted(l["id"] for l in j["lights"]) == ["c", "orbit"]'

# --- roles and connection loss on a second daemon ---------------------------------------------
start_lucentd "$TMP/d2" --controller-tokens ctl-secret --viewer-tokens view-secret || exit 1
D2PID=$LUCENTD_PID
U2="ws://127.0.0.1:$LUCENTD_PORT/"
expect_exit 1 "refuse.jsonl:1: server error forbidden .*viewer role; use a controller token" \
  $T "$CTL" --url "$U2" --token view-secret script "$TMP/refuse.jsonl"
expect_exit 1 "unauthorized.*--token or LUCENT_TOKEN" $T "$CTL" --url "$U2" --token nope script "$TMP/refuse.jsonl"
"$PY" -c 'for i in range(20): print("{\"at\": %.1f, \"type\": \"light.set\", \"light\": {\"id\": \"s\", \"type\": \"point\", \"position\": [0.2, 0.3, 0.2], \"intensity\": %d}}" % (i * 0.5, i))' >"$TMP/slow.jsonl"
$T "$CTL" --url "$U2" --token ctl-secret script "$TMP/slow.jsonl" >"$TMP/slow.out" 2>"$TMP/slow.err" &
SPID=$!
# kill -9 once the script has had a few lines accepted (the daemon's journal says so)
journal_lines_ge() { [ "$(cat "$1" 2>/dev/null | wc -l)" -ge "$2" ]; }
wait_for 20 "two script lines reaching the journal" journal_lines_ge "$TMP/d2/journal.log" 2
{ kill -9 "$D2PID"; wait "$D2PID"; } 2>/dev/null # (quiet: no "Killed" job notice)
D2PID=""
rc=0
wait "$SPID" || rc=$?
[ "$rc" = 3 ] || fail "connection lost: exit $rc, expected 3; stderr: $(head -c 400 "$TMP/slow.err")"
grep -qE "slow.jsonl:[0-9]+: connection lost: " "$TMP/slow.err" || fail "connection lost: $(head -c 400 "$TMP/slow.err")"

kill -0 "$DPID" 2>/dev/null || fail "lucentd died during the test: $(head -c 400 "$TMP/d.err")"
finish
