# lucent-ref on the embedded Cornell bake: a short reference render (texels at their own surface
# points), then fidelity with the lossless-transport bound (the engine's surfels gathered without
# links) beside the engine; `--texel-at cache` (the bake's cache points).
. "$(dirname "$0")/lib.sh"
REF="${LUCENT_BINARY_DIR:?run through ctest}/bin/lucent-ref"
LCB="$LUCENT_BINARY_DIR/cornell.lcb"

expect_exit 0 "surface points" "$REF" render "$LCB" --out "$TMP/ref" --spp 256 --no-cells --quiet
$PY - "$TMP/ref/reference.json" <<'PY' || fail "reference.json texel surfaces"
import json, sys
lm = json.load(open(sys.argv[1]))["lightmap"]
assert lm["texel_at"] == "surface", lm["texel_at"]
s = lm["surface"]
# the reference's own uv lookup finds every texel centre inside a triangle, and where the bake did
# not move the cache it lands on the bake's texel point (float rounding only)
assert s["texels"] == lm["stats"]["caches"] > 2000 and s["missing"] == 0 and s["outside_triangles"] <= 5, s
assert 0 <= s["unmoved_cache_offset_max_m"] < 1e-5, s
PY
expect_exit 0 "" "$REF" fidelity "$LCB" --reference "$TMP/ref" --out "$TMP/fid" --bound-rays 4096 --quiet
grep -q "^bound " "$TMP/out" || fail "fidelity prints no bound row: $(head -c 400 "$TMP/out")"
[ -s "$TMP/fid/bound_lightmap.exr" ] || fail "no bound_lightmap.exr"
$PY - "$TMP/fid/fidelity.json" <<'PY' || fail "fidelity.json bound"
import json, sys
j = json.load(open(sys.argv[1]))
lm, b = j["lightmap"], j["bound"]
assert b["rays"] == 4096 and b["compared"] == lm["compared"] > 1000, (b, lm)
# Cornell moderate: the links cost about 3 points, the surfels about 3 (bench/fidelity.md);
# the 256-spp reference adds ~5% noise to both
assert 0 < b["mean"] < lm["mean"] < 0.15, (b["mean"], lm["mean"])
assert abs(b["bias"]) < 0.06, b["bias"]
PY
expect_exit 0 "" "$REF" fidelity "$LCB" --reference "$TMP/ref" --out "$TMP/fid0" --bound-rays 0 --quiet
$PY -c "import json,sys; sys.exit('bound' in json.load(open('$TMP/fid0/fidelity.json')))" || fail "--bound-rays 0 still reports a bound"
expect_exit 2 "bound-rays" "$REF" fidelity "$LCB" --reference "$TMP/ref" --bound-rays -1
# The bake's cache points: the moved caches sit in the open, lit (surface: buried under the blocks).
expect_exit 0 "cache points" "$REF" render "$LCB" --out "$TMP/refc" --spp 256 --no-cells --quiet --texel-at cache
$PY - "$TMP/refc/reference.json" "$TMP/ref/reference.json" <<'PY' || fail "--texel-at cache"
import json, sys
c, s = (json.load(open(p))["lightmap"] for p in sys.argv[1:3])
assert c["texel_at"] == "cache", c["texel_at"]
# the 53 moved floor caches are lit where the bake put them, black at their surface points
assert c["stats"]["bright_caches"] >= s["stats"]["bright_caches"] + 40, (c["stats"], s["stats"])
PY
expect_exit 2 "texel-at" "$REF" render "$LCB" --out "$TMP/bad" --texel-at centre
finish
