#!/usr/bin/python3
"""lucentd serving the probes solver (issue 20, PROTOCOL.md §3.4 scene.solvers, §4.9 solver), on
small Cornell bakes made here with lucent-bake:

  both          a --solver both bake: welcome.scene.solvers is ["pic", "probes"], the state starts
                on pic; settings.set solver probes relights with the other solver (a converged
                lightmap of the same scale but different texels, state.get shows it), survives a
                restart, and pic comes back the same as before
  probes_only   a --solver probes bake: solvers ["probes"], the state starts on probes, pic is
                refused naming /settings/solver and the state keeps probes
  grid          lucentd computes the SH grid only while a client takes the shgrid stream (--grid
                subscribed, the default; the thesis's §4.1): after converged lightmaps without any
                grid, a client that subscribes to shgrid gets a whole grid, the one a lucentd with
                --grid always serves; the objects stream is the same either way
"""
import array
import os
import socket
import subprocess
import sys
import tempfile
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "lib"))
import lucent_testlib as lt  # noqa: E402
from lucent_testlib import RawWS, frame_payload, parse_frame, stop  # noqa: E402

FAILS = []
TMP = tempfile.mkdtemp(prefix="lucent-solver-")
CORNELL = os.path.join(lt.SOURCE_DIR, "scenes", "cornell-box", "cornell-box.obj")
SMALL = ["--atlas-size", "32", "--surfels", "4096", "--grid-max-samples", "512", "--probes", "8", "--probe-bands",
         "4", "--probe-svd-error", "0.05", "--quiet", "--no-write-glb"]


def check(cond, msg):
    print(("ok: " if cond else "FAIL: ") + msg, file=sys.stdout if cond else sys.stderr)
    if not cond:
        FAILS.append(msg)
    return cond


def bake(name, solver, *extra):
    out = os.path.join(TMP, name + ".lcb")
    subprocess.run([lt.LUCENT_BAKE, "bake", CORNELL, "-o", out, "--solver", solver, *SMALL, *extra], check=True)
    return out


def request(ws, msg):
    ws.send_json(msg)
    end = time.time() + 20
    while time.time() < end:
        m = ws.recv_json()
        if m.get("id") == msg.get("id"):
            return m
    return {}


def converged_lightmap(ws, rid, revision=None):
    """The lightmap of the first converged keyframe (of `revision`, when given), after a snapshot."""
    got = converged_keyframe(ws, 1, rid, revision)
    return floats(got[1]) if got else None


def mean(a):
    return sum(a) / len(a) if a else 0.0


def connect(port):
    ws = RawWS(port, timeout=30)
    w = ws.hello()
    request(ws, {"type": "subscribe", "id": 2, "stream": "lightmap", "encoding": "f32"})
    return ws, w


def case_both():
    path, d = bake("both", "both"), os.path.join(TMP, "both")
    p, port = lt.start_lucentd(d, bake=path)
    try:
        ws, w = connect(port)
        check(w.get("scene", {}).get("solvers") == ["pic", "probes"], "both: welcome.scene.solvers %s" % (
            w.get("scene", {}).get("solvers")))
        st = request(ws, {"type": "state.get", "id": 3})
        check(st.get("settings", {}).get("solver") == "pic", "both: the state starts on pic")
        pic = converged_lightmap(ws, 4)
        ok = request(ws, {"type": "settings.set", "id": 5, "settings": {"solver": "probes"}})
        check(ok.get("type") == "ok", "both: settings.set solver probes accepted: %s" % ok)
        probes = converged_lightmap(ws, 6, ok.get("revision"))
        check(pic is not None and probes is not None, "both: converged lightmaps with each solver")
        if pic and probes:
            m_pic, m_probes = mean(pic), mean(probes)
            diff = mean([abs(a - b) for a, b in zip(pic, probes)]) / m_pic if m_pic > 0 else 0
            check(m_pic > 0 and 0.5 < m_probes / m_pic < 1.5, "both: probes lightmap mean %.4f vs pic %.4f" % (
                m_probes, m_pic))
            check(diff > 0.01, "both: the solvers' lightmaps differ (mean |difference| %.1f%% of pic's)" % (
                100 * diff))
        st = request(ws, {"type": "state.get", "id": 7})
        check(st.get("settings", {}).get("solver") == "probes", "both: state.get shows solver probes")
        ws.close()
    finally:
        check(stop(p) == 0, "both: clean stop")
    p, port = lt.start_lucentd(d, bake=path)
    try:
        ws, _ = connect(port)
        st = request(ws, {"type": "state.get", "id": 3})
        check(st.get("settings", {}).get("solver") == "probes", "both: solver probes survives a restart")
        ok = request(ws, {"type": "settings.set", "id": 4, "settings": {"solver": "pic"}})
        again = converged_lightmap(ws, 5, ok.get("revision"))
        if again and pic:
            worst = max(abs(a - b) for a, b in zip(again, pic))
            check(worst <= 1e-3 * max(pic), "both: back on pic, the same lightmap (worst %.3g of peak %.3g)" % (
                worst, max(pic)))
        ws.close()
    finally:
        stop(p)


def case_probes_only():
    path = bake("probes", "probes")
    p, port = lt.start_lucentd(os.path.join(TMP, "probes"), bake=path)
    try:
        ws, w = connect(port)
        check(w.get("scene", {}).get("solvers") == ["probes"], "probes_only: welcome.scene.solvers %s" % (
            w.get("scene", {}).get("solvers")))
        st = request(ws, {"type": "state.get", "id": 3})
        check(st.get("settings", {}).get("solver") == "probes", "probes_only: the state starts on probes")
        err = request(ws, {"type": "settings.set", "id": 4, "settings": {"solver": "pic"}})
        check(err.get("type") == "error" and "/settings/solver" in err.get("pointer", err.get("message", "")),
              "probes_only: pic refused naming /settings/solver: %s" % err)
        check(converged_lightmap(ws, 5) is not None, "probes_only: a converged lightmap is served")
        ws.close()
    finally:
        stop(p)


def converged_keyframe(ws, stream, rid, revision=None):
    """(header, payload) of the first converged keyframe of `stream` (of `revision` or later,
    when given) after a snapshot, or None. Lightmap keyframes come only when asked: while they
    are not converged, ask again."""
    request(ws, {"type": "snapshot", "id": rid})
    end = time.time() + 30
    while time.time() < end:
        ws.s.settimeout(max(0.01, end - time.time()))
        try:
            op, data = ws.recv_frame()
        except (socket.timeout, TimeoutError):
            break
        if op != 2:
            continue
        f = parse_frame(data)
        if f["stream"] != stream or not f["flags"] & 1 or (revision is not None and f["revision"] < revision):
            continue
        if f["converged"]:
            return f, frame_payload(data)
        if stream == 1:
            request(ws, {"type": "snapshot", "id": rid + 1000})
            time.sleep(0.2)
    return None


def floats(payload):
    a = array.array("f")
    a.frombytes(payload)
    return a


def case_grid():
    path = bake("grid", "probes", "--asset", "cube=" + os.path.join(lt.SOURCE_DIR, "scenes", "cornell-box", "cube.obj"))
    box = {"type": "object.set", "id": 3, "object": {"id": "o1", "asset": "cube", "translation": [0.28, 0, 0.28],
                                                     "scale": [2, 2, 2], "mode": "dynamic"}}
    served = {}
    for mode in ("always", "subscribed"):
        p, port = lt.start_lucentd(os.path.join(TMP, "grid-" + mode), "--grid", mode, bake=path)
        try:
            ws, _ = connect(port)
            has_asset = check(request(ws, box).get("type") == "ok", "grid %s: the cube placed" % mode)
            request(ws, {"type": "subscribe", "id": 4, "stream": "objects", "encoding": "f32"})
            lm = converged_keyframe(ws, 1, 5)
            check(lm is not None, "grid %s: a converged lightmap" % mode)
            obj = converged_keyframe(ws, 3, 6) if has_asset else None
            g = RawWS(port, timeout=30)
            g.hello()
            request(g, {"type": "subscribe", "id": 2, "stream": "shgrid", "encoding": "f32"})
            grid = converged_keyframe(g, 2, 3)
            check(grid is not None, "grid %s: a converged shgrid keyframe after subscribing late" % mode)
            served[mode] = (lm, obj, grid)
            g.close()
            ws.close()
        finally:
            check(stop(p) == 0, "grid %s: clean stop" % mode)
    if any(x is None for x in served["always"] + served["subscribed"]):
        return
    a, b = floats(served["always"][2][1]), floats(served["subscribed"][2][1])
    peak = max(abs(x) for x in a)
    worst = max(abs(x - y) for x, y in zip(a, b))
    zero = sum(1 for i in range(0, len(b), 27) if not any(b[i:i + 27]))
    check(len(a) == len(b) and peak > 0 and worst <= 1e-2 * peak,
          "grid: the late subscriber's grid is the whole one (worst %.3g of peak %.3g)" % (worst, peak))
    check(zero < len(b) // 27 // 2, "grid: %d of %d cells zero" % (zero, len(b) // 27))
    la, lb = floats(served["always"][0][1]), floats(served["subscribed"][0][1])
    check(max(abs(x - y) for x, y in zip(la, lb)) <= 1e-3 * max(la), "grid: the lightmap does not depend on --grid")
    if served["always"][1] and served["subscribed"][1]:
        oa, ob = floats(served["always"][1][1]), floats(served["subscribed"][1][1])
        check(max(abs(x - y) for x, y in zip(oa, ob)) <= 1e-2 * max(abs(x) for x in oa),
              "grid: the objects' SH does not depend on --grid")


for case in (case_both, case_probes_only, case_grid):
    try:
        case()
    except Exception as e:  # a crash in one case is a failure, the others still run
        check(False, "%s raised %r" % (case.__name__, e))
print("%d failure(s)" % len(FAILS) if FAILS else "all checks passed")
sys.exit(1 if FAILS else 0)
