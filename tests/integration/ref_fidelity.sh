# lucent-ref on the embedded Cornell bake: a short reference render, then fidelity with the
# lossless-transport bound (the engine's surfels gathered without links) beside the engine.
. "$(dirname "$0")/lib.sh"
REF="${LUCENT_BINARY_DIR:?run through ctest}/bin/lucent-ref"
LCB="$LUCENT_BINARY_DIR/cornell.lcb"

expect_exit 0 "" "$REF" render "$LCB" --out "$TMP/ref" --spp 256 --no-cells --quiet
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
finish
