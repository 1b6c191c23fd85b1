# What a client of lucentd receives, against the reference (issue 16): bench/served.py on the
# embedded Cornell bake with lucentd's defaults. `row`: lucentctl snapshot once the refinement
# is over, lucent-ref compare against a 256-spp reference; `converge`: one point light added,
# every frame of the new revision at the client against the converged solution.
. "$(dirname "$0")/lib.sh"
BIN="${LUCENT_BINARY_DIR:?run through ctest}/bin"
LCB="$LUCENT_BINARY_DIR/cornell.lcb"
for t in lucentd lucentctl lucent-ref; do
  [ -x "$BIN/$t" ] || { echo "$t not built: skip"; exit 77; }
done
SERVED="$SRC/bench/served.py"
CHANGE='{"type": "light.set", "light": {"id": "probe", "type": "point", "position": [0.15, 0.4, 0.2], "color": [1, 0.9, 0.8], "intensity": 0.05}}'

expect_exit 0 "" "$BIN/lucent-ref" render "$LCB" --out "$TMP/ref" --spp 256 --quiet

# --- row: the served lightmap and SH grid, compared ---------------------------------------------
expect_exit 0 "served: .*pass [0-9]+ converged" $PY "$SERVED" row --bin "$BIN" --bake "$LCB" --reference "$TMP/ref" \
  --out "$TMP/row" --settle 1
for f in lightmap.f32 shgrid.bin; do [ -s "$TMP/row/snapshot/$f" ] || fail "no snapshot/$f"; done
[ -s "$TMP/row/compare/compare.json" ] || fail "no compare.json"
# Cornell moderate: 6-8% against a 256-spp reference (5% of it noise); garbage is far off
json_check "$TMP/row/served.json" 'j["served"] and j["converged"] and j["pass"] >= 1 and j["encoding"] == "rgb9e5"'
json_check "$TMP/row/served.json" 'j["lightmap"]["compared"] > 1000 and 0 < j["lightmap"]["mean"] < 0.5'
json_check "$TMP/row/served.json" 'abs(j["lightmap"]["bias"]) < 0.2 and j["lightmap"]["p95"] < 0.6'
json_check "$TMP/row/served.json" 'j["grid"]["compared"] > 100 and 0 < j["grid"]["mean"] < 0.5'
# the copy the watching client built from keyframes + deltas agrees with the snapshot
json_check "$TMP/row/served.json" 'abs(j["stream"]["mean"] - j["lightmap"]["mean"]) < 0.02'
json_check "$TMP/row/served.json" '"refine-passes" in j["daemon"]["defaults"] and "--refine-passes" not in j["daemon"]["argv"]'
# the check itself fails on garbage: a black lightmap compared the same way is 100% off
$PY -c 'import sys; open(sys.argv[1], "wb").write(bytes(64 * 64 * 12))' "$TMP/zeros.f32"
"$BIN/lucent-ref" compare --reference "$TMP/ref" --lightmap "$TMP/zeros.f32" --out "$TMP/zeros" >/dev/null 2>&1
json_check "$TMP/zeros/compare.json" 'j["lightmap"]["mean"] > 0.9'

# --- converge: one change, every frame at the client ---------------------------------------------
expect_exit 0 "served: converge" $PY "$SERVED" converge --bin "$BIN" --bake "$LCB" --change "$CHANGE" \
  --mask "$TMP/ref/reference_texels.bin" --out "$TMP/conv.json" --settle 1
json_check "$TMP/conv.json" 'len(j["frames"]) >= 1 and all(f["revision"] == j["revision"] for f in j["frames"])'
json_check "$TMP/conv.json" 'j["frames"][-1]["converged"] and j["covered_texels"] > 1000'
# the approach: the last frame closer than the first (unless the first is already within 1%)
json_check "$TMP/conv.json" 'j["final_dist"] < j["frames"][0]["dist"] or j["frames"][0]["dist"] <= 0.01'
json_check "$TMP/conv.json" 'j["final_dist"] < 0.05 and j["snapshot_dist"] < 0.05'
json_check "$TMP/conv.json" 'all(a["t_ms"] <= b["t_ms"] for a, b in zip(j["frames"], j["frames"][1:]))'
json_check "$TMP/conv.json" 'j["t_within_1pct_ms"] is None or any(f["dist"] <= 0.01 and f["t_ms"] == j["t_within_1pct_ms"] for f in j["frames"])'
# the first frame after adding a light is not yet the converged light (the added light matters)
json_check "$TMP/conv.json" 'j["frames"][0]["dist"] > 0.01 or j["frames"][0]["pass"] > 0'
# the client's copy built from deltas alone (no periodic keyframe) reaches the same light
expect_exit 0 "" $PY "$SERVED" converge --bin "$BIN" --bake "$LCB" --change "$CHANGE" --daemon-arg=--keyframe-interval=100000 \
  --mask "$TMP/ref/reference_texels.bin" --out "$TMP/conv-d.json" --settle 0.5
json_check "$TMP/conv-d.json" 'j["final_dist"] < 0.03 and j["snapshot_dist"] < 0.01'
json_check "$TMP/conv-d.json" 'sum(f["tiles"] for f in j["frames"][max(i for i, f in enumerate(j["frames"]) if f["keyframe"] or i == 0) + 1:]) > 20'
# the same with a black "converged" lightmap would be nonsense: served.py refuses it
expect_exit 1 "black" $PY "$SERVED" converge --bin "$BIN" --bake "$LCB" --change "$CHANGE" --converged "$TMP/zeros.f32" \
  --out "$TMP/conv0.json" --settle 0.5
# a "converged" lightmap twice what the daemon serves: the client ends at dist 0.5 (sum |Y - 2Y| / sum 2Y)
$PY - "$TMP/row/snapshot/lightmap.f32" "$TMP/double.f32" <<'PY'
import array, sys
a = array.array("f"); a.frombytes(open(sys.argv[1], "rb").read())
open(sys.argv[2], "wb").write(array.array("f", (2 * x for x in a)).tobytes())
PY
expect_exit 0 "" $PY "$SERVED" converge --bin "$BIN" --bake "$LCB" --change '{"type": "environment.set", "environment": {"type": "none"}}' \
  --converged "$TMP/double.f32" --mask "$TMP/ref/reference_texels.bin" --out "$TMP/conv2.json" --settle 0.5
json_check "$TMP/conv2.json" 'abs(j["final_dist"] - 0.5) < 0.02'
finish
