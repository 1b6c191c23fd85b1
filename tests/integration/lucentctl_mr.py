#!/usr/bin/python3
"""`lucentctl mr replay DIR` against a real lucentd (issue 18; client/README.md "MR replay
format"): a synthetic recording of a wall is played as an MR session and the summary is
checked against what the server must answer.

  replay      linear16 colour, u16mm depth: every frame acknowledged, no error, one light
              per pixel (a flat wall has no rejected pixel), the upload bytes are the raw size;
              --vpl-out: the last mr.vpl frame follows the last upload, 256 points of the cube,
              unlit exactly where the points face away from the wall
  variants    srgb8 colour + confidence, --zlib and --half-depth: fewer bytes, same lights
              minus the low-confidence pixels
  bad input   a PNG of the wrong size, a frame JSON without a field: exit 2 naming the file
              and the field; no --objects: exit 2; an unknown object: exit 1 (unknown_id)
  refused     lucentd --no-mr: exit 1 (the capability is not granted)"""
import json
import os
import struct
import subprocess
import sys
import tempfile
import zlib

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "lib"))
import lucent_testlib as lt  # noqa: E402
from lucent_testlib import RawWS, stop  # noqa: E402

FAILS = []
TMP = tempfile.mkdtemp(prefix="lucent-ctl-mr-")
W, H, N = 64, 48, 5


def check(cond, msg):
    if not cond:
        FAILS.append(msg)
        print("FAIL:", msg, file=sys.stderr)
    return cond


def png(path, w, h, channels, bits, values):
    """A PNG (grey or RGB, 8 or 16 bits) of row-major `values`."""
    fmt = ">%dH" if bits == 16 else "%dB"
    row = w * channels
    raw = b"".join(b"\0" + struct.pack(fmt % row, *values[y * row:(y + 1) * row]) for y in range(h))

    def chunk(t, d):
        return struct.pack(">I", len(d)) + t + d + struct.pack(">I", zlib.crc32(t + d))
    ihdr = struct.pack(">IIBBBBB", w, h, bits, 0 if channels == 1 else 2, 0, 0, 0)
    with open(path, "wb") as f:
        f.write(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b""))


def write_capture(d, color="linear16", confidence=False, frames=N):
    """A wall 2 m in front of the camera (looking along -Z from the origin), uniform colour."""
    os.makedirs(d, exist_ok=True)
    json.dump({"format": "lucent-rgbd/1", "width": W, "height": H, "frames": frames}, open(d + "/capture.json", "w"))
    for k in range(1, frames + 1):
        json.dump({"sequence": k, "time_us": (k - 1) * 50000,
                   "intrinsics": {"fx": 0.78 * W, "fy": 0.78 * W, "cx": W / 2, "cy": H / 2},
                   "pose": {"translation": [0, 0, 0], "rotation": [0, 0, 0, 1]}, "exposure": 100.0,
                   "color": color}, open(d + "/frame_%05d.json" % k, "w"))
        png(d + "/depth_%05d.png" % k, W, H, 1, 16, [2000] * (W * H))
        if color == "linear16":
            png(d + "/color_%05d.png" % k, W, H, 3, 16, [20000, 30000, 10000] * (W * H))
        else:
            png(d + "/color_%05d.png" % k, W, H, 3, 8, [120, 180, 60] * (W * H))
        if confidence:  # the left quarter of the image is unsure
            png(d + "/confidence_%05d.png" % k, W, H, 1, 8, [10 if x < W // 4 else 255 for y in range(H) for x in range(W)])
    return d


def ctl(port, *args):
    r = subprocess.run([lt.LUCENTCTL, "--url", "ws://127.0.0.1:%d/" % port, "mr", "replay", *args],
                       capture_output=True, text=True, timeout=120)
    summary = None
    for line in r.stdout.splitlines():
        if line.startswith("{\"frames_sent\""):
            summary = json.loads(line)
    return r.returncode, summary, r.stdout, r.stderr


def place_object(port):
    ws = RawWS(port, timeout=30)
    ws.hello(client="placer")
    ws.send_json({"type": "object.set", "id": 2, "object": {"id": "mrcube", "asset": "cube",
                                                             "translation": [0, -0.05, -1]}})
    check(ws.recv_json().get("type") == "ok", "object.set ok")
    ws.close()


def test_replays(port):
    d = write_capture(os.path.join(TMP, "lin"))
    rc, s, out, err = ctl(port, d, "--objects", "mrcube", "--rate", "0", "--max-rate", "60")
    if check(rc == 0 and s, "replay exit 0 with a summary: rc %d\n%s\n%s" % (rc, out, err)):
        check(s["frames_sent"] == N and s["processed"] + s["replaced"] == N and s["errors"] == 0,
              "every frame acknowledged without error: %r" % s)
        check(s["processed"] >= 1 and s["lights_mean"] == W * H, "one light per wall pixel: %r" % s)
        raw = 128 + W * H * (2 + 6)
        check(s["bytes_raw_per_frame"] == raw and s["bytes_sent_per_frame"] == raw, "uncompressed size %r" % s)
        check(s["ack_ms"]["p95"] >= s["ack_ms"]["p50"] > 0, "ack latencies %r" % s["ack_ms"])
        check(out.count(" processed: ") == s["processed"], "one line per processed ack")
    vpl = os.path.join(TMP, "vpl.jsonl")
    rc, s, out, err = ctl(port, d, "--objects", "mrcube", "--quiet", "--vpl-out", vpl)
    if check(rc == 0 and s and os.path.exists(vpl), "--vpl-out replay: rc %d %s" % (rc, err)):
        lines = [json.loads(x) for x in open(vpl)]
        last = lines[-1]
        check(last["after_seq"] == N, "the last mr.vpl frame follows the last frame: %r" % last["after_seq"])
        objs = {o["id"]: o for o in last["objects"]}
        if check("mrcube" in objs and objs["mrcube"]["points"] == 256, "256 sparse points of the cube: %r"
                 % {k: v["points"] for k, v in objs.items()}):
            rec = objs["mrcube"]["records"]
            check(len(rec) == 256 * 12, "12 values per point")
            dark = sum(1 for i in range(256) if rec[12 * i:12 * i + 3] == [0, 0, 0])
            # the wall is behind the cube (seen from the camera): only the face towards the
            # camera (about a sixth of the points) gets no light at all
            check(20 <= dark <= 70, "points without light %d (the cube's +Z face)" % dark)
            lit = [rec[12 * i + 1] for i in range(256) if rec[12 * i + 1] > 0]
            check(lit and all(v == v and v < 1e6 for v in lit), "finite intensities")
    d = write_capture(os.path.join(TMP, "srgb"), color="srgb8", confidence=True)
    rc, s, out, err = ctl(port, d, "--objects", "mrcube", "--rate", "4", "--zlib", "--half-depth", "--loop", "2",
                          "--quiet")
    if check(rc == 0 and s, "srgb8 replay exit 0: rc %d\n%s\n%s" % (rc, out, err)):
        check(s["frames_sent"] == 2 * N and s["errors"] == 0, "two loops: %r" % s)
        check(s["lights_mean"] == W * H - (W // 4) * H, "low-confidence pixels are not lights: %r" % s)
        check(s["bytes_sent_per_frame"] < s["bytes_raw_per_frame"] / 4, "zlib on a flat image: %r" % s)
        check(s["seconds"] >= (2 * N - 1) * 0.05 / 4 * 0.9, "paced at 4x the recorded times: %r" % s)
        check(" processed: " not in out, "--quiet prints only the summary")


def test_bad_input(port):
    d = write_capture(os.path.join(TMP, "bad"), frames=2)
    png(d + "/depth_00002.png", W, H - 1, 1, 16, [2000] * (W * (H - 1)))
    rc, s, out, err = ctl(port, d, "--objects", "mrcube")
    check(rc == 2 and "depth_00002.png" in err and "%dx%d" % (W, H - 1) in err, "wrong PNG size: rc %d %s" % (rc, err))
    d = write_capture(os.path.join(TMP, "bad2"), frames=1)
    fj = json.load(open(d + "/frame_00001.json"))
    del fj["intrinsics"]["fy"]
    json.dump(fj, open(d + "/frame_00001.json", "w"))
    rc, s, out, err = ctl(port, d, "--objects", "mrcube")
    check(rc == 2 and "frame_00001.json" in err and "\"fy\"" in err, "missing field: rc %d %s" % (rc, err))
    rc, s, out, err = ctl(port, os.path.join(TMP, "lin"))
    check(rc == 2 and "--objects" in err, "no --objects: rc %d %s" % (rc, err))
    rc, s, out, err = ctl(port, os.path.join(TMP, "nowhere"), "--objects", "mrcube")
    check(rc == 2 and "capture.json" in err, "no recording: rc %d %s" % (rc, err))
    rc, s, out, err = ctl(port, os.path.join(TMP, "lin"), "--objects", "ghost")
    check(rc == 1 and "unknown_id" in err and "/session/objects/0" in err, "unknown object: rc %d %s" % (rc, err))


def test_refused():
    p, port = lt.start_lucentd(os.path.join(TMP, "off"), "--no-mr")
    try:
        rc, s, out, err = ctl(port, os.path.join(TMP, "lin"), "--objects", "mrcube")
        check(rc == 1 and "\"mr\" capability" in err, "--no-mr: rc %d %s" % (rc, err))
    finally:
        stop(p)


if __name__ == "__main__":
    for exe in (lt.LUCENTD, lt.LUCENTCTL, lt.CORNELL_LCB):
        if not os.path.exists(exe):
            print("SKIP: %s is not built" % exe)
            sys.exit(77)
    p, port = lt.start_lucentd(os.path.join(TMP, "state"))
    try:
        place_object(port)
        test_replays(port)
        test_bad_input(port)
    finally:
        check(stop(p) == 0, "lucentd stops cleanly")
    test_refused()
    if FAILS:
        print("%d failure(s)" % len(FAILS))
        sys.exit(1)
    print("lucentctl_mr: all checks passed")
