#!/usr/bin/python3
"""lucentd's MR sessions end to end (issue 18, PROTOCOL.md §8), beyond what the conformance
suite sees from outside:

  privacy     frames are never written: after a session, nothing in the state dir or the log
              holds a frame's plane bytes, and the revision did not move (no journal entry)
  fanout      a viewer (no MR) subscribed to objects sees the capture's light on the object,
              and its grid light again once the MR client disconnects (the session ends)
  metrics     lucent_mr_* count frames received, processed and replaced (latest wins)
  egl         --backend egl (the gather on GL compute): the viewer's light = the CPU's within 0.1%
  mr_off      --no-mr: hello's "mr" is not granted, binary frames stay binary_not_allowed"""
import math
import os
import struct
import sys
import tempfile
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "lib"))
import lucent_testlib as lt  # noqa: E402
from lucent_testlib import RawWS, stop  # noqa: E402

FAILS = []
TMP = tempfile.mkdtemp(prefix="lucent-mr-")
W, H = 96, 72


def check(cond, msg):
    if not cond:
        FAILS.append(msg)
        print("FAIL:", msg, file=sys.stderr)
    return cond


def mr_hello(port, client="mr-test"):
    ws = RawWS(port, timeout=60)
    ws.send_json({"type": "hello", "id": 1, "client": client, "capabilities": ["mr"]})
    return ws, ws.recv_json("welcome")


def object_c0(frame, oid):
    """Green c0 of `oid` in an objects keyframe (f32), or None."""
    h = lt.parse_frame(frame)
    pl = lt.frame_payload(frame)
    rec = 64 + 27 * 4
    for i in range(h["width"]):
        r = pl[i * rec:(i + 1) * rec]
        if r[:64].rstrip(b"\0").decode() == oid:
            return struct.unpack_from("<27f", r, 64)[1]
    return None


def next_objects_c0(ws, oid, pred, tries=40):
    last = None
    for _ in range(tries):
        op, data = ws.recv_frame()
        if op != 2 or lt.parse_frame(data)["stream"] != 3:
            continue
        last = object_c0(data, oid)
        if last is not None and pred(last):
            return last
    return last


def run_session(port, frames):
    """Controller with MR: places the object, begins, sends frames, returns (ws, acks)."""
    ws, w = mr_hello(port)
    if not check("mr" in w.get("capabilities", []), "the default bake's cube has sparse points: mr granted (%r)" % w):
        return ws, w, []
    ws.send_json({"type": "object.set", "id": 2, "object": {"id": "mrcube", "asset": "cube",
                                                             "translation": [0, -0.05, -1]}})
    check(ws.recv_json("ok"), "object.set ok")
    ws.send_json({"type": "mr.begin", "id": 3, "session": {"objects": ["mrcube"], "width": W, "height": H,
                                                           "depth": "u16mm", "color": "rgb16f_linear",
                                                           "max_rate": 60}})
    ok = ws.recv_json()
    check(ok.get("type") == "ok" and "mr" in ok, "mr.begin ok: %r" % ok)
    for seq, frame in enumerate(frames, 1):  # at the granted rate (a faster client is rate_limited)
        ws.send_frame(2, frame)
        time.sleep(1.0 / ok.get("mr", {}).get("max_rate", 1))
    acks = {}
    while len(acks) < len(frames):
        m = ws.recv_json()
        if m["type"] == "mr.ack":
            acks[m["seq"]] = m
        elif m["type"] == "error":
            check(False, "error during the session: %r" % m)
            break
    return ws, w, acks


def test_privacy_fanout_metrics():
    state = os.path.join(TMP, "state")
    p, port = lt.start_lucentd(state)
    try:
        viewer = RawWS(port, timeout=60)
        viewer.hello(client="viewer")
        viewer.send_json({"type": "subscribe", "id": 2, "stream": "objects", "encoding": "f32"})
        viewer.recv_json("ok")
        rev0 = lt.metric(port, "lucent_revision")
        # a marker colour no lightmap or state holds: half floats 0.1234, 0.4321, 0.2468
        frames = [lt.upload_frame(k, W, H, rgb=(0.1234, 0.4321, 0.2468), zlib_planes=(k == 2)) for k in range(1, 7)]
        ws, w, acks = run_session(port, frames)
        check(len(acks) == 6, "every frame acknowledged once: %r" % sorted(acks))
        check(acks.get(6, {}).get("status") == "processed", "the last frame is processed: %r" % acks.get(6))
        c0 = next_objects_c0(viewer, "mrcube", lambda v: v > 1.0)
        check(c0 is not None and c0 > 1.0, "the viewer sees the capture's light on the object (c0 %r)" % c0)
        lt.wait_metric(port, "lucent_mr_frames_processed_total", lambda v: v >= 1)
        check(lt.metric(port, "lucent_mr_frames_received_total") == 6, "6 frames received")
        proc = lt.metric(port, "lucent_mr_frames_processed_total")
        repl = lt.metric(port, "lucent_mr_frames_replaced_total")
        check(proc + repl == 6, "processed %r + replaced %r = 6" % (proc, repl))
        check(lt.metric(port, "lucent_revision") == rev0 + 1, "only the object.set moved the revision")
        ws.close()  # the session ends with the connection
        c1 = next_objects_c0(viewer, "mrcube", lambda v: abs(v - c0) > 0.05 * c0)
        check(c1 is not None and abs(c1 - c0) > 0.05 * c0, "after the MR client left: grid light again (%r)" % c1)
        viewer.close()
    finally:
        check(stop(p) == 0, "lucentd stops cleanly")
    # frames never reach the disk: the colour plane's first 96 bytes and the depth plane's
    plane = frames[0][128 + W * H * 2:128 + W * H * 2 + 96]
    marker = struct.pack("<3e", 0.1234, 0.4321, 0.2468)
    for root, _, files in os.walk(state):
        for name in files:
            data = open(os.path.join(root, name), "rb").read()
            check(marker not in data and plane not in data, "frame bytes in %s" % name)
    log = open(state + ".err", "rb").read()
    check(marker not in log, "frame bytes in the log")


def session_c0(backend):
    """The object's green c0 a viewer sees after a 3-frame session on this backend, or None
    when lucentd cannot start with it (no EGL)."""
    try:
        p, port = lt.start_lucentd(os.path.join(TMP, "be-" + backend), backend=backend)
    except lt.LucentdStartError:
        return None
    try:
        viewer = RawWS(port, timeout=60)
        viewer.hello(client="viewer")
        viewer.send_json({"type": "subscribe", "id": 2, "stream": "objects", "encoding": "f32"})
        viewer.recv_json("ok")
        frames = [lt.upload_frame(k, W, H, rgb=(0.3, 0.5, 0.2)) for k in range(1, 4)]
        ws, w, acks = run_session(port, frames)
        check(len(acks) == 3, "%s: every frame acknowledged: %r" % (backend, sorted(acks)))
        c0 = next_objects_c0(viewer, "mrcube", lambda v: v > 1.0)
        ws.close()
        viewer.close()
        return c0
    finally:
        stop(p)


def test_egl_matches_cpu():
    """--backend egl runs the gather on GL compute (the MR worker's own EGL context): the light
    a viewer gets agrees with the CPU's."""
    egl = session_c0("egl")
    if egl is None:
        print("egl: lucentd --backend egl does not start here (no EGL): case left out")
        return
    cpu = session_c0("cpu")
    check(cpu is not None and abs(egl - cpu) <= 1e-3 * abs(cpu), "egl c0 %r = cpu c0 %r within 0.1%%" % (egl, cpu))


def test_mr_off():
    p, port = lt.start_lucentd(os.path.join(TMP, "off"), "--no-mr")
    try:
        ws, w = mr_hello(port)
        check("mr" not in w.get("capabilities", []), "--no-mr: not granted (%r)" % w.get("capabilities"))
        ws.send_frame(2, lt.upload_frame(1, 16, 16))
        e = ws.recv_json("error")
        check(e["code"] == "binary_not_allowed", "binary frame without the grant: %r" % e)
        ws.send_json({"type": "mr.begin", "id": 5, "session": {"objects": ["x"], "width": 16, "height": 16,
                                                               "depth": "u16mm", "color": "rgb8_srgb"}})
        e = ws.recv_json("error")
        check(e["code"] == "mr_not_enabled", "mr.begin without the grant: %r" % e)
        ws.close()
    finally:
        stop(p)


if __name__ == "__main__":
    if not os.path.exists(lt.LUCENTD) or not os.path.exists(lt.CORNELL_LCB):
        print("SKIP: lucentd or the Cornell bake is not built")
        sys.exit(77)
    test_privacy_fanout_metrics()
    test_egl_matches_cpu()
    test_mr_off()
    if FAILS:
        print("%d failure(s)" % len(FAILS))
        sys.exit(1)
    print("daemon_mr: all checks passed")
