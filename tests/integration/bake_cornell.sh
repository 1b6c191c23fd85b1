# Bakes the embedded Cornell box (draft preset + an asset) and checks what the file holds.
. "$(dirname "$0")/lib.sh"

expect_exit 0 "" "$BAKE" bake "$CORNELL" -o "$TMP/cornell.lcb" --glb "$TMP/cornell.glb" --quality draft \
  --asset cube="$SRC/scenes/cornell-box/cube.obj" --stats-json "$TMP/stats.json"
[ -s "$TMP/cornell.glb" ] || fail "no glb written"
# The .glb is generated from the .lcb just written (lc_lcb_scene_glb, as lucentd serves it):
# its bake id is the file's table CRC and size, its triangles the bake's.
$PY - "$TMP/cornell.glb" "$TMP/cornell.lcb" <<'PY' || fail "glb content"
import json, struct, sys
b = open(sys.argv[1], "rb").read(); h = open(sys.argv[2], "rb").read(64)
def check(cond, msg):
    if not cond:
        print("check failed:", msg); sys.exit(1)
magic, version, length = struct.unpack_from("<4sII", b, 0)
check(magic == b"glTF" and version == 2 and length == len(b), "GLB header")
jlen, jtype = struct.unpack_from("<II", b, 12)
check(jtype == 0x4E4F534A, "JSON chunk")
j = json.loads(b[20:20 + jlen])
check(j["asset"]["generator"] == "lucent", "generator %s" % j["asset"]["generator"])
file_size, = struct.unpack_from("<Q", h, 16); table_crc, = struct.unpack_from("<I", h, 32)
check(j["asset"]["extras"]["lucent"]["bake_id"] == "%08x%016x" % (table_crc, file_size), "bake id")
prims = j["meshes"][0]["primitives"]
check(sum(j["accessors"][p["indices"]]["count"] for p in prims) == 3 * 38, "38 triangles")
check(all("TEXCOORD_1" in p["attributes"] and "TEXCOORD_0" in p["attributes"] for p in prims), "lightmap UVs")
light = [m for m in j["materials"] if m["name"] == "light"][0]
s = light["extensions"]["KHR_materials_emissive_strength"]["emissiveStrength"]
check([round(f * s, 4) for f in light["emissiveFactor"]] == [17, 12, 4], "lamp emission")
check(j["extensionsUsed"] == ["KHR_materials_emissive_strength"], "extensionsUsed")
PY
expect_exit 0 "" "$BAKE" verify "$TMP/cornell.lcb"
"$BAKE" info "$TMP/cornell.lcb" --json > "$TMP/info.json" || fail "info --json failed"
"$BAKE" info "$TMP/cornell.lcb" > "$TMP/info.txt" || fail "info failed"
grep -q "LINK" "$TMP/info.txt" || fail "info does not list the LINK section"
$PY - "$TMP/info.json" "$TMP/stats.json" <<'PY' || fail "info/stats content"
import json, sys
info = json.load(open(sys.argv[1])); stats = json.load(open(sys.argv[2]))
m = info["meta"]
def check(cond, msg):
    if not cond:
        print("check failed:", msg); sys.exit(1)
check(m["format"] == "lucent-bake", "format")
check(m["scene"]["triangles"] == 38, "38 triangles, got %s" % m["scene"]["triangles"])
check(abs(m["scene"]["area"] - stats.get("area", m["scene"]["area"])) < 1e-9, "area")
check(m["surfels"]["count"] == 8192, "draft surfels")
check(abs(m["surfels"]["count"] * m["surfels"]["area"] - m["scene"]["area"]) < 1e-4 * m["scene"]["area"],
      "surfel area sum equals surface area")
check(m["hierarchy"]["nodes"] == 2 * 8192 - 1, "hierarchy nodes")
check(m["links"]["per_cache"] == 64, "draft links")
check(m["sh_bands"] == 2, "draft bands")
check(m["lightmap"]["width"] == 64 and m["lightmap"]["height"] == 64, "draft atlas 64")
check(0.2 < m["lightmap"]["usage"] <= 1.0, "atlas usage %s" % m["lightmap"]["usage"])
check(m["caches"]["texel"] > 500, "texel caches")
check(any(e["material"] == "light" and e["emission"] == [17, 12, 4] for e in m["emitters"]), "light emitter")
check([a["name"] for a in m["assets"]] == ["cube"], "asset listed")
check(m["assets"][0]["triangles"] == 12, "cube triangles")
ids = [s["id"] for s in info["sections"]]
for sid in ["META","MATL","VERT","TRIS","SURF","NODE","LEVL","CACH","LMAP","GRID","LINK","ASET","AVRT","AIDX"]:
    check(sid in ids, "section " + sid)
check(stats["total_s"] > 0 and stats["peak_rss_mib"] > 0, "stats")
check(stats["stages_s"].keys() >= {"import","lightmap-uv","texels","surfels","hierarchy","links","write"}, "stages")
peaks = [stats["stages_peak_mib"][k] for k in stats["stages_s"]]
check(peaks == sorted(peaks) and 0 < peaks[-1] <= stats["peak_rss_mib"], "per-stage peak memory rises to the peak: %r" % peaks)
check(m["surfels"]["exposure"] is False and m["settings"]["exposure"] is False, "exposure off by default")
PY

# --exposure: surfel areas reweighted by how many caches see them; the file stays valid and
# the total (hence the nominal area in META) is kept.
expect_exit 0 "" "$BAKE" bake "$CORNELL" -o "$TMP/exposure.lcb" --quality draft --no-write-glb --exposure --quiet
expect_exit 0 "" "$BAKE" verify "$TMP/exposure.lcb"
[ ! -e "$TMP/exposure.glb" ] || fail "--no-write-glb wrote $TMP/exposure.glb"
"$BAKE" info "$TMP/exposure.lcb" --json > "$TMP/exposure.json" || fail "info --json failed"
$PY - "$TMP/exposure.json" <<'PY' || fail "exposure bake content"
import json, sys
m = json.load(open(sys.argv[1]))["meta"]
def check(cond, msg):
    if not cond:
        print("check failed:", msg); sys.exit(1)
check(m["surfels"]["exposure"] is True and m["settings"]["exposure"] is True, "exposure recorded")
check(0 <= m["surfels"]["unseen"] < m["surfels"]["count"], "unseen count %s" % m["surfels"]["unseen"])
check(abs(m["surfels"]["count"] * m["surfels"]["area"] - m["scene"]["area"]) < 1e-4 * m["scene"]["area"],
      "exposure keeps the total surfel area")
PY
finish
