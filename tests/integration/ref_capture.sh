# lucent-ref capture and mr-truth on the embedded Cornell bake (build/cornell.lcb, baked by the
# build's lucent-bake): a 4-frame 64x48 jittered capture and a 2-frame --path capture (srgb8)
# checked file by file (names, PNG sizes / bit depths / colour types, every JSON field, the
# exposure mapping the brightest channel to 65535, depth in the box's range); mr-truth on it
# (fields, an occluder cube lowers `full`, `visible` within what the scene gives); bad flags
# exit 2 naming the flag or field; the recordings play through `lucentctl mr replay` to lucentd
# (when built). The closed forms are in tests/unit/ref/test_capture.c.
. "$(dirname "$0")/lib.sh"
REF="${LUCENT_BINARY_DIR:?run through ctest}/bin/lucent-ref"
LCB="$LUCENT_BINARY_DIR/cornell.lcb"
[ -f "$LCB" ] || { echo "SKIP: $LCB not built (target cornell_bake)"; exit 77; }
EYE=0.278,0.273,-0.8
TGT=0.278,0.273,0

expect_exit 0 "capture 64x48, 4 frames" "$REF" capture "$LCB" --out "$TMP/cap" --eye $EYE --target $TGT \
  --width 64 --height 48 --frames 4 --jitter-mm 5 --jitter-deg 1 --spp 4 --seed 3 --threads 2
grep -q "capture frame 4/4" "$TMP/err" || fail "no per-frame progress on stderr"
cat >"$TMP/path.json" <<'EOF'
{"frames": [{"eye": [0.278, 0.273, -0.8], "target": [0.278, 0.273, 0]},
            {"eye": [0.2, 0.3, -0.7], "target": [0.278, 0.2, 0.2], "up": [0, 1, 0], "time_us": 33333}]}
EOF
expect_exit 0 "" "$REF" capture "$LCB" --out "$TMP/path" --path "$TMP/path.json" --width 40 --height 30 \
  --fov 50 --spp 2 --color srgb8 --quiet

$PY - "$TMP/cap" "$TMP/path" "$LCB" <<'PY' || fail "capture files"
import json, math, os, struct, sys, zlib

def png(path):
    """(width, height, bit depth, colour type, rows of samples): non-interlaced grey / RGB."""
    d = open(path, "rb").read()
    assert d[:8] == b"\x89PNG\r\n\x1a\n", path
    pos, idat, ihdr = 8, b"", None
    while pos < len(d):
        (n,) = struct.unpack(">I", d[pos:pos + 4])
        kind, body = d[pos + 4:pos + 8], d[pos + 8:pos + 8 + n]
        if kind == b"IHDR": ihdr = struct.unpack(">IIBBBBB", body)
        if kind == b"IDAT": idat += body
        pos += 12 + n
    w, h, bits, ctype, _, _, interlace = ihdr
    assert interlace == 0, path
    ch = {0: 1, 2: 3}[ctype]
    bpp, stride = ch * bits // 8, w * ch * bits // 8
    raw, prev, rows, p = zlib.decompress(idat), bytearray(stride), [], 0
    for _ in range(h):
        f, line = raw[p], bytearray(raw[p + 1:p + 1 + stride])
        p += 1 + stride
        for i in range(stride):
            a = line[i - bpp] if i >= bpp else 0
            b, c = prev[i], prev[i - bpp] if i >= bpp else 0
            pa, pb, pc = abs(b - c), abs(a - c), abs(a + b - 2 * c)
            pred = [0, a, b, (a + b) // 2, a if pa <= pb and pa <= pc else (b if pb <= pc else c)][f]
            line[i] = (line[i] + pred) & 255
        rows.append([int.from_bytes(line[i:i + bits // 8], "big") for i in range(0, stride, bits // 8)])
        prev = line
    return w, h, bits, ctype, rows

def check_capture(d, n, w, h, fov, color, times):
    names = sorted(os.listdir(d))
    want = ["capture.json"] + ["%s_%05d.%s" % (k, i, e) for i in range(1, n + 1)
                               for k, e in (("color", "png"), ("depth", "png"), ("frame", "json"))]
    assert names == sorted(want), (names, want)
    cap = json.load(open(os.path.join(d, "capture.json")))
    assert cap["format"] == "lucent-rgbd/1" and cap["width"] == w and cap["height"] == h and cap["frames"] == n, cap
    assert cap["source"]["bake"] == sys.argv[3] and cap["source"]["state"] is None, cap
    f_px = (h / 2) / math.tan(math.radians(fov) / 2)
    for i in range(1, n + 1):
        fr = json.load(open(os.path.join(d, "frame_%05d.json" % i)))
        assert set(fr) == {"sequence", "time_us", "intrinsics", "pose", "exposure", "color"}, fr
        assert fr["sequence"] == i and fr["time_us"] == times[i - 1] and fr["color"] == color, fr
        k = fr["intrinsics"]
        assert abs(k["fx"] - f_px) < 1e-9 and abs(k["fy"] - f_px) < 1e-9 and k["cx"] == w / 2 and k["cy"] == h / 2, k
        q, t = fr["pose"]["rotation"], fr["pose"]["translation"]
        assert len(q) == 4 and abs(math.sqrt(sum(x * x for x in q)) - 1) < 1e-9 and len(t) == 3, fr["pose"]
        assert 1 < fr["exposure"] < 1e3, fr  # the lamp's radiance, a few to tens of nits
        dw, dh, dbits, dtype, depth = png(os.path.join(d, "depth_%05d.png" % i))
        cw, chh, cbits, ctype, col = png(os.path.join(d, "color_%05d.png" % i))
        assert (dw, dh, dbits, dtype) == (w, h, 16, 0), (dw, dh, dbits, dtype)
        assert (cw, chh, cbits, ctype) == (w, h, 16 if color == "linear16" else 8, 2), (cw, chh, cbits, ctype)
        flat = [v for r in depth for v in r]
        hit = [v for v in flat if v]
        # the box spans z 0..0.56 m in front of an eye 0.6 to 0.8 m away: depth under 1.6 m;
        # its open front leaves pixels without a surface (depth 0)
        assert 0 < len(hit) < len(flat) and max(hit) < 1600 and min(hit) > 300, (len(hit), min(hit), max(hit))
        top = max(v for r in col for v in r)
        assert top == (65535 if color == "linear16" else 255), top  # exposure = the brightest channel
        # no surface, no colour: depth is the pixel centre's ray, colour its spp positions, so a
        # pixel on a silhouette may have colour without depth; one whose 8 neighbours have no
        # depth either has none
        for y in range(h):
            for x in range(w):
                near = [depth[j][i] for j in range(max(0, y - 1), min(h, y + 2)) for i in range(max(0, x - 1), min(w, x + 2))]
                if not any(near): assert col[y][3 * x:3 * x + 3] == [0, 0, 0], (x, y)
    return fr

check_capture(sys.argv[1], 4, 64, 48, 60.0, "linear16", [0, 100000, 200000, 300000])
fr = check_capture(sys.argv[2], 2, 40, 30, 50.0, "srgb8", [0, 33333])
assert fr["pose"]["translation"] == [0.2, 0.3, -0.7] or max(abs(a - b) for a, b in zip(fr["pose"]["translation"], [0.2, 0.3, -0.7])) < 1e-6
PY

# mr-truth on a 192x144 frame (at 64x48 the 5%-of-depth rule drops the ceiling, floor and side
# walls, seen at grazing angles: neighbouring pixels differ by more): a point in the box's middle
# facing the ceiling (and its lamp), one facing the camera; a 10 cm cube 5 cm above the first
# blocks a large part of what it sees.
expect_exit 0 "" "$REF" capture "$LCB" --out "$TMP/big" --eye $EYE --target $TGT --width 192 --height 144 \
  --spp 2 --quiet
cat >"$TMP/pts.json" <<'EOF'
{"points": [{"position": [0.278, 0.3, 0.28], "normal": [0, 1, 0]},
            {"position": [0.278, 0.3, 0.28], "normal": [0, 0, -1]}]}
EOF
cat >"$TMP/pts_occ.json" <<'EOF'
{"points": [{"position": [0.278, 0.3, 0.28], "normal": [0, 1, 0]},
            {"position": [0.278, 0.3, 0.28], "normal": [0, 0, -1]}],
 "occluders": {"objects": [{"asset": "cube", "translation": [0.278, 0.35, 0.28]}]}}
EOF
expect_exit 0 "mr-truth 2 points" "$REF" mr-truth "$LCB" --capture "$TMP/big" --points "$TMP/pts.json" \
  --out "$TMP/t0.json" --spp 2048 --quiet
expect_exit 0 "1 occluders" "$REF" mr-truth "$LCB" --capture "$TMP/big" --points "$TMP/pts_occ.json" \
  --out "$TMP/t1.json" --spp 2048 --quiet
$PY - "$TMP/t0.json" "$TMP/t1.json" <<'PY' || fail "mr-truth output"
import json, sys
t0, t1 = (json.load(open(p)) for p in sys.argv[1:3])
for t in (t0, t1):
    assert t["spp"] == 2048 and len(t["points"]) == 2, t
    for p in t["points"]:
        assert set(p) == {"position", "normal", "full", "full_stderr", "visible", "visible_stderr"}, p
        assert all(len(p[k]) == 3 and all(v >= 0 for v in p[k]) for k in p if k not in ("position", "normal")), p
    q = t["points"][1]
    assert max(abs(a - b) for a, b in zip(q["position"] + q["normal"], [0.278, 0.3, 0.28, 0, 0, -1])) < 1e-6, q
up0, up1 = t0["points"][0], t1["points"][0]
for c in range(3):
    se = (up0["full_stderr"][c] ** 2 + up1["full_stderr"][c] ** 2) ** 0.5
    assert up1["full"][c] < up0["full"][c] - 4 * se, (up0["full"], up1["full"])  # the cube shadows
    assert up1["visible"][c] < up0["visible"][c], (up0["visible"], up1["visible"])
    # the camera sees the ceiling and its lamp from below the front: nearly all of full
    assert 0.8 * up0["full"][c] < up0["visible"][c] < 1.05 * up0["full"][c] + 5 * up0["visible_stderr"][c], up0
PY

# An occluder with "sparse_points": true adds its asset's baked sparse points, placed: the 10 cm
# cube (256 points; its base at y = 0, centred in x and z) turned 90 degrees about y and doubled.
cat >"$TMP/pts_sp.json" <<'EOF'
{"occluders": {"objects": [{"asset": "cube", "translation": [0.278, 0.2, 0.28], "rotation": [0, 0.7071068, 0, 0.7071068],
                            "scale": 2, "sparse_points": true}]}}
EOF
expect_exit 0 "mr-truth 256 points" "$REF" mr-truth "$LCB" --capture "$TMP/big" --points "$TMP/pts_sp.json" \
  --out "$TMP/t2.json" --spp 16 --quiet
$PY - "$TMP/t2.json" <<'PY' || fail "mr-truth sparse points"
import json, sys
pts = json.load(open(sys.argv[1]))["points"]
assert len(pts) == 256, len(pts)
c = (0.278, 0.3, 0.28)  # the 20 cm cube's centre
for p in pts:
    d = [p["position"][k] - c[k] for k in range(3)]
    n = p["normal"]
    assert max(abs(x) for x in d) <= 0.1 + 1e-5, p  # on the 20 cm cube's surface
    assert abs(sum(x * x for x in n) - 1) < 1e-5, p
    k = max(range(3), key=lambda i: abs(n[i]))  # axis-aligned faces: the normal picks the face
    assert abs(abs(n[k]) - 1) < 1e-4 and abs(abs(d[k]) - 0.1) < 1e-4 and d[k] * n[k] > 0, p
PY

# The recording plays through `lucentctl mr replay` (the reader of this format, client/README.md)
# to lucentd on the same bake: every frame acknowledged, none refused. Needs lucentd and lucentctl
# built (else this part is left out, said so).
if [ -x "$LUCENT_BINARY_DIR/bin/lucentd" ] && [ -x "$LUCENT_BINARY_DIR/bin/lucentctl" ]; then
  if start_lucentd "$TMP/d" --bake "$LCB"; then
    DPID=$LUCENTD_PID
    trap 'kill "$DPID" 2>/dev/null; wait "$DPID" 2>/dev/null; rm -rf "$TMP"' EXIT
    export LUCENT_URL="ws://127.0.0.1:$LUCENTD_PORT/"
    CTL="$LUCENT_BINARY_DIR/bin/lucentctl"
    expect_exit 0 "" "$CTL" object set mrcube --asset cube --position 0.278,0,0.28
    for rec in cap path; do
      rc=0
      "$CTL" mr replay "$TMP/$rec" --objects mrcube --rate 0 --max-rate 60 --quiet >"$TMP/replay.out" \
        2>"$TMP/replay.err" || rc=$?
      [ "$rc" = 0 ] || fail "mr replay $rec exited $rc: $(head -c 400 "$TMP/replay.err")"
      want=$([ $rec = cap ] && echo 4 || echo 2)
      grep '^{"frames_sent"' "$TMP/replay.out" >"$TMP/replay.json" || fail "mr replay $rec: no summary"
      json_check "$TMP/replay.json" "j['frames_sent'] == $want and j['processed'] + j['replaced'] == $want and \
j['errors'] == 0 and j['lights_mean'] > 0"
    done
  else
    fail "lucentd did not start"
  fi
else
  echo "lucentd/lucentctl not built: the replay round trip is left out"
fi

expect_exit 2 "--out: required" "$REF" capture "$LCB" --eye $EYE --target $TGT
expect_exit 2 "--eye: required" "$REF" capture "$LCB" --out "$TMP/x" --target $TGT
expect_exit 2 "--path: not with" "$REF" capture "$LCB" --out "$TMP/x" --path "$TMP/path.json" --eye $EYE
expect_exit 2 "--path: not with" "$REF" capture "$LCB" --out "$TMP/x" --path "$TMP/path.json" --jitter-mm 3
echo '{"frames": [{"eye": [0, 0, 0]}]}' >"$TMP/bad.json"
expect_exit 2 "/frames/0/target" "$REF" capture "$LCB" --out "$TMP/x" --path "$TMP/bad.json"
expect_exit 2 "outside the replay format's 8..1024" "$REF" capture "$LCB" --out "$TMP/x" --eye $EYE --target $TGT \
  --width 4 --height 4
expect_exit 2 "--color" "$REF" capture "$LCB" --out "$TMP/x" --eye $EYE --target $TGT --color hdr
expect_exit 1 "--frame: 5 is not a frame" "$REF" mr-truth "$LCB" --capture "$TMP/cap" --frame 5 \
  --points "$TMP/pts.json" --out "$TMP/t.json"
expect_exit 2 "--points: required" "$REF" mr-truth "$LCB" --capture "$TMP/cap" --out "$TMP/t.json"
echo '{"points": [{"position": [0, 0, 0], "normal": [0, 1, 0]}], "occluders": {"objects": [{"asset": "ball"}]}}' \
  >"$TMP/badpts.json"
expect_exit 1 "/occluders/objects/0/asset" "$REF" mr-truth "$LCB" --capture "$TMP/cap" --points "$TMP/badpts.json" \
  --out "$TMP/t.json"
finish
