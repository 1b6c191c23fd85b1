#!/usr/bin/python3
"""bench/served.py: fidelity and time to converge of what a client of lucentd receives (issue 16).

lucentd runs with its own defaults (no quality or refinement flags: only a free port, a
temporary --state-dir, --backend and --log-level), so what is measured is what a user gets.

  served.py row --bin DIR --bake BAKE --reference REFDIR --out OUTDIR [--state STATE.json]
      Starts lucentd on BAKE, applies STATE (the lights, objects, materials, environment of a
      state JSON, as bench/fidelity.sh writes it for lucent-ref; lights the daemon holds that
      STATE lacks are removed) with `lucentctl send` in one batch (revision N), waits with
      `lucentctl watch --until-revision N --settle S` until the refinement of N is over, takes
      `lucentctl snapshot --raw` (lightmap.f32: the default rgb9e5 encoding decoded, bit-exact
      with what a client holds; shgrid.bin: f32, cells x 9 x RGB as `lucent-ref compare
      --grid` reads it) and runs `lucent-ref compare` on it. The copy a watching client built
      from keyframes + delta frames (its last frame) is compared too (`stream`). Writes
      OUTDIR/served.json: compare.json's fields, plus served, daemon (flags, defaults from
      lucentd --help), revision, pass and converged of the last frame, refine_ms (server time
      from the revision's first frame to its last), frames, stream.

  served.py converge --bin DIR --bake BAKE --change JSON [--state STATE.json] --out OUT.json
      The time to converge as a client sees it. Starts lucentd (defaults), subscribes to the
      lightmap (--encoding, f32 by default: no texel encoding error, deltas as the server
      sends them), applies STATE and waits until its refinement is over, then sends ONE change
      (the JSON message CHANGE, e.g. a light.set) and records every frame that arrives, with
      its arrival time after the send, until the new revision's converged frame and --settle s
      of quiet. Frames are applied afterwards (keyframes + tile deltas, PROTOCOL.md 6.2) onto
      the client's copy, and each frame of the new revision gets
          dist = sum |Y_frame - Y_conv| / sum Y_conv      (Y = luminance, lc_ref_luminance)
      over the covered texels (--mask: a reference's reference_texels.bin, texels marked 1 =
      owning their cache; without it every texel: uncovered ones are black in both). Y_conv is
      the same state run to convergence: --converged FILE (raw float32 RGB W*H, e.g. lucentctl
      snapshot --raw --encoding f32) or, by default, a second lucentd run with --refine-passes
      64 (and --refine-tolerance 0 where lucentd has it), read from a snapshot keyframe.
      OUT.json: frames [{t_ms, revision, pass, converged, keyframe, tiles, bytes, dist}],
      t_within_1pct_ms (first frame of the new revision with dist <= 0.01, else null),
      final_dist (the client's copy at the end), snapshot_dist (a fresh keyframe at the end),
      t_first_frame_ms, t_converged_ms, t_ok_ms, daemon, reference.

Only /usr/bin/python3 and tests/lib/lucent_testlib.py (its raw WebSocket client, frame parsing
and lucentd launcher) are needed."""
import argparse
import array
import json
import math
import os
import re
import select
import shutil
import struct
import subprocess
import sys
import tempfile
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tests", "lib"))
import lucent_testlib as lt  # noqa: E402

LUMA = (0.2126, 0.7152, 0.0722)  # tools/ref/ref.h lc_ref_luminance
ENCODINGS = {"rgb9e5": 1, "rgba16f": 2, "f32": 3}
TEXEL_BYTES = {1: 4, 2: 8, 3: 12}
# lucentd options whose defaults say how it serves (recorded with every measurement)
SETTINGS = ("backend", "threads", "bounces", "refine-passes", "refine-tolerance", "refine-delay", "tile",
            "keyframe-interval", "delta-threshold")


class ServedError(RuntimeError):
    pass


# --------------------------------------------------------------------------- lucentd and its state

def daemon_defaults(lucentd):
    """{option: default} of SETTINGS from `lucentd --help` (only those this lucentd has)."""
    text = subprocess.run([lucentd, "--help"], capture_output=True, text=True, timeout=30).stdout
    out = {}
    for line in text.splitlines():
        m = re.match(r"^\s+--([a-z-]+)\s.*\(default ([^()]*)\)(?: \[[^]]*\])?\s*$", line)
        if m and m.group(1) in SETTINGS:
            v = m.group(2)
            try:
                v = int(v) if re.fullmatch(r"-?\d+", v) else float(v)
            except ValueError:
                pass
            out[m.group(1)] = v
    return out


def start(args, extra=()):
    """lucentd on a free port, its state in a fresh temporary directory: (process, port, tmpdir, argv)."""
    tmp = tempfile.mkdtemp(prefix="lucent-served-")
    flags = [*extra]
    p, port = lt.start_lucentd(os.path.join(tmp, "state"), *flags, bake=args.bake,
                               lucentd=os.path.join(args.bin, "lucentd"), backend=args.backend)
    argv = ["lucentd", "--bake", args.bake, "--port", "0", "--state-dir", "TMP", "--backend", args.backend,
            "--log-level", "warn", *flags]
    return p, port, tmp, argv


def finish(p, tmp):
    lt.stop(p)
    shutil.rmtree(tmp, ignore_errors=True)  # the state and lucentd's log (state.err)


def state_ops(target, current):
    """The change messages (a batch's ops) that turn the daemon's `current` state into `target`
    (a state JSON): lights and objects of `current` that `target` lacks are removed; target's
    lights, objects and materials are set; the environment is set (none when target has none);
    target's settings, when it names any."""
    ops = []
    keep = {l["id"] for l in target.get("lights", [])}
    ops += [{"type": "light.remove", "light_id": l["id"]} for l in current.get("lights", []) if l["id"] not in keep]
    keep = {o["id"] for o in target.get("objects", [])}
    ops += [{"type": "object.remove", "object_id": o["id"]} for o in current.get("objects", []) if o["id"] not in keep]
    ops += [{"type": "light.set", "light": l} for l in target.get("lights", [])]
    ops += [{"type": "object.set", "object": o} for o in target.get("objects", [])]
    ops += [{"type": "material.set", "material": m["name"], "emission": m["emission"]}
            for m in target.get("materials", [])]
    ops.append({"type": "environment.set", "environment": target.get("environment") or {"type": "none"}})
    if target.get("settings"):
        ops.append({"type": "settings.set", "settings": target["settings"]})
    return ops


def load_json(path):
    with open(path) as fh:
        return json.load(fh)


# --------------------------------------------------------------------------- lightmap frames

def decode_texels(enc, data):
    """Encoded texels -> flat RGB floats (PROTOCOL.md 6.2)."""
    if enc == 3:
        a = array.array("f")
        a.frombytes(data)
        if sys.byteorder != "little":
            a.byteswap()
        return a
    if enc == 2:
        h = struct.unpack("<%de" % (len(data) // 2), data)
        out = array.array("f", bytes(4 * 3 * (len(h) // 4)))
        out[0::3], out[1::3], out[2::3] = (array.array("f", h[c::4]) for c in range(3))
        return out
    words = struct.unpack("<%dI" % (len(data) // 4), data)
    out = array.array("f", bytes(12 * len(words)))
    for i, w in enumerate(words):
        s = 2.0 ** ((w >> 27) - 24)  # shared exponent, bias 15, 9 mantissa bits
        out[3 * i], out[3 * i + 1], out[3 * i + 2] = (w & 511) * s, (w >> 9 & 511) * s, (w >> 18 & 511) * s
    return out


class ClientCopy:
    """The lightmap as a client holds it: keyframes replace it, tile deltas patch it (6.2).
    apply() returns the texel index ranges it changed."""

    def __init__(self):
        self.w = self.h = 0
        self.rgb = None
        self.seq = None

    def apply(self, data):
        f = lt.parse_frame(data)
        if not (f["magic"] == lt.MAGIC and f["crc_ok"] and f["length_ok"]):
            raise ServedError("lightmap frame %s: bad magic, CRC or length" % f["sequence"])
        if f["flags"] & lt.FLAG_RESIDUAL:
            raise ServedError("residual deltas are not decoded here (subscribe with tile deltas)")
        if self.seq is not None and f["sequence"] != self.seq + 1:
            raise ServedError("lightmap sequence gap: %d after %d" % (f["sequence"], self.seq))
        self.seq = f["sequence"]
        payload = lt.frame_payload(data)
        tb = TEXEL_BYTES.get(f["encoding"])
        if tb is None:
            raise ServedError("lightmap frame encoding %d unknown" % f["encoding"])
        w, h = f["width"], f["height"]
        if f["flags"] & lt.FLAG_KEYFRAME:
            if len(payload) != w * h * tb:
                raise ServedError("keyframe payload %d B, %dx%d texels need %d" % (len(payload), w, h, w * h * tb))
            self.w, self.h, self.rgb = w, h, decode_texels(f["encoding"], payload)
            return [(0, w * h)]
        if self.rgb is None or (w, h) != (self.w, self.h):
            raise ServedError("delta frame %d before a keyframe of its size" % f["sequence"])
        s = f["tile"]
        tw = (w + s - 1) // s
        table = struct.unpack_from("<%dI" % f["tiles"], data, lt.HEADER_SIZE)
        vals = decode_texels(f["encoding"], payload)
        k, changed = 0, []
        for t in table:
            x0, y0 = (t % tw) * s, (t // tw) * s
            x1, y1 = min(x0 + s, w), min(y0 + s, h)
            if x0 >= w or y0 >= h:
                raise ServedError("delta tile %d outside %dx%d" % (t, w, h))
            n = 3 * (x1 - x0)
            for y in range(y0, y1):
                if k + n > len(vals):
                    raise ServedError("delta frame %d: payload shorter than its tiles" % f["sequence"])
                a = 3 * (y * w + x0)
                self.rgb[a:a + n] = vals[k:k + n]
                changed.append((y * w + x0, y * w + x1))
                k += n
        if k != len(vals):
            raise ServedError("delta frame %d: payload longer than its tiles" % f["sequence"])
        return changed


def luminance(rgb):
    r, g, b = LUMA
    return array.array("d", (r * x + g * y + b * z for x, y, z in zip(rgb[0::3], rgb[1::3], rgb[2::3])))


class Distance:
    """sum |Y - Y_conv| / sum Y_conv over the covered texels, kept up to date texel range by range."""

    def __init__(self, y_conv, mask):
        self.yc = y_conv
        self.mask = mask
        self.den = sum(y for y, m in zip(y_conv, mask) if m)
        if not self.den > 0:
            raise ServedError("the converged lightmap is black over the covered texels")
        self.err = array.array("d", bytes(8 * len(y_conv)))
        self.num = 0.0

    def update(self, copy, ranges):
        if len(copy.rgb) != 3 * len(self.yc):
            raise ServedError("lightmap of %d texels, the converged one has %d" % (len(copy.rgb) // 3, len(self.yc)))
        r, g, b = LUMA
        rgb, yc, mask, err = copy.rgb, self.yc, self.mask, self.err
        for a, z in ranges:
            for i in range(a, z):
                e = abs(r * rgb[3 * i] + g * rgb[3 * i + 1] + b * rgb[3 * i + 2] - yc[i]) if mask[i] else 0.0
                self.num += e - err[i]
                err[i] = e
        if len(ranges) == 1 and ranges[0] == (0, len(yc)):  # a keyframe: sum again, no drift
            self.num = math.fsum(err)
        return max(self.num, 0.0) / self.den


# --------------------------------------------------------------------------- a raw client

class Conn:
    """RawWS with a poll: next(timeout) -> ("text", msg) | ("frame", t, bytes) | None."""

    def __init__(self, port, client):
        self.ws = lt.RawWS(port, timeout=30.0)
        if not self.ws.ok:
            raise ServedError("WebSocket upgrade refused: %s" % self.ws.status_line)
        self.welcome = self.ws.hello(client=client)
        if self.welcome.get("type") != "welcome":
            raise ServedError("hello answered %r" % self.welcome)
        self.next_id = 10

    def send(self, msg):
        self.next_id += 1
        msg = dict(msg, id=self.next_id)
        self.ws.send_json(msg)
        return self.next_id

    def next(self, timeout):
        if not self.ws.buf:
            r, _, _ = select.select([self.ws.s], [], [], max(timeout, 0))
            if not r:
                return None
        op, data = self.ws.recv_frame()
        t = time.monotonic()
        if op == 8:
            raise ServedError("server closed the connection: %r" % data[:80])
        if op == 2:
            return ("frame", t, data)
        if op == 1:
            return ("text", json.loads(data))
        return self.next(timeout)

    def request(self, msg, want, timeout=30.0, on_frame=None):
        """Sends msg; returns the reply of type `want` to it (frames go to on_frame meanwhile)."""
        rid = self.send(msg)
        end = time.monotonic() + timeout
        while True:
            m = self.next(end - time.monotonic())
            if m is None:
                raise ServedError("no reply to %s within %.0f s" % (msg["type"], timeout))
            if m[0] == "frame":
                if on_frame:
                    on_frame(m[1], m[2])
            elif m[1].get("id") == rid:
                if m[1].get("type") == "error":
                    raise ServedError("%s refused: %s" % (msg["type"], json.dumps(m[1])))
                if m[1].get("type") == want:
                    return m[1]

    def close(self):
        self.ws.close()


def settle(conn, revision, on_frame, quiet, timeout, what):
    """Reads frames until one of `revision` (or later) marked converged has come and then none
    for `quiet` s. Returns the last frame's header."""
    end = time.monotonic() + timeout
    last, conv_seen, t_last = None, False, time.monotonic()
    while True:
        left = end - time.monotonic()
        if left <= 0:
            raise ServedError("%s: no converged frame of revision %d within %.0f s (last: %r)" % (
                what, revision, timeout, last and {k: last[k] for k in ("revision", "refine_pass", "converged")}))
        m = conn.next(min(left, quiet if conv_seen else left))
        if m is None:
            if conv_seen and time.monotonic() - t_last >= quiet:
                return last
            continue
        if m[0] != "frame":
            continue
        on_frame(m[1], m[2])
        f = lt.parse_frame(m[2])
        t_last, last = m[1], f
        if f["revision"] >= revision:
            conv_seen = conv_seen or f["converged"]


# --------------------------------------------------------------------------- converge

def session(args, extra, change):
    """One lucentd: subscribe, the base state, then CHANGE. Returns a dict with the frames after
    the send (raw, with arrival times), the copy before them, revisions, and a final snapshot keyframe."""
    p, port, tmp, argv = start(args, extra)
    conn = None
    try:
        conn = Conn(port, "bench/served.py")
        copy = ClientCopy()
        apply = lambda t, d: copy.apply(d)  # noqa: E731
        conn.request({"type": "subscribe", "stream": "lightmap", "encoding": args.encoding}, "ok", on_frame=apply)
        rev = conn.welcome["revision"]
        if args.state:
            cur = conn.request({"type": "state.get"}, "state", on_frame=apply)
            ok = conn.request({"type": "batch", "ops": state_ops(load_json(args.state), cur)}, "ok", on_frame=apply)
            rev = ok["revision"]
        base = settle(conn, rev, apply, args.settle, args.timeout, "the base state")
        frames, box = [], {}

        def keep(t, d):
            frames.append((t, d))

        t0 = time.monotonic()
        rid = conn.send(change)
        end = t0 + args.timeout
        while "rev" not in box:
            m = conn.next(end - time.monotonic())
            if m is None:
                raise ServedError("no reply to the change within %.0f s" % args.timeout)
            if m[0] == "frame":
                keep(m[1], m[2])
            elif m[1].get("id") == rid:
                if m[1].get("type") != "ok":
                    raise ServedError("the change was refused: %s" % json.dumps(m[1]))
                box.update(rev=m[1]["revision"], t_ok=time.monotonic())
        last = settle(conn, box["rev"], keep, args.settle, max(end - time.monotonic(), 1), "the change")
        snap = []
        conn.request({"type": "snapshot"}, "ok", on_frame=lambda t, d: snap.append(d))
        while not (snap and lt.parse_frame(snap[-1])["flags"] & lt.FLAG_KEYFRAME):  # the keyframe follows the ok
            m = conn.next(30.0)
            if m is None:
                raise ServedError("no keyframe after snapshot")
            if m[0] == "frame":
                snap.append(m[2])
        return {"copy": copy, "frames": frames, "t0": t0, "t_ok": box["t_ok"], "revision": box["rev"],
                "base": base, "last": last, "snapshot": snap[-1], "argv": argv}
    finally:
        if conn:
            conn.close()
        finish(p, tmp)


def read_f32(path):
    a = array.array("f")
    with open(path, "rb") as fh:
        a.frombytes(fh.read())
    if sys.byteorder != "little":
        a.byteswap()
    return a


def reference_lightmap(args, change):
    """Y_conv: --converged, or a second lucentd refining 64 passes (tolerance 0 where it has one)."""
    if args.converged:
        return luminance(read_f32(args.converged)), {"source": args.converged}
    extra = list(args.daemon_arg) + ["--refine-passes", "64"]
    if "refine-tolerance" in daemon_defaults(os.path.join(args.bin, "lucentd")):
        extra += ["--refine-tolerance", "0"]
    saved = args.encoding
    args.encoding = "f32"
    try:
        s = session(args, extra, change)
    finally:
        args.encoding = saved
    snap = ClientCopy()
    snap.apply(s["snapshot"])
    f = lt.parse_frame(s["snapshot"])
    return luminance(snap.rgb), {"source": "lucentd " + " ".join(s["argv"][1:]) + ", snapshot keyframe (f32)",
                                 "pass": f["refine_pass"], "converged": f["converged"], "revision": f["revision"]}


def converge(args):
    change = json.loads(args.change)
    lucentd = os.path.join(args.bin, "lucentd")
    y_conv, ref = reference_lightmap(args, change)
    mask = [1] * len(y_conv)
    if args.mask:
        with open(args.mask, "rb") as fh:
            raw = fh.read()
        if len(raw) != len(y_conv):
            raise ServedError("%s: %d texels, the lightmap has %d" % (args.mask, len(raw), len(y_conv)))
        mask = [1 if b == 1 else 0 for b in raw]
    dist = Distance(y_conv, mask)  # refuses a black Y_conv before lucentd starts
    s = session(args, list(args.daemon_arg), change)
    copy = s["copy"]
    dist.update(copy, [(0, len(y_conv))])
    rows = []
    for t, data in s["frames"]:
        ranges = copy.apply(data)
        d = dist.update(copy, ranges)
        f = lt.parse_frame(data)
        if f["revision"] >= s["revision"]:
            rows.append({"t_ms": round(1000 * (t - s["t0"]), 2), "revision": f["revision"], "pass": f["refine_pass"],
                         "converged": f["converged"], "keyframe": bool(f["flags"] & lt.FLAG_KEYFRAME),
                         "tiles": f["tiles"], "bytes": len(data), "dist": round(d, 6)})
    snap = ClientCopy()
    snap.apply(s["snapshot"])
    snap_dist = Distance(y_conv, mask).update(snap, [(0, len(y_conv))])
    within = next((r["t_ms"] for r in rows if r["dist"] <= 0.01), None)
    conv = next((r["t_ms"] for r in rows if r["converged"]), None)
    out = {"bench": "served-converge", "bake": os.path.abspath(args.bake), "state": args.state, "change": change,
           "encoding": args.encoding, "revision": s["revision"],
           "daemon": {"argv": s["argv"], "defaults": daemon_defaults(lucentd)},
           "reference": ref, "covered_texels": sum(mask), "mask": args.mask,
           "metric": "dist = sum |Y_frame - Y_conv| / sum Y_conv over covered texels (Y = luminance); t_ms from the "
                     "send of the change to the frame's arrival at this client",
           "t_ok_ms": round(1000 * (s["t_ok"] - s["t0"]), 2),
           "t_first_frame_ms": rows[0]["t_ms"] if rows else None, "t_converged_ms": conv,
           "t_within_1pct_ms": within, "first_dist": rows[0]["dist"] if rows else None,
           "final_dist": rows[-1]["dist"] if rows else None, "final_pass": rows[-1]["pass"] if rows else None,
           "snapshot_dist": round(snap_dist, 6), "frames": rows}
    if not rows:
        raise ServedError("no frame of revision %d arrived" % s["revision"])
    return out


# --------------------------------------------------------------------------- row

def ctl(args, port, *cmd, timeout=60):
    r = subprocess.run([os.path.join(args.bin, "lucentctl"), "--url", "ws://127.0.0.1:%d/" % port, *cmd],
                       capture_output=True, text=True, timeout=timeout)
    if r.returncode != 0:
        raise ServedError("lucentctl %s: exit %d: %s" % (" ".join(cmd[:2]), r.returncode, r.stderr.strip()[-400:]))
    return r.stdout


def compare(args, lightmap, grid, out):
    cmd = [os.path.join(args.bin, "lucent-ref"), "compare", "--reference", args.reference, "--lightmap", lightmap,
           "--out", out]
    if grid:
        cmd += ["--grid", grid]
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    if r.returncode != 0:
        raise ServedError("lucent-ref compare %s: exit %d: %s" % (lightmap, r.returncode, r.stderr.strip()[-400:]))
    return load_json(os.path.join(out, "compare.json"))


def watch_until_converged(args, port, rev, out):
    """`lucentctl watch` of the lightmap (a client holding keyframes + deltas, --raw) until a frame
    of revision >= rev marked converged has come and then none for --settle s; then Ctrl-C.
    Returns its frames.jsonl records."""
    cmd = [os.path.join(args.bin, "lucentctl"), "--url", "ws://127.0.0.1:%d/" % port, "watch", "--stream", "lightmap",
           "--raw", "--no-reconnect", "--duration", str(int(args.timeout)), "--out", out]
    index = os.path.join(out, "frames.jsonl")
    w = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    end, frames, t_new, done = time.monotonic() + args.timeout, [], time.monotonic(), False
    try:
        while time.monotonic() < end and w.poll() is None:
            time.sleep(0.05)
            try:
                with open(index) as fh:
                    lines = [l for l in fh.read().split("\n")[:-1] if l.strip()]  # whole lines only
            except FileNotFoundError:
                continue
            if len(lines) != len(frames):
                frames, t_new = [json.loads(l) for l in lines], time.monotonic()
            done = done or any(f["revision"] >= rev and f.get("converged") for f in frames)
            if done and time.monotonic() - t_new >= args.settle:
                break
    finally:
        if w.poll() is None:
            w.send_signal(2)  # SIGINT: lucentctl watch stops as on Ctrl-C
            try:
                w.wait(10)
            except subprocess.TimeoutExpired:
                w.kill()
                w.wait()
    if not done:
        raise ServedError("lucentctl watch: no converged frame of revision %d within %.0f s (exit %s: %s; last %r)" % (
            rev, args.timeout, w.returncode, w.stderr.read().strip()[-300:], frames[-1] if frames else None))
    return frames


def row(args):
    os.makedirs(args.out, exist_ok=True)
    for sub in ("watch", "snapshot", "compare", "compare-stream"):
        shutil.rmtree(os.path.join(args.out, sub), ignore_errors=True)
    p, port, tmp, argv = start(args, list(args.daemon_arg))
    watch, snapdir = os.path.join(args.out, "watch"), os.path.join(args.out, "snapshot")
    try:
        cur = json.loads(ctl(args, port, "--json", "state"))
        rev = cur["revision"]
        if args.state:
            batch = json.dumps({"type": "batch", "ops": state_ops(load_json(args.state), cur)})
            rev = json.loads(ctl(args, port, "--json", "send", batch).splitlines()[-1])["revision"]
        elif cur.get("lights") or cur.get("objects"):
            raise ServedError("lucentd starts %s with lights or objects: give the reference's --state" % args.bake)
        frames = watch_until_converged(args, port, rev, watch)
        ctl(args, port, "snapshot", "--out", snapdir, "--raw", "--stream", "lightmap,shgrid")
    finally:
        finish(p, tmp)
    mine = [f for f in frames if f["revision"] >= rev]
    snap = load_json(os.path.join(snapdir, "snapshot.json"))
    grid = os.path.join(snapdir, "shgrid.bin")
    c = compare(args, os.path.join(snapdir, "lightmap.f32"), grid if os.path.exists(grid) else None,
                os.path.join(args.out, "compare"))
    cs = compare(args, os.path.join(watch, mine[-1]["file"] + ".f32"), None, os.path.join(args.out, "compare-stream"))
    out = dict(c)
    out.update({"served": True, "daemon": {"argv": argv, "defaults": daemon_defaults(os.path.join(args.bin, "lucentd"))},
                "state": args.state, "revision": rev, "encoding": snap["lightmap"]["encoding"],
                "pass": mine[-1].get("pass"), "converged": mine[-1].get("converged"),
                "refine_ms": round((mine[-1]["server_time_us"] - mine[0]["server_time_us"]) / 1000, 1),
                "frames": len(mine), "stream": cs.get("lightmap")})
    with open(os.path.join(args.out, "served.json"), "w") as fh:
        json.dump(out, fh, indent=1)
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter, epilog=__doc__)
    sub = ap.add_subparsers(dest="cmd", required=True)
    for name in ("row", "converge"):
        s = sub.add_parser(name)
        s.add_argument("--bin", required=True, help="the build's bin/ (lucentd, lucentctl, lucent-ref)")
        s.add_argument("--bake", required=True)
        s.add_argument("--state", help="state JSON to serve (default: the daemon's initial lights removed, environment none)")
        s.add_argument("--backend", default="cpu", help="lucentd --backend (default cpu)")
        s.add_argument("--daemon-arg", action="append", default=[],
                       help="extra lucentd flag (repeat; none for the defaults), e.g. --daemon-arg=--refine-passes=4")
        s.add_argument("--settle", type=float, default=2.0, help="quiet seconds after the converged frame (default 2)")
        s.add_argument("--timeout", type=float, default=300.0, help="seconds to wait for convergence (default 300)")
        if name == "row":
            s.add_argument("--reference", required=True, help="lucent-ref render directory of the same bake and state")
            s.add_argument("--out", required=True, help="output directory (served.json, snapshot/, watch/, compare/)")
        else:
            s.add_argument("--change", required=True, help="the one change message (JSON), e.g. a light.set")
            s.add_argument("--encoding", default="f32", choices=sorted(ENCODINGS), help="lightmap encoding (default f32)")
            s.add_argument("--converged", help="Y_conv from this raw float32 RGB lightmap instead of a 64-pass run")
            s.add_argument("--mask", help="texel mask (u8, 1 = covered: a reference's reference_texels.bin)")
            s.add_argument("--out", required=True, help="output JSON")
    a = ap.parse_args()
    a.daemon_arg = [x for arg in a.daemon_arg for x in arg.split("=", 1)] if a.daemon_arg else []
    try:
        if a.cmd == "row":
            r = row(a)
            lm = r.get("lightmap") or {}
            print("served: %s pass %s%s: lightmap mean %.2f%% p95 %.2f%% bias %+.2f%% (n %d)" % (
                os.path.basename(a.bake), r["pass"], " converged" if r["converged"] else "", 100 * lm.get("mean", 0),
                100 * lm.get("p95", 0), 100 * lm.get("bias", 0), lm.get("compared", 0)), file=sys.stderr)
        else:
            r = converge(a)
            with open(a.out, "w") as fh:
                json.dump(r, fh, indent=1)
            print("served: converge %s: %d frames, first %.1f ms dist %.4f, final dist %.4f (pass %s), within 1%%: %s" % (
                os.path.basename(a.bake), len(r["frames"]), r["t_first_frame_ms"], r["first_dist"], r["final_dist"],
                r["final_pass"], "%.1f ms" % r["t_within_1pct_ms"] if r["t_within_1pct_ms"] is not None else "never"),
                file=sys.stderr)
    except (ServedError, lt.LucentdStartError, lt.WaitTimeout, OSError, ValueError, subprocess.TimeoutExpired) as e:
        print("served.py: %s" % e, file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
