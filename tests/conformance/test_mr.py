"""MR sessions (PROTOCOL.md §8, lucent/1.1): negotiation, mr.begin/mr.end, upload frames
(every malformed field answered with the error that names it, the connection kept),
acknowledgements, latest-wins, rate limits, and the light a synthetic capture gives an
object. Skipped on a server that does not grant the `mr` capability (a 1.0 server, or MR
off) except the cases a 1.0 server must pass too."""
import asyncio
import math
import struct
import zlib

import pytest

from conftest import aio, controller, open_client, subscribe_keyframe, decode_sh

section = pytest.mark.section

UPLOAD_MAGIC = 0x3155434C
DEPTH = {"u16mm": 1, "f16m": 2}
COLOR = {"rgb8_srgb": 1, "rgb16f_linear": 2}
SH_Y00 = 0.5 * math.sqrt(1 / math.pi)
SH_Y1 = math.sqrt(3 / (4 * math.pi))


def upload_frame(seq, w, h, depth_mm=2000, color=(0.5, 0.5, 0.5), exposure=100.0, depth_enc="u16mm",
                 color_enc="rgb16f_linear", zlib_planes=False, confidence=None, pose=None, intrinsics=None,
                 patch=None):
    """An LCU1 frame (§8.4) of a flat wall: every pixel at depth_mm, one linear colour.
    `patch(header_bytearray, planes)` may break it before the CRC is computed; it returns
    (header, planes, fix_crc)."""
    n = w * h
    if depth_enc == "u16mm":
        depth = struct.pack("<%dH" % n, *([depth_mm] * n))
    else:
        depth = struct.pack("<%de" % n, *([depth_mm / 1000.0] * n))
    if color_enc == "rgb16f_linear":
        col = struct.pack("<%de" % (3 * n), *(list(color) * n))
    else:
        def enc(c):
            v = 12.92 * c if c <= 0.0031308 else 1.055 * c ** (1 / 2.4) - 0.055
            return max(0, min(255, round(v * 255)))
        col = bytes([enc(c) for c in color] * n)
    conf = bytes([confidence] * n) if confidence is not None else b""
    planes = [depth, conf, col]
    if zlib_planes:
        planes = [zlib.compress(p) if p else p for p in planes]
    fx, fy, cx, cy = intrinsics or (w * 0.78, w * 0.78, w / 2, h / 2)
    t, q = pose or ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0))
    hdr = bytearray(128)
    struct.pack_into("<IHBBHHIQHHBBBBB", hdr, 0, UPLOAD_MAGIC, 1, 1, 1 if confidence is not None else 0, 128, 0,
                     seq, 1000 * seq, w, h, DEPTH[depth_enc], COLOR[color_enc],
                     1 if zlib_planes else 0, 1 if (zlib_planes and confidence is not None) else 0,
                     1 if zlib_planes else 0)
    struct.pack_into("<4f3f4ff", hdr, 36, fx, fy, cx, cy, *t, *q, exposure)
    fix_crc = True
    if patch:
        hdr, planes, fix_crc = patch(hdr, planes)
    struct.pack_into("<III", hdr, 84, len(planes[0]), len(planes[1]), len(planes[2]))
    if patch and getattr(patch, "after_sizes", None):
        hdr, planes, fix_crc = patch.after_sizes(hdr, planes)
    body = b"".join(planes)
    if fix_crc:
        struct.pack_into("<I", hdr, 124, zlib.crc32(bytes(hdr[:124]) + body))
    return bytes(hdr) + body


async def mr_client(cfg, name="conf-mr"):
    c = await open_client(cfg, name=name, hello_extra={"capabilities": ["mr"]})
    if c.welcome["role"] != "controller":
        await c.close()
        pytest.skip("the default token does not give the controller role")
    if "mr" not in c.welcome.get("capabilities", []):
        await c.close()
        pytest.skip("the server does not grant the mr capability (a 1.0 server, or MR sessions off)")
    return c


async def placed_object(c, cfg, oid=None):
    """A cube object centred at (0, 0, -1) (the asset stands on its base, 10 cm high)."""
    oid = oid or cfg.uid("mr-obj")
    assets = c.welcome["scene"].get("assets", [])
    if "cube" not in assets:
        pytest.skip("the scene has no 'cube' asset")
    await c.expect_ok({"type": "object.set", "object": {"id": oid, "asset": "cube", "translation": [0, -0.05, -1]}})
    return oid


async def begin(c, oid, w=64, h=48, **kw):
    s = {"objects": [oid], "width": w, "height": h, "depth": "u16mm", "color": "rgb16f_linear", "max_rate": 60}
    s.update(kw)
    ok = await c.expect_ok({"type": "mr.begin", "session": s})
    m = ok.get("mr")
    assert isinstance(m, dict) and m.get("max_frame", 0) > 0 and m.get("points", 0) > 0, \
        "§8.2 ok of mr.begin must carry mr limits: %r" % ok
    return m


async def next_ack(c, seq, timeout=None):
    return await c.recv_json("mr.ack", pred=lambda m: m.get("seq") == seq, timeout=timeout or max(c.cfg.timeout, 30))


@section("8.1")
@aio
async def test_binary_without_capability_still_refused(cfg):
    """A client that did not ask for `mr` gets binary_not_allowed for any binary frame, and
    mr.begin is refused (mr_not_enabled, or unknown_type from a 1.0 server)."""
    c = await controller(cfg)
    try:
        await c.send(upload_frame(1, 8, 8))
        r = await c.recv_json("error")
        assert r["code"] == "binary_not_allowed", r
        r = await c.request({"type": "mr.begin", "session": {"objects": ["x"], "width": 8, "height": 8,
                                                             "depth": "u16mm", "color": "rgb8_srgb"}})
        assert r["type"] == "error" and r["code"] in ("mr_not_enabled", "unknown_type"), r
        await c.ping_ok()
    finally:
        await c.close()


@section("8.1")
@aio
async def test_capability_granted_in_welcome(cfg):
    c = await mr_client(cfg)
    try:
        assert c.welcome.get("version") == "1.1", c.welcome
    finally:
        await c.close()


@section("8.2")
@aio
async def test_begin_validation(cfg):
    c = await mr_client(cfg)
    try:
        oid = await placed_object(c, cfg)
        base = {"objects": [oid], "width": 64, "height": 48, "depth": "u16mm", "color": "rgb8_srgb"}
        for field, value, code, pointer in [
                ("objects", [cfg.uid("nosuch")], "unknown_id", "/session/objects/0"),
                ("objects", [], "invalid", "/session/objects"),
                ("width", 4, "out_of_range", "/session/width"),
                ("height", 2000, "out_of_range", "/session/height"),
                ("depth", "u32mm", "invalid", "/session/depth"),
                ("color", "rgb", "invalid", "/session/color"),
                ("max_rate", 0, "out_of_range", "/session/max_rate"),
                ("smoothing", 1.0, "out_of_range", "/session/smoothing"),
                ("min_confidence", -0.1, "out_of_range", "/session/min_confidence"),
                ("specular_exponent", 0.5, "out_of_range", "/session/specular_exponent"),
                ("light", "mix", "invalid", "/session/light")]:
            s = dict(base)
            s[field] = value
            await c.expect_error({"type": "mr.begin", "session": s}, code, pointer)
        s = dict(base, objects=[oid] * 17)
        r = await c.request({"type": "mr.begin", "session": s})
        assert r["type"] == "error" and r["code"] in ("invalid", "limit_exceeded"), r
        await begin(c, oid)
        await c.expect_ok({"type": "mr.end"})
        await c.expect_ok({"type": "mr.end"})  # also without a session
    finally:
        await c.close()


def _set(offset, fmt, value, fix_crc=True):
    def patch(hdr, planes):
        struct.pack_into(fmt, hdr, offset, value)
        return hdr, planes, fix_crc
    return patch


def _after_sizes(offset, fmt, value):
    def patch(hdr, planes):
        return hdr, planes, True
    def after(hdr, planes):
        struct.pack_into(fmt, hdr, offset, value)
        return hdr, planes, True
    patch.after_sizes = after
    return patch


def _planes(fn):
    def patch(hdr, planes):
        return hdr, fn(list(planes)), True
    return patch


def _rotation_zero(hdr, planes):
    struct.pack_into("<4f", hdr, 64, 0, 0, 0, 0)
    return hdr, planes, True


BAD_FRAMES = [
    ("magic", _set(0, "<I", 0x3146434C), "/header/magic"),
    ("version", _set(4, "<H", 2), "/header/version"),
    ("kind", _set(6, "<B", 9), "/header/kind"),
    ("flags", _set(7, "<B", 0x80), "/header/flags"),
    ("header size", _set(8, "<H", 64), "/header/header_size"),
    ("width", _set(24, "<H", 32), "/header/width"),
    ("height", _set(26, "<H", 24), "/header/height"),
    ("depth encoding", _set(28, "<B", 2), "/header/depth_encoding"),
    ("colour encoding", _set(29, "<B", 1), "/header/color_encoding"),
    ("compression", _set(30, "<B", 7), "/header/depth_compression"),
    ("reserved", _set(33, "<B", 1), "/header/reserved"),
    ("fx zero", _set(36, "<f", 0.0), "/header/fx"),
    ("fy nan", _set(40, "<f", float("nan")), "/header/fy"),
    ("cx out of range", _set(44, "<f", 1e6), "/header/cx"),
    ("translation", _set(52, "<f", 1e7), "/header/translation"),
    ("rotation zero", _rotation_zero, "/header/rotation"),
    ("rotation inf", _set(76, "<f", float("inf")), "/header/rotation"),
    ("exposure", _set(80, "<f", 0.0), "/header/exposure"),
    ("crc", _set(124, "<I", 0, fix_crc=False), "/header/crc"),
    ("depth bytes", _after_sizes(84, "<I", 10), None),
    ("short plane", _planes(lambda p: [p[0][:-2], p[1], p[2]]), None),
]


@section("8.4")
@section("8.5")
@aio
async def test_bad_frames_named(cfg):
    """Each malformed header field gets frame_invalid naming it (no id), and the connection
    and the session stay: a good frame afterwards is processed."""
    c = await mr_client(cfg)
    try:
        oid = await placed_object(c, cfg)
        await begin(c, oid, w=64, h=48)
        seq = 0
        for name, patch, pointer in BAD_FRAMES:
            seq += 1
            await c.send(upload_frame(seq, 64, 48, patch=patch))
            r = await c.recv_json("error")
            assert r["code"] == "frame_invalid", "%s: %r" % (name, r)
            assert "id" not in r, r
            if pointer:
                assert r.get("pointer") == pointer, "%s: pointer %r, expected %r" % (name, r.get("pointer"), pointer)
            else:
                assert r.get("pointer", "").startswith("/"), "%s: %r" % (name, r)
        # a corrupt zlib plane
        seq += 1
        good = bytearray(upload_frame(seq, 64, 48, zlib_planes=True))
        good[128 + 4] ^= 0xFF
        struct.pack_into("<I", good, 124, zlib.crc32(bytes(good[:124]) + bytes(good[128:])))
        await c.send(bytes(good))
        r = await c.recv_json("error")
        assert r["code"] == "frame_invalid" and r.get("pointer", "").startswith("/depth"), r
        # a sequence that does not increase
        await c.send(upload_frame(seq + 1, 64, 48))
        a = await next_ack(c, seq + 1)
        assert a["status"] in ("processed", "replaced"), a
        await c.send(upload_frame(seq + 1, 64, 48))
        r = await c.recv_json("error")
        assert r["code"] == "frame_invalid" and r.get("pointer") == "/header/sequence", r
        await c.ping_ok()
    finally:
        await c.close()


@section("8.5")
@aio
async def test_frame_too_large_and_outside_session(cfg):
    c = await mr_client(cfg)
    try:
        oid = await placed_object(c, cfg)
        m = await begin(c, oid, w=64, h=48)
        await c.send(b"\0" * (m["max_frame"] + 1))
        r = await c.recv_json("error")
        assert r["code"] == "frame_too_large", r
        await c.ping_ok()
        await c.expect_ok({"type": "mr.end"})
        await c.send(upload_frame(1, 64, 48))
        r = await c.recv_json("error")
        assert r["code"] == "mr_not_enabled", r
        await c.ping_ok()
    finally:
        await c.close()


@section("8.5")
@aio
async def test_every_frame_acknowledged_once(cfg):
    """Frames sent back to back: each sequence is acknowledged exactly once, processed or
    replaced (latest wins), and the last one is processed."""
    c = await mr_client(cfg)
    try:
        oid = await placed_object(c, cfg)
        m = await begin(c, oid, w=128, h=96)
        for seq in range(1, 5):  # at the granted rate: a faster client is rate_limited
            await c.send(upload_frame(seq, 128, 96, zlib_planes=(seq % 2 == 0)))
            await asyncio.sleep(1.0 / m["max_rate"])
        acks = {}
        while len(acks) < 4:
            a = await c.recv_json("mr.ack", timeout=max(cfg.timeout, 60))
            assert a["seq"] not in acks, "§8.5 frame %d acknowledged twice" % a["seq"]
            assert a["capture_us"] == 1000 * a["seq"], a
            acks[a["seq"]] = a
        assert acks[4]["status"] == "processed", acks
        assert acks[4]["lights"] > 0, acks[4]
    finally:
        await c.close()


@section("8.5")
@aio
async def test_rate_limited(cfg):
    c = await mr_client(cfg)
    try:
        oid = await placed_object(c, cfg)
        await begin(c, oid, w=64, h=48, max_rate=0.1)
        for seq in range(1, 4):
            await c.send(upload_frame(seq, 64, 48))
        r = await c.recv_json("error", timeout=max(cfg.timeout, 30))
        assert r["code"] == "rate_limited", r
        await c.ping_ok()
    finally:
        await c.close()


def sh_irradiance(sh, n):
    """E(n) of 27 interleaved RGB irradiance SH values (§2.3), band 0..2, green channel."""
    x, y, z = n
    ys = [SH_Y00, SH_Y1 * y, SH_Y1 * z, SH_Y1 * x,
          1.092548 * x * y, 1.092548 * y * z, 0.315392 * (3 * z * z - 1), 1.092548 * x * z,
          0.546274 * (x * x - y * y)]
    return sum(sh[3 * i + 1] * ys[i] for i in range(9))


def rect_form_factor(hx, hy, d):
    """Point facing a parallel rectangle [-hx, hx] x [-hy, hy] at distance d, on its axis."""
    def corner(a, b):
        x, y = a / d, b / d
        return (x / math.sqrt(1 + x * x) * math.atan(y / math.sqrt(1 + x * x)) +
                y / math.sqrt(1 + y * y) * math.atan(x / math.sqrt(1 + y * y))) / (2 * math.pi)
    return 4 * corner(hx, hy)


@section("8.6")
@section("8.7")
@aio
async def test_capture_lights_object(cfg):
    """A uniformly radiant wall 1 m behind the object (the camera at the origin looking down −Z,
    the wall at 2 m): the object's SH on the objects stream faces the wall with irradiance
    ≈ π·L·F(centre → wall) and nothing from behind; the mr.vpl stream carries its points;
    after mr.end the object has its grid light again."""
    c = await mr_client(cfg)
    w, h = 128, 96
    f = 0.78 * w
    L = 0.5 * 100.0
    try:
        oid = await placed_object(c, cfg)
        m = await begin(c, oid, w=w, h=h)
        await subscribe_keyframe(c, "objects", "f32")
        await c.expect_ok({"type": "subscribe", "stream": "mr.vpl", "encoding": "f32"})
        await c.send(upload_frame(1, w, h, intrinsics=(f, f, w / 2, h / 2)))
        a = await next_ack(c, 1)
        assert a["status"] == "processed" and a["lights"] > 0, a
        want = math.pi * L * rect_form_factor(w / 2 / f * 2, h / 2 / f * 2, 1.0)
        got = None
        for _ in range(20):
            fr = await c.recv_frame("objects", timeout=max(cfg.timeout, 30))
            ids, vals = decode_sh(fr)
            if oid in ids:
                sh = vals[27 * ids.index(oid):27 * ids.index(oid) + 27]
                got = sh_irradiance(sh, (0, 0, -1))
                if abs(got - want) < 0.1 * want:
                    break
        assert got is not None and abs(got - want) < 0.1 * want, "E toward the wall %r, expected %.4g ±10%%" % (got, want)
        back = sh_irradiance(sh, (0, 0, 1))
        assert back < 0.1 * want, "irradiance from behind the object %.4g (the wall is in front)" % back
        v = await c.recv_frame("mr.vpl", timeout=max(cfg.timeout, 30))
        assert v.width >= 1 and v.height == m["points"], (v, m)
        await c.expect_ok({"type": "mr.end"})
        for _ in range(20):
            fr = await c.recv_frame("objects", timeout=max(cfg.timeout, 30))
            ids, vals = decode_sh(fr)
            if oid in ids and abs(sh_irradiance(vals[27 * ids.index(oid):27 * ids.index(oid) + 27], (0, 0, -1)) - got) > 0.05 * want:
                break
        else:
            raise AssertionError("§8.3 after mr.end the object's SH still shows the capture's light")
    finally:
        await c.close()
