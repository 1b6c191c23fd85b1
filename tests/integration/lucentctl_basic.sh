# lucentctl against a live lucentd: global options and help, ping, state, send, light (each
# with --help, usage errors, a server refusal), exit codes. object, material, env, settings:
# lucentctl_scene.sh; scripts: lucentctl_script.sh.
. "$(dirname "$0")/lib.sh"
lucentctl_setup
T="timeout 20"

# state --json into $TMP/state.json
state() { $T "$CTL" state --json >"$TMP/state.json" 2>"$TMP/state.err" || fail "state failed: $(head -c 300 "$TMP/state.err")"; }

# --- global -------------------------------------------------------------------------------
expect_exit 0 "" $T "$CTL" --help
for c in ping state send light object material env settings script watch snapshot latency; do
  grep -q "^  $c " "$TMP/out" || fail "--help does not list '$c'"
done
grep -q "exit codes: 0 ok, 1 server refused, 2 usage, 3 connection" "$TMP/out" || fail "--help lacks the exit codes"
expect_exit 0 "" $T "$CTL" help
expect_exit 0 "" $T "$CTL" help light
grep -q "light set ID" "$TMP/out" || fail "help light printed: $(head -c 200 "$TMP/out")"
expect_exit 2 "" $T "$CTL"
expect_exit 2 "unknown command 'frob'" $T "$CTL" frob
expect_exit 2 "unknown option '--frob'" $T "$CTL" --frob ping
expect_exit 2 "--url needs a value" $T "$CTL" ping --url
expect_exit 3 "cannot connect" $T "$CTL" --url ws://127.0.0.1:1/ ping
expect_exit 3 "cannot connect" $T "$CTL" ping --url=ws://127.0.0.1:1/   # global options after the command
expect_exit 3 "cannot connect" $T "$CTL" ping --url ws://127.0.0.1:1/

# --- ping ---------------------------------------------------------------------------------
expect_exit 0 "" $T "$CTL" ping
grep -qE "^pong from ws://127.0.0.1:$LUCENTD_PORT/: [0-9.]+ ms$" "$TMP/out" || fail "ping printed: $(head -c 200 "$TMP/out")"
expect_exit 0 "" $T "$CTL" ping --count 3 --interval 0
[ "$(grep -c '^pong from' "$TMP/out")" = 3 ] || fail "ping --count 3: $(head -c 400 "$TMP/out")"
grep -q "^3 pings: min/avg/max = " "$TMP/out" || fail "ping --count 3 has no summary"
expect_exit 0 "" $T "$CTL" ping --json
json_check "$TMP/out" 'j["type"] == "pong" and j["rtt_ms"] >= 0'
expect_exit 0 "" $T "$CTL" ping --help
grep -q "usage: lucentctl ping" "$TMP/out" || fail "ping --help: $(head -c 200 "$TMP/out")"
expect_exit 2 "ping: --count 'x'" $T "$CTL" ping --count x
expect_exit 2 "ping: --count 0" $T "$CTL" ping --count 0
expect_exit 2 "ping: unexpected argument 'now'" $T "$CTL" ping now

# --- light --------------------------------------------------------------------------------
expect_exit 0 "" $T "$CTL" light set key --type point --position 0.2,0.4,0.3 --intensity 2
grep -qE "^ok: light 'key' set \(revision [0-9]+\)$" "$TMP/out" || fail "light set printed: $(head -c 200 "$TMP/out")"
expect_exit 0 "" $T "$CTL" state --json
grep -q '"id":"key"' "$TMP/out" || fail "state lacks the light: $(head -c 400 "$TMP/out")"
expect_exit 0 "" $T "$CTL" --json state
grep -q '"intensity":2' "$TMP/out" || fail "state lacks the light's intensity: $(head -c 400 "$TMP/out")"
[ "$(wc -l <"$TMP/out")" = 1 ] || fail "state --json is not one line"
expect_exit 0 "" $T "$CTL" state
json_check "$TMP/out" 'j["lights"][0]["position"] == [0.2, 0.4, 0.3]'
[ "$(wc -l <"$TMP/out")" -gt 5 ] || fail "state (human) is not indented"
expect_exit 0 "" $T "$CTL" light set spot1 --type spot --position 0.28,0.5,0.28 --direction 0,-1,0 \
  --color 1,0.5,0.25 --intensity 3 --range 2 --inner-cone 0.2 --outer-cone 0.5 --json
json_check "$TMP/out" 'j["type"] == "ok" and j["revision"] >= 2'
expect_exit 0 "" $T "$CTL" light set panel --type area --position 0.28,0.54,0.28 --direction 0,-1,0 \
  --shape quad --size 0.1,0.2 --tangent 1,0,0 --intensity 5
expect_exit 0 "" $T "$CTL" light set sun --type directional --direction=-0.3,-1,0.2 --intensity 0.5
state
json_check "$TMP/state.json" '[l["id"] for l in j["lights"]] == ["key", "panel", "spot1", "sun"]'
json_check "$TMP/state.json" '[l for l in j["lights"] if l["id"] == "spot1"][0]["innerConeAngle"] == 0.2'
json_check "$TMP/state.json" '[l for l in j["lights"] if l["id"] == "spot1"][0]["outerConeAngle"] == 0.5'
json_check "$TMP/state.json" '[l for l in j["lights"] if l["id"] == "spot1"][0]["range"] == 2'
json_check "$TMP/state.json" '[l for l in j["lights"] if l["id"] == "panel"][0]["size"] == [0.1, 0.2]'
expect_exit 1 "out_of_range at /light/intensity: .*hint: " $T "$CTL" light set bad --type point --position 0,0,0 --intensity -1
expect_exit 1 "invalid at /light/position" $T "$CTL" light set bad --type point
expect_exit 1 "unknown_id at /light_id: .*lucentctl state" $T "$CTL" light rm nope
expect_exit 0 "" $T "$CTL" light rm key
grep -qE "^ok: light 'key' removed \(revision [0-9]+\)$" "$TMP/out" || fail "light rm printed: $(head -c 200 "$TMP/out")"
for sub in "" set rm; do
  expect_exit 0 "" $T "$CTL" light $sub --help
  grep -q "usage: lucentctl light" "$TMP/out" || fail "light $sub --help: $(head -c 200 "$TMP/out")"
done
grep -q -- "--outer-cone RAD" "$TMP/out" && fail "light rm --help shows the set options"
expect_exit 0 "" $T "$CTL" light set --help
for f in --type --position --direction --color --intensity --range --inner-cone --outer-cone --shape --size --tangent; do
  grep -q -- "$f" "$TMP/out" || fail "light set --help lacks $f"
done
expect_exit 2 "light: expected a subcommand" $T "$CTL" light
expect_exit 2 "light: unknown subcommand 'frob'" $T "$CTL" light frob
expect_exit 2 "light set: --intensity 'abc': expected a number" $T "$CTL" light set x --type point --intensity abc
expect_exit 2 "light set: --intensity 'inf'" $T "$CTL" light set x --type point --intensity inf
expect_exit 2 "light set: --type 'pont': expected point\|spot" $T "$CTL" light set x --type pont
expect_exit 2 "light set: --type is required" $T "$CTL" light set x --position 0,0,0
expect_exit 2 "light set: --position '1,2': expected 3 comma-separated" $T "$CTL" light set x --type point --position 1,2
expect_exit 2 "light set: --size '1,2,3': expected 1 or 2" $T "$CTL" light set x --type area --size 1,2,3
expect_exit 2 "light set: --shape 'square'" $T "$CTL" light set x --type area --shape square
expect_exit 2 "light set: unknown option '--colour'" $T "$CTL" light set x --type point --colour 1,1,1
expect_exit 2 "light set: --color needs a value" $T "$CTL" light set x --type point --color
expect_exit 2 "light set: --intensity given twice" $T "$CTL" light set x --type point --intensity 1 --intensity 2
expect_exit 2 "light set: missing the light ID" $T "$CTL" light set --type point
expect_exit 2 "light set: expected one ID" $T "$CTL" light set a b --type point
expect_exit 2 "light rm: expected exactly one ID" $T "$CTL" light rm

# --- send ---------------------------------------------------------------------------------
expect_exit 0 "" $T "$CTL" send '{"type":"ping","t":1}'
grep -q '"pong"' "$TMP/out" || fail "send ping printed no pong: $(head -c 400 "$TMP/out")"
expect_exit 1 "bad_json at .*whole message" $T "$CTL" send 'not json'
expect_exit 1 "unknown_type at /type" $T "$CTL" send '{"type":"frob"}'
printf '%s\n' '{"type":"ping","t":2}' '' '{"type":"state.get"}' >"$TMP/in.jsonl"
expect_exit 0 "" sh -c "$T '$CTL' --json send - <'$TMP/in.jsonl'"
[ "$(grep -c '"type"' "$TMP/out")" = 2 ] || fail "send - expected two replies: $(head -c 400 "$TMP/out")"
expect_exit 0 "" $T "$CTL" send --help
expect_exit 2 "send: expected JSON messages" $T "$CTL" send

kill -0 "$DPID" 2>/dev/null || fail "lucentd died during the test: $(head -c 400 "$TMP/d.err")"
finish
