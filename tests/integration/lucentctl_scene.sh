# lucentctl against a live lucentd: object (the baked `cube` asset), material, env and
# settings, each with --help, usage errors and a server refusal; the state they leave
# (object and settings --dnrt / --dnrt-blockers: issue 17; object --mode: issue 19).
. "$(dirname "$0")/lib.sh"
lucentctl_setup
T="timeout 20"

# state --json into $TMP/state.json
state() { $T "$CTL" state --json >"$TMP/state.json" 2>"$TMP/state.err" || fail "state failed: $(head -c 300 "$TMP/state.err")"; }

# --- object -------------------------------------------------------------------------------
expect_exit 0 "" $T "$CTL" object set box1 --asset cube --position 0.4,0,0.15 --rotation 0,0.3826834,0,0.9238795 \
  --scale 0.5 --visible false --dnrt false
grep -qE "^ok: object 'box1' set \(revision [0-9]+\)$" "$TMP/out" || fail "object set printed: $(head -c 200 "$TMP/out")"
expect_exit 0 "" $T "$CTL" object set box2 --asset cube --scale 1,2,1
state
json_check "$TMP/state.json" '[o["id"] for o in j["objects"]] == ["box1", "box2"]'
json_check "$TMP/state.json" 'j["objects"][0]["asset"] == "cube" and j["objects"][0]["translation"] == [0.4, 0, 0.15]'
json_check "$TMP/state.json" 'j["objects"][0]["scale"] == [0.5, 0.5, 0.5] and j["objects"][0]["visible"] is False'
json_check "$TMP/state.json" 'abs(j["objects"][0]["rotation"][1] - 0.3826834) < 1e-5 and j["objects"][1]["scale"] == [1, 2, 1]'
json_check "$TMP/state.json" 'j["objects"][0]["dnrt"] is False and j["objects"][1]["dnrt"] is True'
expect_exit 0 "" $T "$CTL" object set box2 --asset cube --scale 1,2,1 --dnrt false
state
json_check "$TMP/state.json" 'j["objects"][1]["id"] == "box2" and j["objects"][1]["dnrt"] is False'
expect_exit 0 "" $T "$CTL" object set box2 --asset cube --scale 1,2,1 --dnrt true
state
json_check "$TMP/state.json" 'j["objects"][1]["dnrt"] is True'
json_check "$TMP/state.json" 'j["objects"][1]["mode"] == "dynamic" and j["objects"][1]["transport"] == "dynamic"'
expect_exit 0 "" $T "$CTL" object set box2 --asset cube --scale 1,2,1 --mode auto
state
json_check "$TMP/state.json" 'j["objects"][1]["mode"] == "auto"'
expect_exit 1 "unknown_asset at /object/asset: .*scene.assets" $T "$CTL" object set box3 --asset sphere
expect_exit 1 "out_of_range at /object/rotation" $T "$CTL" object set box3 --asset cube --rotation 0,0,0,0
expect_exit 0 "" $T "$CTL" object rm box1
grep -qE "^ok: object 'box1' removed \(revision [0-9]+\)$" "$TMP/out" || fail "object rm printed: $(head -c 200 "$TMP/out")"
expect_exit 0 "" $T "$CTL" object rm box2 --json
json_check "$TMP/out" 'j["type"] == "ok"'
expect_exit 1 "unknown_id at /object_id" $T "$CTL" object rm box1
state
json_check "$TMP/state.json" 'j["objects"] == []'
for sub in "" set rm; do
  expect_exit 0 "" $T "$CTL" object $sub --help
  grep -q "usage: lucentctl object" "$TMP/out" || fail "object $sub --help: $(head -c 200 "$TMP/out")"
done
expect_exit 2 "object: expected a subcommand" $T "$CTL" object
expect_exit 2 "object set: --asset is required" $T "$CTL" object set box3 --position 0,0,0
expect_exit 2 "object set: --scale '1,2': expected 1 or 3" $T "$CTL" object set box3 --asset cube --scale 1,2
expect_exit 2 "object set: --visible 'maybe': expected true or false" $T "$CTL" object set box3 --asset cube --visible maybe
expect_exit 2 "object set: --dnrt '5': expected true or false" $T "$CTL" object set box3 --asset cube --dnrt 5
expect_exit 2 "object set: --mode 'static': expected dynamic[|]clutter[|]auto" $T "$CTL" object set box3 --asset cube --mode static
expect_exit 0 "" $T "$CTL" object set --help
grep -q -- "--dnrt true|false" "$TMP/out" || fail "object set --help lacks --dnrt"
grep -q -- "--mode dynamic|clutter|auto" "$TMP/out" || fail "object set --help lacks --mode"
expect_exit 2 "object set: --rotation '0,0,1': expected 4" $T "$CTL" object set box3 --asset cube --rotation 0,0,1
expect_exit 2 "object rm: expected exactly one ID" $T "$CTL" object rm a b

# --- material -----------------------------------------------------------------------------
expect_exit 0 "" $T "$CTL" material set light --emission 34,24,8
grep -qE "^ok: material 'light' emission set \(revision [0-9]+\)$" "$TMP/out" || fail "material set printed: $(head -c 200 "$TMP/out")"
state
json_check "$TMP/state.json" '[m["emission"] for m in j["materials"] if m["name"] == "light"] == [[34, 24, 8]]'
expect_exit 1 "unknown_material at /material: .*lucentctl state" $T "$CTL" material set lamp --emission 1,1,1
expect_exit 1 "out_of_range at /emission" $T "$CTL" material set light --emission=-1,0,0
expect_exit 0 "" $T "$CTL" material set light --emission 17,12,4 --json
json_check "$TMP/out" 'j["type"] == "ok"'
expect_exit 0 "" $T "$CTL" material --help
expect_exit 0 "" $T "$CTL" material set --help
grep -q -- "--emission r,g,b" "$TMP/out" || fail "material set --help lacks --emission"
expect_exit 2 "material set: --emission is required" $T "$CTL" material set light
expect_exit 2 "material set: expected one material NAME" $T "$CTL" material set --emission 1,1,1
expect_exit 2 "material: unknown subcommand 'get'" $T "$CTL" material get light

# --- env ----------------------------------------------------------------------------------
expect_exit 0 "" $T "$CTL" env set --color 0.1,0.2,0.3 --intensity 0.5
grep -qE "^ok: environment set \(constant\) \(revision [0-9]+\)$" "$TMP/out" || fail "env set printed: $(head -c 200 "$TMP/out")"
state
json_check "$TMP/state.json" 'j["environment"]["type"] == "constant" and j["environment"]["color"] == [0.1, 0.2, 0.3] and j["environment"]["intensity"] == 0.5'
SH="$(seq -s, 1 27 | sed 's/\([0-9]*\)/0.0\1/g')"
expect_exit 0 "" $T "$CTL" env set --sh "$SH"
state
json_check "$TMP/state.json" 'j["environment"]["type"] == "sh" and len(j["environment"]["sh"]) == 27 and j["environment"]["sh"][26] == 0.027'
expect_exit 0 "" $T "$CTL" env set --none
state
json_check "$TMP/state.json" 'j["environment"]["type"] == "none"'
expect_exit 1 "out_of_range at /environment/intensity" $T "$CTL" env set --color 1,1,1 --intensity -2
expect_exit 0 "" $T "$CTL" env --help
expect_exit 0 "" $T "$CTL" env set --help
grep -q -- "--sh" "$TMP/out" || fail "env set --help lacks --sh"
expect_exit 2 "env set: give exactly one of --none, --color, --sh" $T "$CTL" env set --none --color 1,1,1
expect_exit 2 "env set: give exactly one of" $T "$CTL" env set --intensity 2
expect_exit 2 "env set: --sh '1,2,3': expected 27" $T "$CTL" env set --sh 1,2,3
expect_exit 2 "env set: --none takes no value" $T "$CTL" env set --none=1
expect_exit 2 "env: expected a subcommand" $T "$CTL" env

# --- settings -----------------------------------------------------------------------------
expect_exit 0 "" $T "$CTL" settings set --bounces 1 --bands 3 --progressive false --chroma-compression true --chroma-bands 2
grep -qE "^ok: settings set \(revision [0-9]+\)$" "$TMP/out" || fail "settings set printed: $(head -c 200 "$TMP/out")"
state
json_check "$TMP/state.json" 'j["settings"] == {"bounces": 1, "bands": 3, "progressive": False, "chroma_compression": True, "chroma_bands": 2, "dnrt": True, "dnrt_blockers": True, "solver": "pic"}'
expect_exit 0 "" $T "$CTL" settings set --bounces 2   # only the given field changes
state
json_check "$TMP/state.json" 'j["settings"] == {"bounces": 2, "bands": 3, "progressive": False, "chroma_compression": True, "chroma_bands": 2, "dnrt": True, "dnrt_blockers": True, "solver": "pic"}'
expect_exit 0 "" $T "$CTL" settings set --dnrt false --dnrt-blockers false
grep -qE "^ok: settings set \(revision [0-9]+\)$" "$TMP/out" || fail "settings set --dnrt printed: $(head -c 200 "$TMP/out")"
state
json_check "$TMP/state.json" 'j["settings"] == {"bounces": 2, "bands": 3, "progressive": False, "chroma_compression": True, "chroma_bands": 2, "dnrt": False, "dnrt_blockers": False, "solver": "pic"}'
expect_exit 0 "" $T "$CTL" settings set --dnrt true
state
json_check "$TMP/state.json" 'j["settings"]["dnrt"] is True and j["settings"]["dnrt_blockers"] is False'
expect_exit 0 "" $T "$CTL" settings set --dnrt-blockers true --json
json_check "$TMP/out" 'j["type"] == "ok"'
state
json_check "$TMP/state.json" 'j["settings"]["dnrt"] is True and j["settings"]["dnrt_blockers"] is True'
expect_exit 2 "settings set: --dnrt-blockers 'sometimes': expected true or false" $T "$CTL" settings set --dnrt-blockers sometimes
expect_exit 1 "out_of_range at /settings/bounces" $T "$CTL" settings set --bounces 99
# the solver: this PIC bake offers pic only (welcome.scene.solvers)
expect_exit 0 "" $T "$CTL" settings set --solver pic
expect_exit 1 "invalid at /settings/solver" $T "$CTL" settings set --solver probes
expect_exit 2 "settings set: --solver 'radiosity': expected pic|probes" $T "$CTL" settings set --solver radiosity
state
json_check "$TMP/state.json" 'j["settings"]["solver"] == "pic"'
expect_exit 0 "" $T "$CTL" settings set --help
grep -q -- "--chroma-compression true|false" "$TMP/out" || fail "settings set --help lacks --chroma-compression"
grep -q -- "--dnrt true|false" "$TMP/out" || fail "settings set --help lacks --dnrt"
grep -q -- "--dnrt-blockers true|false" "$TMP/out" || fail "settings set --help lacks --dnrt-blockers"
expect_exit 0 "" $T "$CTL" settings --help
expect_exit 2 "settings set: give at least one option" $T "$CTL" settings set
expect_exit 2 "settings set: --bands '2.5': expected an integer" $T "$CTL" settings set --bands 2.5
expect_exit 2 "settings set: --progressive 'yes please'" $T "$CTL" settings set --progressive "yes please"
expect_exit 2 "settings set: unexpected argument 'now'" $T "$CTL" settings set --bounces 1 now

kill -0 "$DPID" 2>/dev/null || fail "lucentd died during the test: $(head -c 400 "$TMP/d.err")"
finish
