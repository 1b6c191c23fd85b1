"""lucent/1 conformance suite: shared configuration, client and checks.

The server under test is named by environment variables (set by `lucent-conformance`, or
by hand when running pytest directly):

  LUCENT_CONF_URL               ws://host:port/ or wss://host:port/ (required)
  LUCENT_CONF_TOKEN             token of the default client (needs the controller role)
  LUCENT_CONF_CONTROLLER_TOKEN  a controller token (role cases; defaults to LUCENT_CONF_TOKEN)
  LUCENT_CONF_VIEWER_TOKEN      a viewer token (role cases are skipped without one)
  LUCENT_CONF_TIMEOUT           seconds to wait for any single reply or frame (default 10)
  LUCENT_CONF_INSECURE          1 = do not verify the TLS certificate (wss://)
  LUCENT_CONF_DELTA_THRESHOLD   the server's lightmap delta threshold (relative; default 0.01,
                                lucentd's --delta-threshold default): PROTOCOL.md §6.2 leaves it
                                to the server, the delta cases check deltas against it

Every JSON message a test receives is validated against protocol/schema/ (by its `type`)
and every binary frame is checked against §6.1 (header, lengths, CRC, tile table,
per-stream sequence and revision order) as it arrives, so each case also checks §5 and §6.1
for whatever traffic it produces.
"""
import asyncio
import base64
import functools
import json
import math
import os
import socket
import ssl
import struct
import uuid
import zlib
from collections import deque
from urllib.parse import urlparse

import jsonschema
import pytest
import websockets

HERE = os.path.dirname(os.path.abspath(__file__))
SCHEMA_DIR = os.environ.get("LUCENT_CONF_SCHEMA_DIR",
                            os.path.join(HERE, "..", "..", "protocol", "schema"))
SUBPROTOCOL = "lucent.v1"
MAGIC = 0x3146434C
STREAMS = {"lightmap": 1, "shgrid": 2, "objects": 3, "mr.vpl": 4}
STREAM_NAMES = {v: k for k, v in STREAMS.items()}
ENCODINGS = {"rgb9e5": 1, "rgba16f": 2, "f32": 3}
CHANGE_TYPES = ["light.set", "light.remove", "object.set", "object.remove", "material.set",
                "environment.set", "settings.set"]
SERVER_TYPES = ["welcome", "ok", "error", "changed", "state", "pong", "mr.ack", "object.transport"]


# --------------------------------------------------------------------------- configuration

class Config:
    def __init__(self):
        self.url = os.environ.get("LUCENT_CONF_URL", "")
        self.token = os.environ.get("LUCENT_CONF_TOKEN", "")
        self.controller_token = os.environ.get("LUCENT_CONF_CONTROLLER_TOKEN") or self.token
        self.viewer_token = os.environ.get("LUCENT_CONF_VIEWER_TOKEN", "")
        self.timeout = float(os.environ.get("LUCENT_CONF_TIMEOUT", "10"))
        self.insecure = os.environ.get("LUCENT_CONF_INSECURE", "") not in ("", "0")
        self.delta_threshold = float(os.environ.get("LUCENT_CONF_DELTA_THRESHOLD") or "0.01")
        u = urlparse(self.url)
        self.secure = u.scheme == "wss"
        self.host = u.hostname or "127.0.0.1"
        self.port = u.port or (443 if self.secure else 80)
        self.path = (u.path or "/") + (("?" + u.query) if u.query else "")
        self.run_id = uuid.uuid4().hex[:8]

    def ssl_context(self):
        if not self.secure:
            return None
        ctx = ssl.create_default_context()
        if self.insecure:
            ctx.check_hostname = False
            ctx.verify_mode = ssl.CERT_NONE
        return ctx

    def uid(self, what):
        """An id unlikely to clash with anything else on the server."""
        return "conf-%s-%s-%s" % (self.run_id, what, uuid.uuid4().hex[:6])


CFG = Config()


def pytest_configure(config):
    config.addinivalue_line("markers", "section(s): the PROTOCOL.md section a case checks")
    if not CFG.url:
        raise pytest.UsageError("LUCENT_CONF_URL is not set (use lucent-conformance URL)")


@pytest.fixture
def cfg():
    return CFG


def aio(fn):
    """Run an async test function to completion (no pytest-asyncio on Debian 12)."""
    @functools.wraps(fn)
    def wrapper(*a, **kw):
        asyncio.run(fn(*a, **kw))
    return wrapper


def scene_asset(w):
    """The first asset of welcome.scene.assets (the case skips when the scene has none)."""
    if not w["scene"]["assets"]:
        pytest.skip("the scene has no assets (welcome.scene.assets is empty)")
    return w["scene"]["assets"][0]


# --------------------------------------------------------------------------- schemas

def _load_schemas():
    store, by_name = {}, {}
    for name in sorted(os.listdir(SCHEMA_DIR)):
        if name.endswith(".json"):
            with open(os.path.join(SCHEMA_DIR, name)) as fh:
                s = json.load(fh)
            store[s["$id"]] = s
            by_name[name[:-5]] = s
    validators = {}
    for name, s in by_name.items():
        # jsonschema 4.10: RefResolver with a store keyed by $id, so relative $refs
        # ("defs.json#/...") resolve against the schema's own $id, never over the network.
        resolver = jsonschema.RefResolver(base_uri=s["$id"], referrer=s, store=store)
        cls = jsonschema.validators.validator_for(s)
        cls.check_schema(s)
        validators[name] = cls(s, resolver=resolver)
    return validators


VALIDATORS = _load_schemas()


def schema_errors(msg):
    """Validation errors of a server message against the schema named by its type."""
    t = msg.get("type") if isinstance(msg, dict) else None
    if t not in SERVER_TYPES:
        return ["server message with unknown type %r: %r" % (t, msg)]
    return ["%s: %s at %s" % (t, e.message, "/" + "/".join(str(p) for p in e.absolute_path))
            for e in VALIDATORS[t].iter_errors(msg)]


# --------------------------------------------------------------------------- frames

HEADER = struct.Struct("<IHBBHHIQQQIIIIII")


class Frame:
    def __init__(self, data):
        self.raw = data
        if len(data) < 64:
            raise AssertionError("§6.1: binary frame of %d bytes is shorter than the 64-byte header" % len(data))
        (self.magic, self.version, self.stream, self.encoding, self.flags_raw, self.header_size, self.tiles,
         self.revision, self.sequence, self.timestamp, self.width, self.height, self.depth, self.tile,
         self.payload_len, self.crc) = HEADER.unpack_from(data, 0)
        # §6.1: bits 0-2 the frame kind, bit 3 converged, bits 4-7 reserved, bits 8-15 the pass
        self.flags = self.flags_raw & 7
        self.converged = bool(self.flags_raw & 8)
        self.refine_pass = self.flags_raw >> 8

    @property
    def keyframe(self):
        return self.flags == 1

    @property
    def delta(self):
        """A plain delta (§6.2): the listed tiles' texels as they are."""
        return self.flags == 2

    @property
    def residual(self):
        """A residual delta (§6.2.1, lightmap only): delta + residual bits, compressed payload."""
        return self.flags == 6

    def tile_table(self):
        return struct.unpack_from("<%dI" % self.tiles, self.raw, 64)

    def payload(self):
        off = 64 + 4 * self.tiles
        return self.raw[off:off + self.payload_len]

    def __repr__(self):
        return ("Frame(stream=%d enc=%d flags=%d tiles=%d rev=%d seq=%d %dx%dx%d tile=%d payload=%d len=%d)" %
                (self.stream, self.encoding, self.flags, self.tiles, self.revision, self.sequence, self.width,
                 self.height, self.depth, self.tile, self.payload_len, len(self.raw)))


def texel_bytes(stream, encoding):
    if stream == 1:
        return {1: 4, 2: 8, 3: 12}[encoding]
    return 27 * {2: 2, 3: 4}[encoding]


def _inflate(data):
    """(inflated bytes, problem or None) of one zlib stream (RFC 1950) that must fill `data` exactly."""
    d = zlib.decompressobj()
    try:
        out = d.decompress(data)
    except zlib.error as e:
        return None, "not a zlib stream (%s)" % e
    if not d.eof:
        return out, "the zlib stream is truncated (no end after %d bytes, %d inflated)" % (len(data), len(out))
    if d.unused_data:
        return out, "%d bytes after the end of the zlib stream" % len(d.unused_data)
    return out, None


def _residual_stream_problems(payload, expect):
    """§6.2.1: the payload of a residual delta is one zlib stream inflating to exactly `expect` bytes."""
    out, err = _inflate(payload)
    if err:
        return ["residual delta payload: %s" % err]
    if len(out) != expect:
        return ["residual delta inflates to %d bytes != texels of the listed tiles * texel size = %d" %
                (len(out), expect)]
    return []


def _vpl_problems(f, per):
    """§8.7: width objects, height points in all, each object 64 B id + u32 count + u32 0."""
    pl, o, points, p = f.payload(), 0, 0, []
    if f.depth != 1:
        p.append("mr.vpl frame depth %d (must be 1)" % f.depth)
    for i in range(f.width):
        if o + 72 > len(pl):
            return p + ["mr.vpl payload ends inside object %d's header" % i]
        n, zero = struct.unpack_from("<II", pl, o + 64)
        if zero:
            p.append("mr.vpl object %d: reserved word %d (must be 0)" % (i, zero))
        o += 72 + n * 12 * per
        points += n
    if o != len(pl):
        p.append("mr.vpl payload %d != the objects' records (%d)" % (len(pl), o))
    if points != f.height:
        p.append("mr.vpl header height %d != points in the payload %d" % (f.height, points))
    return p


def frame_problems(f):
    """§6.1-§6.4 consistency of one frame taken on its own."""
    p = []
    if f.magic != MAGIC:
        p.append("magic 0x%08x != 0x%08x" % (f.magic, MAGIC))
    if f.version != 1:
        p.append("version %d != 1" % f.version)
    if f.header_size != 64:
        p.append("header size %d != 64" % f.header_size)
    if f.flags_raw & 0xF0:
        p.append("flags 0x%x: bits 4-7 are reserved and must be 0 (§6.1)" % f.flags_raw)
    if f.flags == 6:
        if f.stream != 1:
            p.append("flags 0x6 (residual delta) on a %s frame: residual deltas are lightmap only (§6.2.1)" %
                     STREAM_NAMES.get(f.stream, "stream %d" % f.stream))
    elif f.flags not in (1, 2):
        p.append("flags 0x%x: exactly one of keyframe/delta must be set (and no other bits; bit 2 residual only "
                 "with delta, §6.2.1)" % f.flags)
    if f.stream not in (1, 2, 3, 4):
        p.append("stream %d unknown" % f.stream)
        return p
    if f.encoding not in (1, 2, 3) or (f.stream != 1 and f.encoding == 1):
        p.append("encoding %d not valid for stream %d" % (f.encoding, f.stream))
        return p
    if 64 + 4 * f.tiles + f.payload_len != len(f.raw):
        p.append("64 + 4*tiles(%d) + payload(%d) != frame length %d" % (f.tiles, f.payload_len, len(f.raw)))
        return p
    if zlib.crc32(f.raw[:60] + f.raw[64:]) != f.crc:
        p.append("CRC-32 mismatch (header says 0x%08x, computed 0x%08x)" % (f.crc, zlib.crc32(f.raw[:60] + f.raw[64:])))
    bpt = texel_bytes(f.stream, f.encoding)
    if f.keyframe and f.tiles != 0:
        p.append("keyframe with tile count %d (must be 0)" % f.tiles)
    if f.stream == 1:
        if f.depth != 1 or f.tile == 0:
            p.append("lightmap frame: depth %d (must be 1), tile size %d (must be > 0)" % (f.depth, f.tile))
            return p
        if f.keyframe and f.payload_len != f.width * f.height * bpt:
            p.append("lightmap keyframe payload %d != W*H*%d = %d" % (f.payload_len, bpt, f.width * f.height * bpt))
        if f.delta or f.residual:
            tw, th = -(-f.width // f.tile), -(-f.height // f.tile)
            table = f.tile_table()
            if any(b <= a for a, b in zip(table, table[1:])):
                p.append("delta tile table not strictly ascending: %r" % (table[:20],))
            if f.residual and not table:
                p.append("residual delta with no tiles (§6.2.1: a delta with no tiles is a plain delta)")
            if any(t >= tw * th for t in table):
                p.append("delta tile index out of bounds (%d tiles): %r" % (tw * th, max(table)))
            else:
                texels = 0
                for t in table:
                    x0, y0 = (t % tw) * f.tile, (t // tw) * f.tile
                    texels += (min(x0 + f.tile, f.width) - x0) * (min(y0 + f.tile, f.height) - y0)
                if f.residual:
                    p.extend(_residual_stream_problems(f.payload(), texels * bpt))
                elif texels * bpt != f.payload_len:
                    p.append("delta payload %d != %d texels of the listed tiles * %d" % (f.payload_len, texels, bpt))
    else:
        if f.delta:
            p.append("%s frames are keyframes only (§6.3/§6.4), got a delta" % STREAM_NAMES[f.stream])
        if f.tile != 0:
            p.append("%s frame with tile size %d (must be 0)" % (STREAM_NAMES[f.stream], f.tile))
        if f.stream == 4:
            p.extend(_vpl_problems(f, bpt // 27))
        elif f.stream == 2:
            if f.payload_len != f.width * f.height * f.depth * bpt:
                p.append("shgrid payload %d != x*y*z*27*%d" % (f.payload_len, bpt // 27))
        else:
            if f.height != 1 or f.depth != 1:
                p.append("objects frame height %d depth %d (both must be 1)" % (f.height, f.depth))
            if f.payload_len != f.width * (64 + bpt):
                p.append("objects payload %d != count(%d) * (64 + 27*%d)" % (f.payload_len, f.width, bpt // 27))
    return p


# --------------------------------------------------------------------------- decoding

def decode_rgb9e5(u):
    m = u & 0x1FF, (u >> 9) & 0x1FF, (u >> 18) & 0x1FF
    e = (u >> 27) - 15 - 9
    return tuple(math.ldexp(c, e) for c in m)


def decode_lightmap(f):
    """Texels of a lightmap frame's payload as a flat list of RGB floats (3 per texel)."""
    pl = f.payload()
    n = len(pl) // texel_bytes(1, f.encoding)
    if f.encoding == 1:
        out = []
        for u in struct.unpack("<%dI" % n, pl):
            out.extend(decode_rgb9e5(u))
        return out
    if f.encoding == 2:
        v = struct.unpack("<%de" % (4 * n), pl)
        return [x for i in range(n) for x in v[4 * i:4 * i + 3]], v[3::4]
    return list(struct.unpack("<%df" % (3 * n), pl))


def decode_sh(f):
    pl = f.payload()
    if f.stream == 3:
        vals, ids = [], []
        rec = 64 + 27 * (4 if f.encoding == 3 else 2)
        for i in range(f.width):
            r = pl[i * rec:(i + 1) * rec]
            ids.append(r[:64].rstrip(b"\0").decode("utf-8"))
            vals.extend(struct.unpack("<27" + ("f" if f.encoding == 3 else "e"), r[64:]))
        return ids, vals
    fmt = "f" if f.encoding == 3 else "e"
    return None, list(struct.unpack("<%d%s" % (len(pl) // struct.calcsize(fmt), fmt), pl))


def apply_delta(img, f):
    """Apply a lightmap delta frame onto `img` (flat RGB list) in place."""
    assert not f.residual, "apply_delta: %r is a residual delta (§6.2.1): use apply_delta_encoded" % f
    vals = decode_lightmap(f)
    if f.encoding == 2:
        vals = vals[0]
    tw = -(-f.width // f.tile)
    k = 0
    for t in f.tile_table():
        x0, y0 = (t % tw) * f.tile, (t // tw) * f.tile
        for y in range(y0, min(y0 + f.tile, f.height)):
            for x in range(x0, min(x0 + f.tile, f.width)):
                i = 3 * (y * f.width + x)
                img[i:i + 3] = vals[k:k + 3]
                k += 3


# --------------------------------------------------------------------------- encoded copies (§6.2.1)

# Per lightmap encoding: the wire word (struct code), and the (bit offset, width) of the fields a
# residual adds to, inside each word (§6.2.1).
RESIDUAL_FIELDS = {
    1: ("I", ((0, 9), (9, 9), (18, 9), (27, 5))),  # rgb9e5: 3 mantissas, shared exponent
    2: ("H", ((0, 16),)),                          # rgba16f: each binary16
    3: ("I", ((0, 32),)),                          # f32: each float's bit pattern
}


def unzigzag(r, width):
    """§6.2.1 unzigzag on a `width`-bit field: (r >> 1) XOR -(r AND 1), modulo 2^width."""
    mask = (1 << width) - 1
    return (r >> 1) ^ (mask if r & 1 else 0)


def residual_add(word, res, fields):
    """One encoded word plus its residual word, field by field modulo the field width."""
    v = 0
    for off, w in fields:
        mask = (1 << w) - 1
        v |= ((((word >> off) & mask) + unzigzag((res >> off) & mask, w)) & mask) << off
    return v


def tile_texels(f):
    """Texel indices (y * W + x) of a lightmap delta's tiles, in payload order (§6.2)."""
    tw = -(-f.width // f.tile)
    for t in f.tile_table():
        x0, y0 = (t % tw) * f.tile, (t // tw) * f.tile
        for y in range(y0, min(y0 + f.tile, f.height)):
            for x in range(x0, min(x0 + f.tile, f.width)):
                yield y * f.width + x


def residual_bytes(f):
    """The inflated payload of a residual delta (§6.2.1); AssertionError if it is not one
    complete zlib stream of exactly (texels of the tiles) x texel size bytes."""
    expect = sum(1 for _ in tile_texels(f)) * texel_bytes(1, f.encoding)
    out, err = _inflate(f.payload())
    assert err is None and len(out) == expect, "§6.2.1 residual payload of %r: %s" % (
        f, err or "inflates to %d bytes, expected %d" % (len(out), expect))
    return out


def apply_delta_encoded(copy, f):
    """Apply a lightmap delta frame to `copy`, a bytearray of the ENCODED texels (a keyframe's
    payload, W*H texels row-major, as received), in place. A plain delta (§6.2) overwrites the
    listed tiles' texels with its payload; a residual delta (§6.2.1) adds its inflated residuals
    field by field. Returns the number of texels whose encoded value changed."""
    assert f.stream == 1 and (f.delta or f.residual), "apply_delta_encoded: not a lightmap delta: %r" % f
    tb = texel_bytes(1, f.encoding)
    assert len(copy) == f.width * f.height * tb, "copy of %d bytes for a %dx%d %d-byte lightmap" % (
        len(copy), f.width, f.height, tb)
    changed = 0
    if f.delta:
        pl = f.payload()
        for k, i in enumerate(tile_texels(f)):
            new = pl[k * tb:(k + 1) * tb]
            if copy[i * tb:(i + 1) * tb] != new:
                changed += 1
                copy[i * tb:(i + 1) * tb] = new
        return changed
    code, fields = RESIDUAL_FIELDS[f.encoding]
    per = tb // struct.calcsize(code)  # words per texel
    raw = residual_bytes(f)
    res = struct.unpack("<%d%s" % (len(raw) // struct.calcsize(code), code), raw)
    words = list(struct.unpack("<%d%s" % (len(copy) // struct.calcsize(code), code), copy))
    for k, i in enumerate(tile_texels(f)):
        moved = False
        for j in range(per):
            r = res[k * per + j]
            if r:
                words[i * per + j] = residual_add(words[i * per + j], r, fields)
                moved = True
        changed += moved
    copy[:] = struct.pack("<%d%s" % (len(words), code), *words)
    return changed


def decode_encoded(encoding, data):
    """Encoded lightmap texels (bytes as on the wire) as a flat list of RGB floats (3 per texel;
    rgba16f's alpha dropped)."""
    n = len(data) // texel_bytes(1, encoding)
    if encoding == 1:
        out = []
        for u in struct.unpack("<%dI" % n, data):
            out.extend(decode_rgb9e5(u))
        return out
    if encoding == 2:
        v = struct.unpack("<%de" % (4 * n), data)
        return [x for i in range(n) for x in v[4 * i:4 * i + 3]]
    return list(struct.unpack("<%df" % (3 * n), data))


# --------------------------------------------------------------------------- client

class ProtocolViolation(AssertionError):
    pass


class RecvTimeout(AssertionError):
    """Nothing (of the kind wanted) arrived in time."""


class Client:
    """A lucent/1 client that checks everything it receives."""

    def __init__(self, ws, cfg, name):
        self.ws = ws
        self.cfg = cfg
        self.name = name
        self.json_q = deque()
        self.frame_q = deque()
        self.seq = {}
        self.rev = {}
        self.welcome = None
        self.frames_seen = 0
        self.next_id = 100

    async def _recv(self, timeout):
        m = await asyncio.wait_for(self.ws.recv(), timeout)
        if isinstance(m, bytes):
            f = Frame(m)
            p = frame_problems(f)
            if p:
                raise ProtocolViolation("§6.1 frame %r: %s" % (f, "; ".join(p)))
            if f.sequence != self.seq.get(f.stream, 0) + 1:
                raise ProtocolViolation("§6.1/§6.5 %s sequence %d after %d (must increase by one per stream)" %
                                        (STREAM_NAMES[f.stream], f.sequence, self.seq.get(f.stream, 0)))
            if f.revision < self.rev.get(f.stream, 0):
                raise ProtocolViolation("§6.5 %s revision %d after %d (must never decrease)" %
                                        (STREAM_NAMES[f.stream], f.revision, self.rev.get(f.stream, 0)))
            self.seq[f.stream] = f.sequence
            self.rev[f.stream] = f.revision
            self.frames_seen += 1
            self.frame_q.append(f)
        else:
            try:
                msg = json.loads(m)
            except ValueError:
                raise ProtocolViolation("§1.2 server text frame is not JSON: %r" % m[:200])
            errs = schema_errors(msg)
            if errs:
                raise ProtocolViolation("§5 schema: %s" % "; ".join(errs))
            self.json_q.append(msg)

    async def recv_json(self, want=None, timeout=None, pred=None):
        """Next JSON message (of type `want` / matching `pred`); others of other types are dropped."""
        timeout = self.cfg.timeout if timeout is None else timeout
        loop = asyncio.get_running_loop()
        end = loop.time() + timeout
        while True:
            while self.json_q:
                msg = self.json_q.popleft()
                if (want is None or msg.get("type") == want) and (pred is None or pred(msg)):
                    return msg
            left = end - loop.time()
            if left <= 0:
                raise RecvTimeout("no %s message%s within %.1f s" % (want or "JSON", " matching" if pred else "",
                                                                       timeout))
            try:
                await self._recv(left)
            except asyncio.TimeoutError:
                pass

    async def recv_frame(self, stream=None, min_revision=0, timeout=None, keyframe=None):
        timeout = self.cfg.timeout if timeout is None else timeout
        loop = asyncio.get_running_loop()
        end = loop.time() + timeout
        while True:
            while self.frame_q:
                f = self.frame_q.popleft()
                if ((stream is None or f.stream == STREAMS[stream]) and f.revision >= min_revision and
                        (keyframe is None or f.keyframe == keyframe)):
                    return f
            left = end - loop.time()
            if left <= 0:
                raise RecvTimeout("no %s%s frame of revision >= %d within %.1f s" % (
                    {True: "key", False: "delta ", None: ""}[keyframe], stream or "", min_revision, timeout))
            try:
                await self._recv(left)
            except asyncio.TimeoutError:
                pass

    async def pump(self, seconds):
        """Receive (and check) everything for `seconds`; returns the frames received."""
        loop = asyncio.get_running_loop()
        end = loop.time() + seconds
        got = []
        while True:
            left = end - loop.time()
            if left <= 0:
                break
            try:
                await self._recv(left)
            except asyncio.TimeoutError:
                break
            while self.frame_q:
                got.append(self.frame_q.popleft())
        return got

    async def send(self, msg):
        await self.ws.send(msg if isinstance(msg, (str, bytes)) else json.dumps(msg))

    async def request(self, msg, timeout=None):
        """Send a request with a fresh id and return the reply echoing that id."""
        if isinstance(msg, dict) and "id" not in msg:
            self.next_id += 1
            msg = dict(msg, id=self.next_id)
        rid = msg["id"]
        await self.send(msg)
        reply = await self.recv_json(timeout=timeout, pred=lambda m: m.get("type") in ("ok", "error", "state", "pong")
                                     and m.get("id") == rid)
        return reply

    async def expect_ok(self, msg, timeout=None):
        r = await self.request(msg, timeout)
        assert r["type"] == "ok", "expected ok for %s, got %r" % (json.dumps(msg)[:200], r)
        return r

    async def expect_error(self, msg, code, pointer=None, timeout=None):
        if isinstance(msg, dict):
            r = await self.request(msg, timeout)
        else:  # raw text: the reply may not echo an id
            await self.send(msg)
            r = await self.recv_json(timeout=timeout, pred=lambda m: m.get("type") in ("ok", "error", "state", "pong"))
        assert r["type"] == "error", "expected error %s for %s, got %r" % (code, str(msg)[:200], r)
        assert r["code"] == code, "expected error code %s for %s, got %r" % (code, str(msg)[:200], r)
        if pointer is not None:
            ok = r["pointer"] in pointer if isinstance(pointer, (list, tuple)) else r["pointer"] == pointer
            assert ok, "error pointer %r for %s, expected %r" % (r["pointer"], str(msg)[:200], pointer)
        return r

    async def ping_ok(self, t=12.5):
        """The connection is still usable: ping -> pong with the same t."""
        r = await self.request({"type": "ping", "t": t})
        assert r["type"] == "pong" and r["t"] == t, "ping after the error: %r" % r
        return r

    async def revision(self):
        st = await self.request({"type": "state.get"})
        assert st["type"] == "state", st
        return st["revision"]

    async def close(self):
        try:
            await asyncio.wait_for(self.ws.close(), 5)
        except Exception:
            pass

    async def wait_closed(self, timeout=None):
        """Read until the server closes; returns (close code, messages received before)."""
        timeout = self.cfg.timeout if timeout is None else timeout
        loop = asyncio.get_running_loop()
        end = loop.time() + timeout
        before = []
        try:
            while True:
                left = end - loop.time()
                if left <= 0:
                    raise AssertionError("the server did not close the connection within %.0f s" % timeout)
                await self._recv(left)
                before.extend(self.json_q)
                self.json_q.clear()
        except websockets.exceptions.ConnectionClosed as c:
            return (c.rcvd.code if c.rcvd else None), before
        except asyncio.TimeoutError:
            raise AssertionError("the server did not close the connection within %.0f s" % timeout)


async def connect(cfg, subprotocols=(SUBPROTOCOL,), **kw):
    ws = await asyncio.wait_for(websockets.connect(
        cfg.url, subprotocols=list(subprotocols) if subprotocols is not None else None,
        ssl=cfg.ssl_context(), max_size=None, ping_interval=None, compression=None, **kw), cfg.timeout)
    return ws


async def open_client(cfg, token=None, name="lucent-conformance", hello_extra=None):
    """Connect, hello, and check the welcome. Returns a Client."""
    ws = await connect(cfg)
    c = Client(ws, cfg, name)
    hello = {"type": "hello", "id": 1, "client": name, "token": cfg.token if token is None else token}
    hello.update(hello_extra or {})
    await c.send(hello)
    w = await c.recv_json()
    assert w["type"] == "welcome", "hello -> %r (token %r)" % (w, hello["token"])
    assert w.get("id") == 1, "§2.5 the welcome must echo the hello id: %r" % w.get("id")
    c.welcome = w
    return c


async def controller(cfg, name="lucent-conformance"):
    c = await open_client(cfg, name=name)
    if c.welcome["role"] != "controller":
        await c.close()
        pytest.skip("the default token (--token) does not give the controller role")
    return c


# --------------------------------------------------------------------------- raw socket

class RawWS:
    """A minimal blocking RFC 6455 client over a plain (or TLS) socket: for frames that
    websockets will not send, and for clients that never read."""

    def __init__(self, cfg, rcvbuf=None, subprotocol=SUBPROTOCOL):
        s = socket.socket(socket.AF_INET6 if ":" in cfg.host else socket.AF_INET)
        if rcvbuf:
            s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, rcvbuf)
        s.settimeout(cfg.timeout)
        s.connect((cfg.host, cfg.port))
        if cfg.secure:
            s = cfg.ssl_context().wrap_socket(s, server_hostname=cfg.host)
        self.sock = s
        key = base64.b64encode(os.urandom(16)).decode()
        req = ("GET %s HTTP/1.1\r\nHost: %s:%d\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
               "Sec-WebSocket-Key: %s\r\nSec-WebSocket-Version: 13\r\n" % (cfg.path, cfg.host, cfg.port, key))
        if subprotocol:
            req += "Sec-WebSocket-Protocol: %s\r\n" % subprotocol
        s.sendall((req + "\r\n").encode())
        resp = b""
        while b"\r\n\r\n" not in resp:
            ch = s.recv(1)
            if not ch:
                break
            resp += ch
        self.status_line = resp.split(b"\r\n")[0].decode("latin-1")
        self.buf = b""

    @property
    def upgraded(self):
        return " 101 " in self.status_line + " "

    def send_frame(self, opcode, data, fin=True):
        mask = os.urandom(4)
        n = len(data)
        b0 = (0x80 if fin else 0) | opcode
        if n < 126:
            hdr = bytes([b0, 0x80 | n])
        elif n < 65536:
            hdr = bytes([b0, 0xFE]) + struct.pack(">H", n)
        else:
            hdr = bytes([b0, 0xFF]) + struct.pack(">Q", n)
        self.sock.sendall(hdr + mask + bytes(b ^ mask[i % 4] for i, b in enumerate(data)))

    def send_text(self, data):
        self.send_frame(0x1, data if isinstance(data, bytes) else json.dumps(data).encode())

    def _need(self, n):
        while len(self.buf) < n:
            ch = self.sock.recv(65536)
            if not ch:
                raise EOFError("connection closed")
            self.buf += ch

    def recv_frame(self):
        """(opcode, payload) of the next frame (no fragmentation support needed for lucent/1 replies)."""
        self._need(2)
        b0, b1 = self.buf[0], self.buf[1]
        n, off = b1 & 0x7F, 2
        if n == 126:
            self._need(4)
            n, off = struct.unpack(">H", self.buf[2:4])[0], 4
        elif n == 127:
            self._need(10)
            n, off = struct.unpack(">Q", self.buf[2:10])[0], 10
        self._need(off + n)
        data = self.buf[off:off + n]
        self.buf = self.buf[off + n:]
        return b0 & 0x0F, data

    def close(self):
        try:
            self.sock.close()
        except OSError:
            pass


# --------------------------------------------------------------------------- helpers

async def nudge(cfg, c=None):
    """A harmless accepted change (a zero-intensity light): makes the server publish a frame."""
    own = c is None
    if own:
        c = await controller(cfg, name="nudger")
    try:
        return await c.expect_ok({"type": "light.set", "light": {
            "id": "conf-%s-nudge" % cfg.run_id, "type": "point", "position": [0, 0, 0], "intensity": 0}})
    finally:
        if own:
            await c.close()


async def subscribe_keyframe(c, stream, encoding=None, grace=3.0, extra=None):
    """subscribe and return the keyframe that must follow (§4.1). If none comes within
    `grace` s, nudge the server with a change (so the case can go on checking what it is
    about; test_semantics.test_subscribe_keyframe_idle checks the keyframe on its own).
    `extra`: more subscribe members (e.g. {"delta": "residual"})."""
    msg = {"type": "subscribe", "stream": stream}
    if encoding:
        msg["encoding"] = encoding
    msg.update(extra or {})
    await c.expect_ok(msg)
    try:
        return await c.recv_frame(stream, keyframe=True, timeout=grace)
    except RecvTimeout:
        await nudge(c.cfg)
        return await c.recv_frame(stream, keyframe=True)
