"""Shared helpers for lucent's Python tests and benchmarks (tests/integration/*.py,
tests/bench/*.py, the Python snippets of the shell tests). The conformance suite
(tests/conformance/) is standalone and keeps its own copies on purpose.

    import os, sys
    sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "lib"))
    import lucent_testlib as lt

What is here:
  frames     HEADER, MAGIC, parse_frame(data) -> dict (fields + crc_ok, length_ok),
             frame_crc(data), frame_ok(data)
  lucentd    start_lucentd(state_dir, *args, bake=..., env=...) -> (process, port);
             stop(p); the process's stderr is in p.log (a DaemonLog on STATE_DIR.err)
  waiting    wait_for(cond, timeout, what) / async_wait_for(...): poll until cond() is
             truthy, else raise WaitTimeout naming what was awaited
  HTTP       http_get(port, path), metrics(port), metric(port, name), healthz(port),
             wait_metric(port, name, pred, timeout), reload(p, port) (SIGHUP, then waits
             for lucent_config_reloads_total to count it)
  WebSocket  RawWS (minimal blocking RFC 6455 client: exact control of what is sent and
             read), recv_json(ws, want, timeout) for a `websockets` connection
  MR         upload_frame(seq, w, h, ...): an LCU1 upload frame (PROTOCOL.md §8.4) of a wall

Only the standard library is needed (python3-websockets only by callers using it)."""
import base64
import json
import os
import re
import signal
import socket
import struct
import subprocess
import threading
import time
import urllib.error
import urllib.request
import zlib

# --------------------------------------------------------------------------- paths

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
BINARY_DIR = os.environ.get("LUCENT_BINARY_DIR") or os.path.join(REPO, "build")
SOURCE_DIR = os.environ.get("LUCENT_SOURCE_DIR") or REPO
LUCENTD = os.path.join(BINARY_DIR, "bin", "lucentd")
LUCENTCTL = os.path.join(BINARY_DIR, "bin", "lucentctl")
LUCENT_BAKE = os.environ.get("LUCENT_BAKE") or os.path.join(BINARY_DIR, "bin", "lucent-bake")
CORNELL_LCB = os.path.join(BINARY_DIR, "cornell.lcb")  # the build's embedded Cornell bake

# --------------------------------------------------------------------------- frames (PROTOCOL.md §6.1)

HEADER = struct.Struct("<IHBBHHIQQQIIIIII")
HEADER_SIZE = 64
MAGIC = 0x3146434C  # "LCF1"
STREAMS = {1: "lightmap", 2: "shgrid", 3: "objects"}
FLAG_KEYFRAME, FLAG_DELTA, FLAG_RESIDUAL = 1, 2, 4


def frame_crc(data):
    """The CRC-32 a frame's header must carry: header bytes 0..59, then everything after the header."""
    mv = memoryview(data)
    return zlib.crc32(mv[HEADER_SIZE:], zlib.crc32(mv[:60]))


def parse_frame(data):
    """The 64-byte header of a binary frame as a dict (PROTOCOL.md §6.1 names), plus crc_ok and
    length_ok (the message is exactly header + tile table + payload). `flags` is the frame
    kind (bits 0-2); `converged` (bit 3) and `pass` (bits 8-15) come apart, `flags_raw` whole.
    Raises ValueError when the message is shorter than a header."""
    if len(data) < HEADER_SIZE:
        raise ValueError("binary message of %d bytes is shorter than a frame header" % len(data))
    (magic, ver, stream, enc, flags, hsize, tiles, rev, seq, ts, w, h, d, tile, plen,
     crc) = HEADER.unpack_from(data, 0)
    return dict(magic=magic, version=ver, stream=stream, encoding=enc, flags=flags & 7, flags_raw=flags,
                converged=bool(flags & 8), refine_pass=flags >> 8, header_size=hsize, tiles=tiles,
                revision=rev, sequence=seq, timestamp_us=ts, width=w, height=h, depth=d, tile=tile, payload=plen,
                crc=crc, crc_ok=frame_crc(data) == crc, length_ok=len(data) == HEADER_SIZE + 4 * tiles + plen)


def frame_payload(data):
    """The payload bytes of a frame (after the header and the tile table)."""
    f = parse_frame(data)
    start = HEADER_SIZE + 4 * f["tiles"]
    return bytes(data[start:start + f["payload"]])


def frame_ok(data):
    """True when the message is a well-formed frame: magic, version, header size, length, CRC."""
    try:
        f = parse_frame(data)
    except ValueError:
        return False
    return (f["magic"] == MAGIC and f["version"] == 1 and f["header_size"] == HEADER_SIZE and f["length_ok"]
            and f["crc_ok"])

# --------------------------------------------------------------------------- waiting


class WaitTimeout(AssertionError):
    """What a test waited for did not happen in time (the message says what and how long)."""


def _describe(what):
    return what() if callable(what) else what


def wait_for(cond, timeout=10.0, what="the condition", interval=0.02):
    """Calls cond() until it returns something truthy and returns that. After `timeout` s raises
    WaitTimeout("<what> did not happen within T s"); `what` may be a callable (evaluated then,
    e.g. to quote a log)."""
    end = time.monotonic() + timeout
    while True:
        v = cond()
        if v:
            return v
        if time.monotonic() >= end:
            raise WaitTimeout("%s did not happen within %.1f s" % (_describe(what), timeout))
        time.sleep(interval)


async def async_wait_for(cond, timeout=10.0, what="the condition", interval=0.02):
    """wait_for for asyncio code: cond() runs in an executor thread when it blocks (HTTP)."""
    import asyncio
    loop = asyncio.get_running_loop()
    end = loop.time() + timeout
    while True:
        v = await loop.run_in_executor(None, cond)
        if v:
            return v
        if loop.time() >= end:
            raise WaitTimeout("%s did not happen within %.1f s" % (_describe(what), timeout))
        await asyncio.sleep(interval)

# --------------------------------------------------------------------------- lucentd


class DaemonLog:
    """lucentd's stderr (one line per event), written to a file; read back on demand."""

    def __init__(self, path):
        self.path = path

    def text(self):
        try:
            with open(self.path, errors="replace") as fh:
                return fh.read()
        except FileNotFoundError:
            return ""

    def lines(self):
        return self.text().splitlines()

    def find(self, *parts):
        """The first line containing every one of `parts`, or None."""
        return next((l for l in self.lines() if all(p in l for p in parts)), None)

    def count(self, *parts):
        return sum(1 for l in self.lines() if all(p in l for p in parts))

    def tail(self, n=600):
        return self.text()[-n:]

    def wait(self, *parts, timeout=10.0):
        """The first line containing every one of `parts`; WaitTimeout after `timeout` s."""
        return wait_for(lambda: self.find(*parts), timeout,
                        lambda: "a lucentd log line with %r (log: %r)" % (parts, self.tail(400)))


class LucentdStartError(AssertionError):
    pass


_DEFAULT = object()
_LISTENING = re.compile(r"^lucentd listening port=(\d+)")


def start_lucentd(state_dir, *args, bake=_DEFAULT, env=None, lucentd=None, backend="cpu", log_level="warn",
                  preexec=None, wrapper=(), timeout=30.0):
    """Starts lucentd on a free port (--port 0) with its state in `state_dir` and waits for its
    `lucentd listening port=N` line. Returns (process, port).

    bake: the build's Cornell bake by default; a path; None for no --bake (lucentd's own
    default). env: variables added to this environment. wrapper: argv put before lucentd
    (valgrind, a shim). The daemon's stderr goes to STATE_DIR.err, readable as p.log (a
    DaemonLog); its stdout is drained on a thread. Raises LucentdStartError (with the log's
    tail) when it exits or says nothing within `timeout` s."""
    cmd = [*wrapper, lucentd or LUCENTD]
    if bake is _DEFAULT:
        bake = CORNELL_LCB
    if bake is not None:
        cmd += ["--bake", bake]
    cmd += ["--port", "0", "--state-dir", state_dir, "--backend", backend, "--log-level", log_level, *args]
    err_path = state_dir.rstrip("/") + ".err"
    with open(err_path, "w") as err:
        p = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=err, text=True, preexec_fn=preexec,
                             env=dict(os.environ, **env) if env else None)
    p.log = DaemonLog(err_path)
    p.port = None
    got = threading.Event()

    def drain():  # the first line names the port; the rest is read so the daemon never blocks
        for line in p.stdout:
            m = _LISTENING.match(line)
            if m and p.port is None:
                p.port = int(m.group(1))
                got.set()
        got.set()

    threading.Thread(target=drain, daemon=True).start()
    got.wait(timeout)
    if p.port is None:
        rc = p.poll()
        if rc is None:
            p.kill()
        p.wait()
        raise LucentdStartError("lucentd did not start (%s): %s\n  command: %s\n  stderr: %s" % (
            "exit %d" % rc if rc is not None else "no 'lucentd listening port=N' line within %.0f s" % timeout,
            state_dir, " ".join(cmd), p.log.tail(800)))
    return p, p.port


def stop(p, sig=signal.SIGTERM, timeout=20.0):
    """Stops lucentd (SIGTERM by default; SIGKILL after `timeout` s). Returns the exit code."""
    if p.poll() is None:
        p.send_signal(sig)
        try:
            p.wait(timeout)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait()
    return p.returncode

# --------------------------------------------------------------------------- MR upload frames (PROTOCOL.md §8.4)

UPLOAD_MAGIC = 0x3155434C  # "LCU1"


def upload_frame(seq, w, h, depth_mm=2000, rgb=(0.5, 0.5, 0.5), exposure=100.0, zlib_planes=False,
                 f=None, translation=(0.0, 0.0, 0.0), rotation=(0.0, 0.0, 0.0, 1.0), capture_us=None):
    """An LCU1 frame of a flat wall facing the camera: every pixel at depth_mm (u16mm), one
    linear colour (rgb16f_linear) times `exposure` nits; focal length f pixels (0.78 w)."""
    n = w * h
    planes = [struct.pack("<%dH" % n, *([depth_mm] * n)), b"", struct.pack("<%de" % (3 * n), *(list(rgb) * n))]
    if zlib_planes:
        planes = [zlib.compress(planes[0]), b"", zlib.compress(planes[2])]
    f = f or 0.78 * w
    hdr = bytearray(128)
    struct.pack_into("<IHBBHHIQHHBBBBB", hdr, 0, UPLOAD_MAGIC, 1, 1, 0, 128, 0, seq,
                     1000 * seq if capture_us is None else capture_us, w, h, 1, 2,
                     int(zlib_planes), 0, int(zlib_planes))
    struct.pack_into("<4f3f4ff", hdr, 36, f, f, w / 2, h / 2, *translation, *rotation, exposure)
    struct.pack_into("<III", hdr, 84, len(planes[0]), 0, len(planes[2]))
    body = planes[0] + planes[2]
    struct.pack_into("<I", hdr, 124, zlib.crc32(bytes(hdr[:124]) + body))
    return bytes(hdr) + body


# --------------------------------------------------------------------------- HTTP: /metrics, /healthz


def http_get(port, path, timeout=10.0, context=None, scheme=None):
    """(status, body text) of GET http://127.0.0.1:PORT/PATH (https with a `context`)."""
    url = "%s://127.0.0.1:%d%s" % (scheme or ("https" if context else "http"), port, path)
    try:
        with urllib.request.urlopen(url, timeout=timeout, context=context) as r:
            return r.status, r.read().decode(errors="replace")
    except urllib.error.HTTPError as e:
        return e.code, e.read().decode(errors="replace")


def metrics(port):
    """/metrics as {sample name with labels: value}, e.g. m['lucent_errors_total{code="invalid"}']."""
    status, text = http_get(port, "/metrics")
    if status != 200:
        raise AssertionError("/metrics answered %d: %r" % (status, text[:200]))
    out = {}
    for line in text.splitlines():
        if line and not line.startswith("#"):
            k, _, v = line.rpartition(" ")
            try:
                out[k] = float(v)
            except ValueError:
                pass
    return out


def metric(port, name, default=None):
    """One sample of /metrics (the name with its labels, if any), or `default`."""
    return metrics(port).get(name, default)


def healthz(port):
    return http_get(port, "/healthz")


def wait_metric(port, name, pred, timeout=10.0, what=None):
    """Polls /metrics until pred(value) holds for sample `name` (None when absent); returns the value.
    WaitTimeout after `timeout` s names `what` (a string or a callable) and the last value."""
    box = []

    def cond():
        v = metric(port, name)
        box[:] = [v]
        return pred(v) and (v if v else True)

    wait_for(cond, timeout, lambda: "%s (%s is %r)" % (_describe(what) or "the metric's condition", name,
                                                         box[0] if box else None))
    return box[0]


def reload(p, port, timeout=10.0):
    """SIGHUP, then waits until lucentd has applied it (lucent_config_reloads_total counts it)."""
    before = metric(port, "lucent_config_reloads_total")
    if before is None:
        raise AssertionError("/metrics has no lucent_config_reloads_total")
    p.send_signal(signal.SIGHUP)
    return wait_metric(port, "lucent_config_reloads_total", lambda v: v is not None and v > before, timeout,
                       lambda: "lucentd applying the SIGHUP (log: %r)" % p.log.tail(300))

# --------------------------------------------------------------------------- WebSocket


class RawWS:
    """A minimal RFC 6455 client over a blocking socket: exact control of what is sent and when
    anything is read (a peer that never reads, broken frames, odd Origin/Host headers).
    `ok` says whether the upgrade was accepted (`status_line` has the answer)."""

    def __init__(self, port, origin=None, host=None, timeout=10.0, rcvbuf=None, subprotocol="lucent.v1"):
        s = socket.socket()
        if rcvbuf:
            s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, rcvbuf)
        s.settimeout(timeout)
        s.connect(("127.0.0.1", port))
        self.s = s
        key = base64.b64encode(os.urandom(16)).decode()
        req = ("GET / HTTP/1.1\r\nHost: %s\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
               "Sec-WebSocket-Key: %s\r\nSec-WebSocket-Version: 13\r\n" % (host or "127.0.0.1:%d" % port, key))
        if subprotocol:
            req += "Sec-WebSocket-Protocol: %s\r\n" % subprotocol
        if origin:
            req += "Origin: %s\r\n" % origin
        self.s.sendall((req + "\r\n").encode())
        head = b""
        while b"\r\n\r\n" not in head:
            chunk = self.s.recv(4096)
            if not chunk:
                break
            head += chunk
        self.status_line = head.split(b"\r\n", 1)[0].decode(errors="replace")
        self.buf = head.split(b"\r\n\r\n", 1)[1] if b"\r\n\r\n" in head else b""
        self.ok = " 101 " in self.status_line

    def send_frame(self, opcode, payload, fin=True):
        mask = os.urandom(4)
        n = len(payload)
        hdr = bytes([(0x80 if fin else 0) | opcode])
        if n < 126:
            hdr += bytes([0x80 | n])
        elif n < 65536:
            hdr += bytes([0x80 | 126]) + struct.pack(">H", n)
        else:
            hdr += bytes([0x80 | 127]) + struct.pack(">Q", n)
        masked = bytes(b ^ mask[i % 4] for i, b in enumerate(payload))
        self.s.sendall(hdr + mask + masked)

    def send_json(self, obj):
        self.send_frame(1, json.dumps(obj).encode())

    def _read(self, n):
        while len(self.buf) < n:
            chunk = self.s.recv(65536)
            if not chunk:
                raise ConnectionError("closed")
            self.buf += chunk
        out, self.buf = self.buf[:n], self.buf[n:]
        return out

    def recv_frame(self):
        """(opcode, payload) of the next WebSocket frame."""
        b0, b1 = self._read(2)
        n = b1 & 0x7F
        if n == 126:
            n = struct.unpack(">H", self._read(2))[0]
        elif n == 127:
            n = struct.unpack(">Q", self._read(8))[0]
        return b0 & 0x0F, self._read(n)

    def recv_json(self, want=None):
        """The next text message (of type `want`); binary frames are skipped. A close frame raises
        ConnectionError("close CODE")."""
        while True:
            op, data = self.recv_frame()
            if op == 8:
                raise ConnectionError("close %s" % (struct.unpack(">H", data[:2])[0] if len(data) >= 2 else None))
            if op == 1:
                m = json.loads(data)
                if want is None or m.get("type") == want:
                    return m

    def hello(self, token=None, client="testlib"):
        msg = {"type": "hello", "id": 1, "protocol": "lucent/1", "client": client}
        if token is not None:
            msg["token"] = token
        self.send_json(msg)
        return self.recv_json()

    def close(self):
        try:
            self.s.close()
        except OSError:
            pass


async def recv_json(ws, want=None, timeout=10.0):
    """The next text message of a `websockets` connection whose type is `want` (a type, a tuple
    of types, or None for any); binary messages and other types are skipped. asyncio.TimeoutError
    after `timeout` s without a message."""
    import asyncio
    if isinstance(want, str):
        want = (want,)
    while True:
        m = await asyncio.wait_for(ws.recv(), timeout)
        if isinstance(m, bytes):
            continue
        msg = json.loads(m)
        if want is None or msg.get("type") in want:
            return msg
