# DNRT against the path tracer (lucent-ref), on the change an object makes (`lucent-ref delta`):
# 1. A sphere (R 0.5 m, albedo 0.5) over the floor of a 4 m box whose walls all emit 1 nit with
#    albedo 0: near it (|dE| above 2% of the mean) the engine's change agrees with the
#    reference's within a few percent (measured 3.0%, ratio 0.983 at 32768 spp); exact in
#    closed form (tests/unit/engine/test_dnrt.c).
# 2. The 15 cm cube on the embedded Cornell floor: the shadow's sign is right, and DNRT takes
#    the error of the change well below what the engine gives without it (100%: without DNRT a
#    placed object leaves the Cornell lightmap as it was). Measured at 8192 spp (bench/dnrt.sh):
#    error 60%, sign right 87%, darker sum ratio 0.50 (the paper's "lack of intensity"); here,
#    at 2048 spp, 149 texels: error 56%, sign right 87%, darker ratio 0.57.
. "$(dirname "$0")/lib.sh"
REF="${LUCENT_BINARY_DIR:?run through ctest}/bin/lucent-ref"
BAKE="$LUCENT_BINARY_DIR/bin/lucent-bake"
LCB="$LUCENT_BINARY_DIR/cornell.lcb"

# --- 1. the uniform field ---------------------------------------------------------------------
$PY - "$TMP" <<'PY' || fail "writing the box scene"
import math, os, sys
d = sys.argv[1]
s, n = 4.0, 8
faces = [((0, 0, 0), (0, 0, 1), (1, 0, 0)), ((0, 1, 0), (1, 0, 0), (0, 0, 1)), ((0, 0, 0), (1, 0, 0), (0, 1, 0)),
         ((0, 0, 1), (0, 1, 0), (1, 0, 0)), ((0, 0, 0), (0, 1, 0), (0, 0, 1)), ((1, 0, 0), (0, 0, 1), (0, 1, 0))]
out, base = ["mtllib box.mtl", "usemtl wall"], 1
for o, u, w in faces:  # inward-facing walls, n x n quads each
    for j in range(n + 1):
        for i in range(n + 1):
            out.append("v %g %g %g" % tuple(s * (o[k] + i / n * u[k] + j / n * w[k]) for k in range(3)))
    for j in range(n):
        for i in range(n):
            v = base + j * (n + 1) + i
            out.append("f %d %d %d %d" % (v, v + 1, v + n + 2, v + n + 1))
    base += (n + 1) ** 2
open(os.path.join(d, "box.obj"), "w").write("\n".join(out) + "\n")
open(os.path.join(d, "box.mtl"), "w").write("newmtl wall\nKd 0 0 0\nKe 1 1 1\n")
r, nu, nv, b = 0.5, 64, 32, ["mtllib ball.mtl", "usemtl ball"]
for j in range(nv + 1):
    for i in range(nu):
        th, ph = math.pi * j / nv, 2 * math.pi * i / nu
        p = (math.sin(th) * math.cos(ph), math.cos(th), math.sin(th) * math.sin(ph))
        b += ["v %.6f %.6f %.6f" % tuple(r * c for c in p), "vn %.6f %.6f %.6f" % p]
for j in range(nv):
    for i in range(nu):
        a, q = j * nu + i + 1, j * nu + (i + 1) % nu + 1
        if j > 0: b.append("f %d//%d %d//%d %d//%d" % (a, a, q, q, a + nu, a + nu))
        if j < nv - 1: b.append("f %d//%d %d//%d %d//%d" % (q, q, q + nu, q + nu, a + nu, a + nu))
open(os.path.join(d, "ball.obj"), "w").write("\n".join(b) + "\n")
open(os.path.join(d, "ball.mtl"), "w").write("newmtl ball\nKd 0.5 0.5 0.5\n")
st = '{"type":"state","revision":1,"lights":[],"objects":[%s],"materials":[],"environment":{"type":"none"},"settings":{}}'
open(os.path.join(d, "none.json"), "w").write(st % "")
open(os.path.join(d, "ball.json"), "w").write(st % '{"id":"b","asset":"ball","translation":[2,1.5,2],'
                                              '"rotation":[0,0,0,1],"scale":[1,1,1],"visible":true}')
PY
expect_exit 0 "" "$BAKE" bake "$TMP/box.obj" -o "$TMP/box.lcb" --no-write-glb --quiet --surfels 4096 --atlas-size 64 \
  --min-texel-density 0 --grid-max-dim 9 --asset "ball=$TMP/ball.obj"
for c in none ball; do
  expect_exit 0 "" "$REF" render "$TMP/box.lcb" --state "$TMP/$c.json" --out "$TMP/box-ref-$c" --spp 32768 --no-cells --quiet
  expect_exit 0 "" "$REF" fidelity "$TMP/box.lcb" --state "$TMP/$c.json" --reference "$TMP/box-ref-$c" \
    --out "$TMP/box-fid-$c" --bound-rays 0 --quiet
done
expect_exit 0 "" "$REF" delta --reference "$TMP/box-ref-none" --reference-with "$TMP/box-ref-ball" \
  --lightmap "$TMP/box-fid-none/engine_lightmap.exr" --lightmap-with "$TMP/box-fid-ball/engine_lightmap.exr" \
  --delta-floor 0.02 --out "$TMP/box-delta"
grep -q "^delta " "$TMP/out" || fail "delta prints no row: $(head -c 300 "$TMP/out")"
$PY - "$TMP/box-delta/delta.json" <<'PY' || fail "uniform field: $(cat "$TMP/out")"
import json, sys
d = json.load(open(sys.argv[1]))
assert d["n"] > 200 and d["n_darker"] == d["n"], d           # the sphere only darkens
assert d["error"] < 0.06 and 0.94 < d["darker_ratio"] < 1.06, d
assert d["sign_agree"] > 0.99, d
PY

# --- 2. the Cornell cube ------------------------------------------------------------------------
cube='{"id":"c","asset":"cube","translation":[0.42,0,0.1],"rotation":[0,0,0,1],"scale":[1.5,1.5,1.5],"visible":true}'
state() { printf '{"type":"state","revision":1,"lights":[],"objects":[%s],"materials":[],"environment":{"type":"none"},"settings":{%s}}' "$1" "$2"; }
state "" "" >"$TMP/c-none.json"
state "$cube" "" >"$TMP/c-cube.json"
state "" '"dnrt":false' >"$TMP/c-none-off.json"
state "$cube" '"dnrt":false' >"$TMP/c-cube-off.json"
for c in none cube; do
  expect_exit 0 "" "$REF" render "$LCB" --state "$TMP/c-$c.json" --out "$TMP/c-ref-$c" --spp 2048 --no-cells --quiet
done
for c in none cube none-off cube-off; do
  expect_exit 0 "" "$REF" fidelity "$LCB" --state "$TMP/c-$c.json" --reference "$TMP/c-ref-${c%-off}" \
    --out "$TMP/c-fid-$c" --bound-rays 0 --quiet
done
for v in "" -off; do
  expect_exit 0 "" "$REF" delta --reference "$TMP/c-ref-none" --reference-with "$TMP/c-ref-cube" \
    --lightmap "$TMP/c-fid-none$v/engine_lightmap.exr" --lightmap-with "$TMP/c-fid-cube$v/engine_lightmap.exr" \
    --out "$TMP/c-delta$v"
done
$PY - "$TMP/c-delta/delta.json" "$TMP/c-delta-off/delta.json" <<'PY' || fail "Cornell cube"
import json, sys
on, off = (json.load(open(p)) for p in sys.argv[1:3])
print("Cornell cube: DNRT error %.1f%%, sign right %.1f%%, darker ratio %.3f; without DNRT error %.1f%%"
      % (100 * on["error"], 100 * on["sign_agree"], on["darker_ratio"], 100 * off["error"]))
assert on["n"] > 100 and on["n_buried"] > 10, on              # the footprint is black in the reference
assert off["error"] > 0.99 and off["sign_agree"] < 0.01, off   # without DNRT nothing changes
assert on["error"] < 0.80 and on["sign_agree"] > 0.75, on
assert 0.3 < on["darker_ratio"] < 1.2, on
PY
finish
