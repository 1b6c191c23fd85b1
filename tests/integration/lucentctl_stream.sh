# lucentctl watch / snapshot / latency against a live lucentd: files written, values
# bit-exact with what the server sends (f32, compared with an independent Python client),
# frames.jsonl, usage errors, connection loss.
. "$(dirname "$0")/lib.sh"
lucentctl_setup

expect_exit 0 "" timeout 20 "$CTL" light set key --type point --position 0.28,0.4,0.28 --intensity 0.5
expect_exit 0 "" timeout 20 "$CTL" object set box --asset cube --position 0.3,0,0.3

# An independent client (Python) waits until idle refinement settles, then takes the f32
# lightmap and shgrid payloads of a snapshot.
cat >"$TMP/grab.py" <<'PY'
import asyncio, json, sys
import websockets
import lucent_testlib as lt
async def main(url, out):
    async with websockets.connect(url, subprotocols=["lucent.v1"], max_size=None) as ws:
        await ws.send(json.dumps({"type": "hello", "client": "grab"}))
        json.loads(await ws.recv())
        for s in ("lightmap", "shgrid"):
            await ws.send(json.dumps({"type": "subscribe", "stream": s, "encoding": "f32"}))
        while True:  # quiet for 1.5 s: refinement is over
            try:
                await asyncio.wait_for(ws.recv(), 1.5)
            except asyncio.TimeoutError:
                break
        await ws.send(json.dumps({"type": "snapshot"}))
        got = {}
        while len(got) < 2:
            m = await asyncio.wait_for(ws.recv(), 10)
            if isinstance(m, bytes):
                f = lt.parse_frame(m)
                assert f["crc_ok"] and f["length_ok"], f
                got[f["stream"]] = (f["revision"], lt.frame_payload(m))
        open(out + ".lightmap", "wb").write(got[1][1])
        open(out + ".shgrid", "wb").write(got[2][1])
        print(got[1][0])
asyncio.run(main(sys.argv[1], sys.argv[2]))
PY
REV="$(PYTHONPATH="$SRC/tests/lib" timeout 30 "$PY" "$TMP/grab.py" "$LUCENT_URL" "$TMP/py")" || fail "python client"

expect_exit 0 "" timeout 30 "$CTL" snapshot --out "$TMP/snap" --encoding f32 --raw
for f in lightmap.exr lightmap.png lightmap.f32 shgrid.json shgrid.bin objects.json objects.bin snapshot.json; do
  [ -s "$TMP/snap/$f" ] || fail "snapshot did not write $f"
done
cmp -s "$TMP/snap/lightmap.f32" "$TMP/py.lightmap" || fail "lightmap.f32 differs from the server's f32 payload"
cmp -s "$TMP/snap/shgrid.bin" "$TMP/py.shgrid" || fail "shgrid.bin differs from the server's f32 payload"
json_check "$TMP/snap/snapshot.json" "j['lightmap']['revision'] == $REV and j['lightmap']['encoding'] == 'f32'"
# watch's files too: its first frame (a keyframe of the same, settled state), f32 raw
expect_exit 0 "" timeout 30 "$CTL" watch --stream lightmap --encoding f32 --raw --count 1 --out "$TMP/wf32"
cmp -s "$TMP/wf32/lightmap-000001.f32" "$TMP/py.lightmap" || fail "watch lightmap .f32 differs from the server's f32 payload"
expect_exit 0 "" timeout 30 "$CTL" watch --stream shgrid --encoding f32 --count 1 --out "$TMP/wgf32"
cmp -s "$TMP/wgf32/shgrid-000001.bin" "$TMP/py.shgrid" || fail "watch shgrid .bin differs from the server's f32 payload"
json_check "$TMP/snap/shgrid.json" "len(j['values']) == j['dims'][0] * j['dims'][1] * j['dims'][2] * 27 and len(j['origin']) == 3"
json_check "$TMP/snap/objects.json" "[o['id'] for o in j['objects']] == ['box'] and len(j['objects'][0]['sh']) == 27"
head -c 4 "$TMP/snap/lightmap.exr" | od -An -tx1 | grep -q "76 2f 31 01" || fail "lightmap.exr lacks the OpenEXR magic"
head -c 8 "$TMP/snap/lightmap.png" | od -An -c | grep -q "P   N   G" || fail "lightmap.png lacks the PNG signature"
# the half EXR read back (OpenImageIO's oiiotool, when installed) matches the f32 values within half precision
if command -v oiiotool >/dev/null; then
  oiiotool "$TMP/snap/lightmap.exr" -d float -o "$TMP/snap/back.tif" >/dev/null 2>&1 || fail "oiiotool cannot read lightmap.exr"
fi
# default encoding (rgb9e5) snapshot of one stream
expect_exit 0 "" timeout 30 "$CTL" --json snapshot --out "$TMP/snap2" --stream lightmap
json_check "$TMP/out" "j['lightmap']['encoding'] == 'rgb9e5' and 'shgrid' not in j"

# move_light X: moves the key light, prints the revision lucentd acknowledged
move_light() {
  timeout 20 "$CTL" light set key --type point --position "$1",0.4,0.28 --intensity 0.5 |
    sed -n 's/.*(revision \([0-9]*\)).*/\1/p'
}
# frames_reached FILE REV: FILE (a watch's frames.jsonl) has a frame of revision REV or later
frames_reached() {
  "$PY" -c 'import json, sys
sys.exit(0 if any(json.loads(l)["revision"] >= int(sys.argv[2]) for l in open(sys.argv[1])) else 1)' "$1" "$2"
}
# watch_done_or_reached PID FILE REV: the watch exited, or it has the frame
watch_done_or_reached() { ! kill -0 "$1" 2>/dev/null || frames_reached "$2" "$3"; }

# watch: frames while a light moves (each move once the watch has the frame of the last)
timeout 30 "$CTL" --json watch --stream lightmap --encoding rgba16f --out "$TMP/watch" --count 3 \
  >"$TMP/watch.out" 2>"$TMP/watch.err" &
WPID=$!
wait_for 20 "watch printing 'subscribed to lightmap'" grep -q "lucentctl: subscribed to lightmap" "$TMP/watch.err"
for x in 0.2 0.25 0.3 0.35; do
  rev="$(move_light $x)"
  wait_for 20 "the watch's frame of revision $rev" watch_done_or_reached "$WPID" "$TMP/watch/frames.jsonl" "$rev"
done
wait "$WPID" || fail "watch exited $?: $(head -c 400 "$TMP/watch.err")"
[ "$(ls "$TMP/watch"/lightmap-*.exr 2>/dev/null | wc -l)" = 3 ] || fail "watch wrote $(ls "$TMP/watch" | tr '\n' ' ')"
[ "$(ls "$TMP/watch"/lightmap-*.png 2>/dev/null | wc -l)" = 3 ] || fail "watch PNGs"
[ "$(wc -l <"$TMP/watch/frames.jsonl")" = 3 ] || fail "frames.jsonl: $(cat "$TMP/watch/frames.jsonl")"
"$PY" - "$TMP/watch/frames.jsonl" <<'PY' || fail "frames.jsonl content"
import json, sys
rows = [json.loads(l) for l in open(sys.argv[1])]
assert rows[0]["keyframe"] and rows[0]["sequence"] == 1, rows[0]
assert all(r["encoding"] == "rgba16f" for r in rows)
assert [r["sequence"] for r in rows] == [1, 2, 3], rows
assert all(rows[i]["revision"] <= rows[i + 1]["revision"] for i in range(2))
PY
[ "$(grep -c '"type":"frame"' "$TMP/watch.out")" = 3 ] || fail "watch --json lines: $(head -c 300 "$TMP/watch.out")"
# watch with residual deltas (f32): the copy rebuilt from them ends within the server's
# threshold (1% of the texel's brightest channel) of a fresh snapshot of the settled state.
# Four moves follow, so the watch ends by itself (--until-revision: the last move's frame and
# then 1 s without a frame, its refinement passes over); it must end by itself: a SIGTERM to an
# ASan process can hang LeakSanitizer's exit-time check. --duration only caps it (exit 3).
expect_exit 0 "" timeout 20 "$CTL" --json state
FINAL="$("$PY" -c 'import json, sys; print(json.load(open(sys.argv[1]))["revision"] + 4)' "$TMP/out")"
timeout 120 "$CTL" watch --stream lightmap --encoding f32 --delta residual --raw --until-revision "$FINAL" \
  --duration 90 --out "$TMP/wres" >"$TMP/wres.out" 2>"$TMP/wres.err" &
WPID=$!
wait_for 20 "watch --delta residual printing 'subscribed to lightmap'" grep -q "lucentctl: subscribed to lightmap" "$TMP/wres.err"
for x in 0.3 0.303 0.306 0.2; do  # each move once the watch has the last one's frame
  RESREV="$(move_light $x)"
  wait_for 20 "the residual watch's frame of revision $RESREV" frames_reached "$TMP/wres/frames.jsonl" "$RESREV"
done
[ "$RESREV" = "$FINAL" ] || fail "the moves ended at revision '$RESREV', expected $FINAL"
wait "$WPID" || fail "watch --delta residual exited $?: $(head -c 400 "$TMP/wres.err")"
expect_exit 0 "" timeout 30 "$CTL" snapshot --out "$TMP/snapres" --stream lightmap --encoding f32 --raw
json_check "$TMP/snapres/snapshot.json" "j['lightmap']['revision'] == $RESREV"
"$PY" - "$TMP/wres" "$TMP/snapres/lightmap.f32" "$RESREV" <<'PY' || fail "residual watch does not rebuild the lightmap"
import json, struct, sys
rows = [json.loads(l) for l in open(sys.argv[1] + "/frames.jsonl")]
assert rows[0]["keyframe"] and any(r["residual"] for r in rows), rows[:4]
assert rows[-1]["revision"] == int(sys.argv[3]), (rows[-1], sys.argv[3])
last = rows[-1]["file"]
a = struct.unpack("<%df" % (len(open(sys.argv[2], "rb").read()) // 4), open(sys.argv[2], "rb").read())
b = struct.unpack("<%df" % len(a), open(sys.argv[1] + "/" + last + ".f32", "rb").read())
peak = max(a)
worst = max(max(abs(a[i + c] - b[i + c]) for c in range(3)) / max(max(a[i:i + 3]), max(b[i:i + 3]), 1e-3 * peak)
            for i in range(0, len(a), 3))
assert worst <= 0.011, "worst texel %.4f of its brightest channel" % worst
PY
expect_exit 2 "tiles or residual" timeout 10 "$CTL" watch --stream lightmap --delta xor --out "$TMP/x"
expect_exit 2 "lightmap only" timeout 10 "$CTL" watch --stream shgrid --delta residual --out "$TMP/x"
expect_exit 0 "" timeout 30 "$CTL" watch --stream objects --out "$TMP/wobj" --count 1
json_check "$TMP/wobj/objects-000001.json" "j['objects'][0]['id'] == 'box'"
expect_exit 0 "" timeout 30 "$CTL" watch --stream shgrid --out "$TMP/wgrid" --duration 1
ls "$TMP/wgrid"/shgrid-000001.bin >/dev/null 2>&1 || fail "watch --duration wrote no shgrid frame"
# --until-revision: a revision that does not come fails clearly when --duration ends (exit 3);
# one already there ends the watch after the first frame and --settle of quiet
expect_exit 3 "no frame of revision 999999 within --duration 1 s" timeout 30 "$CTL" watch --stream lightmap \
  --out "$TMP/wnever" --until-revision 999999 --duration 1
expect_exit 0 "subscribed to objects" timeout 30 "$CTL" watch --stream objects --out "$TMP/wnow" \
  --until-revision "$RESREV" --settle 0.2 --duration 20
[ "$(wc -l <"$TMP/wnow/frames.jsonl")" = 1 ] || fail "watch --until-revision (reached at once): $(cat "$TMP/wnow/frames.jsonl")"

# latency
expect_exit 0 "" timeout 60 "$CTL" --json latency --count 5 --interval 0.05
json_check "$TMP/out" "j['update_to_frame']['n'] == 5 and 0 < j['update_to_frame']['p50_ms'] < 5000 and j['ping']['n'] >= 5"
expect_exit 0 "" timeout 60 "$CTL" --json latency --count 3 --interval 0.05 --clients 3
json_check "$TMP/out" "j['update_to_frame']['n'] == 9 and j['update_to_ok']['n'] == 3"
expect_exit 2 "clients" timeout 10 "$CTL" latency --clients 0
expect_exit 0 "" timeout 60 "$CTL" latency --count 3 --interval 0.05
grep -q "update_to_frame" "$TMP/out" || fail "latency table: $(head -c 300 "$TMP/out")"
expect_exit 0 "" timeout 20 "$CTL" --json state
json_check "$TMP/out" "'lucentctl-probe' not in [l['id'] for l in j['lights']]"

# usage errors and help
for c in watch snapshot latency; do expect_exit 0 "" timeout 10 "$CTL" $c --help; done
"$CTL" watch --help >"$TMP/whelp" 2>&1
grep -q -- "--until-revision N" "$TMP/whelp" && grep -q -- "--settle SECONDS" "$TMP/whelp" &&
  grep -q "lucentctl: subscribed to STREAM" "$TMP/whelp" || fail "watch --help: $(head -c 600 "$TMP/whelp")"
expect_exit 2 "settle needs --until-revision" timeout 10 "$CTL" watch --stream lightmap --out "$TMP/x" --settle 1
expect_exit 2 "until-revision '1.5' is not a whole number" timeout 10 "$CTL" watch --stream lightmap --out "$TMP/x" --until-revision 1.5
expect_exit 2 "stream is required" timeout 10 "$CTL" watch --out "$TMP/x"
expect_exit 2 "out DIR is required" timeout 10 "$CTL" watch --stream lightmap
expect_exit 2 "not lightmap" timeout 10 "$CTL" watch --stream nope --out "$TMP/x"
expect_exit 2 "rgb9e5 is for the lightmap" timeout 10 "$CTL" watch --stream shgrid --encoding rgb9e5 --out "$TMP/x"
expect_exit 2 "out DIR is required" timeout 10 "$CTL" snapshot
expect_exit 2 "count" timeout 10 "$CTL" latency --count 0
expect_exit 2 "unknown option" timeout 10 "$CTL" latency --frob 1

# connection: none there (3); lost while watching without reconnect (3)
expect_exit 3 "" timeout 20 "$CTL" --url ws://127.0.0.1:1/ snapshot --out "$TMP/none"
timeout 30 "$CTL" watch --stream lightmap --out "$TMP/lost" --no-reconnect >/dev/null 2>"$TMP/lost.err" &
WPID=$!
wait_for 20 "watch printing 'subscribed to lightmap'" grep -q "lucentctl: subscribed to lightmap" "$TMP/lost.err"
kill -9 "$LUCENTD_PID"; wait "$LUCENTD_PID" 2>/dev/null
RC=0; wait "$WPID" || RC=$?
[ "$RC" = 3 ] || fail "watch after the server died exited $RC, expected 3: $(head -c 300 "$TMP/lost.err")"
finish
