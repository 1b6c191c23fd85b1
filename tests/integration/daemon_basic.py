#!/usr/bin/python3
"""lucentd end to end on loopback: handshake and hello, welcome, subscribe and a lightmap
keyframe (header fields and CRC checked), light.set -> ok -> a frame of that revision,
state.get, errors with codes and pointers, roles by token, kill -9 durability (state and
revision exactly as acknowledged), SIGTERM (close 1001, exit 0), /healthz and /metrics.
Uses Python's websockets, a different implementation from the server's."""
import asyncio
import glob
import json
import ssl
import os
import signal
import socket
import struct
import subprocess
import sys
import tempfile
import time
import urllib.request

import websockets

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "lib"))
import lucent_testlib as lt  # noqa: E402
from lucent_testlib import parse_frame, recv_json  # noqa: E402

LUCENTD = lt.LUCENTD
BAKE = lt.CORNELL_LCB
FAILS = []


def check(cond, msg):
    if not cond:
        FAILS.append(msg)
        print("FAIL:", msg, file=sys.stderr)


def start(state_dir, *extra, log_level=None):
    """lucentd on a free port (tests/lib/lucent_testlib.py); its stderr is in STATE_DIR.err,
    readable as p.log (printed by main() when a check fails)."""
    return lt.start_lucentd(state_dir, *extra, log_level=log_level or "warn")


async def recv_frame(ws, min_revision=0, timeout=15):
    while True:
        m = await asyncio.wait_for(ws.recv(), timeout)
        if isinstance(m, bytes):
            f = parse_frame(m)
            if f["revision"] >= min_revision:
                return f, m


async def hello(port, token="", name="test"):
    ws = await websockets.connect("ws://127.0.0.1:%d/" % port, subprotocols=["lucent.v1"], max_size=2**24)
    await ws.send(json.dumps({"type": "hello", "id": 1, "client": name, "token": token}))
    return ws, await recv_json(ws)


async def scenario(state_dir):
    p, port = start(state_dir)
    try:
        # Subprotocol required.
        try:
            ws = await websockets.connect("ws://127.0.0.1:%d/" % port)
            await ws.close()
            check(False, "a handshake without lucent.v1 was accepted")
        except Exception:
            pass
        ws, welcome = await hello(port)
        check(welcome.get("type") == "welcome" and welcome.get("id") == 1, "welcome: %r" % welcome)
        check(welcome.get("role") == "controller" and welcome.get("protocol") == "lucent/1", "role/protocol")
        lm = welcome["scene"]["lightmap"]
        # --tile 0 (default): 32, 16 or 8, the largest giving at least 64 tiles
        want_tile = next((t for t in (32, 16) if -(-lm["width"] // t) * -(-lm["height"] // t) >= 64), 8)
        check(lm["tile"] == want_tile, "automatic tile %r for %dx%d, expected %d" % (lm["tile"], lm["width"], lm["height"], want_tile))
        await ws.send(json.dumps({"type": "subscribe", "id": "s1", "stream": "lightmap", "encoding": "rgb9e5"}))
        ok = await recv_json(ws, "ok")
        check(ok.get("id") == "s1", "subscribe ok echoes id")
        f, raw = await recv_frame(ws)
        check(f["magic"] == 0x3146434C and f["version"] == 1 and f["header_size"] == 64, "frame header %r" % f)
        check(f["crc_ok"] and f["length_ok"], "frame CRC/length")
        check(f["flags"] == 1 and f["stream"] == 1 and f["encoding"] == 1, "keyframe of the lightmap in rgb9e5")
        check((f["width"], f["height"]) == (lm["width"], lm["height"]), "frame dims match welcome")
        check(f["payload"] == lm["width"] * lm["height"] * 4, "rgb9e5 payload size")
        # A change: ok with revision 1, then a frame reflecting it.
        await ws.send(json.dumps({"type": "light.set", "id": 7, "light": {
            "id": "key", "type": "point", "position": [0.28, 0.4, 0.28], "intensity": 3}}))
        ok = await recv_json(ws, "ok")
        check(ok.get("id") == 7 and ok.get("revision") == 1, "light.set ok: %r" % ok)
        f, raw = await recv_frame(ws, 1)
        check(f["revision"] == 1 and f["sequence"] >= 2 and f["crc_ok"], "frame for revision 1: %r" % f)
        await ws.send(json.dumps({"type": "state.get", "id": "st"}))
        st = await recv_json(ws, "state")
        check(st.get("revision") == 1 and [l["id"] for l in st.get("lights", [])] == ["key"], "state: %r" % st)
        # Errors carry codes and pointers, and the connection stays usable.
        await ws.send(json.dumps({"type": "frobnicate", "id": 3}))
        e = await recv_json(ws, "error")
        check(e.get("code") == "unknown_type" and e.get("id") == 3, "unknown type: %r" % e)
        await ws.send(json.dumps({"type": "light.set", "light": {"id": "x", "type": "point", "position": [0, 0, 0],
                                                                 "intensity": -1}}))
        e = await recv_json(ws, "error")
        check(e.get("code") == "out_of_range" and e.get("pointer") == "/light/intensity", "range: %r" % e)
        await ws.send(json.dumps({"type": "batch", "ops": [
            {"type": "light.set", "light": {"id": "b1", "type": "point", "position": [0, 0.3, 0]}},
            {"type": "object.set", "object": {"id": "o", "asset": "nope"}}]}))
        e = await recv_json(ws, "error")
        check(e.get("code") == "unknown_asset" and e.get("pointer") == "/ops/1/object/asset", "batch: %r" % e)
        await ws.send(b"\x00\x01")
        e = await recv_json(ws, "error")
        check(e.get("code") == "binary_not_allowed", "binary: %r" % e)
        await ws.send(json.dumps({"type": "ping", "id": "p", "t": 1.5}))
        pong = await recv_json(ws, "pong")
        check(pong.get("t") == 1.5, "pong")
        # Coalescing: 100 rapid updates give frames for a handful of revisions, the last final.
        base = st["revision"]
        for i in range(100):
            await ws.send(json.dumps({"type": "light.set", "light": {
                "id": "anim", "type": "point", "position": [0.1 + 0.003 * i, 0.4, 0.28], "intensity": 2}}))
        revisions, oks = set(), 0
        final = base + 100
        while True:
            m = await asyncio.wait_for(ws.recv(), 30)
            if isinstance(m, bytes):
                fr = parse_frame(m)
                revisions.add(fr["revision"])
                if fr["revision"] == final and oks == 100:
                    break
            elif json.loads(m).get("type") == "ok":
                oks += 1
        check(len(revisions) <= 40 and max(revisions) == final,
              "coalescing: frames for %d revisions (max %d, final %d)" % (len(revisions), max(revisions), final))
        # A second client sees `changed`.
        ws2, w2 = await hello(port, name="watcher")
        await ws.send(json.dumps({"type": "light.remove", "light_id": "key", "id": 9}))
        await recv_json(ws, "ok")
        ch = await recv_json(ws2, "changed")
        check(ch.get("revision") == final + 1 and ch.get("by") == "test", "changed broadcast: %r" % ch)
        # HTTP on the same port.
        status, body = lt.healthz(port)
        check(status == 200 and body.startswith("ok"), "healthz: %d %r" % (status, body))
        status, metrics = lt.http_get(port, "/metrics")
        check("lucent_clients 2" in metrics and "lucent_errors_total{code=\"unknown_type\"} 1" in metrics and
              "lucent_relight_seconds_bucket{le=\"+Inf\"}" in metrics and "lucent_relight_seconds_count" in metrics,
              "metrics: %r" % metrics[:400])
        await ws2.close()
        await ws.close()
    finally:
        p.send_signal(signal.SIGKILL)  # no chance to flush: durability must come from the journal
        p.wait()

    # After kill -9: the state and revision are exactly those acknowledged.
    p, port = start(state_dir)
    try:
        ws, welcome = await hello(port)
        check(welcome.get("revision") == 102, "revision after kill -9: %r" % welcome.get("revision"))
        await ws.send(json.dumps({"type": "state.get"}))
        st = await recv_json(ws, "state")
        lights = st.get("lights", [])
        check(st.get("revision") == 102 and [l["id"] for l in lights] == ["anim"] and
              abs(lights[0]["position"][0] - (0.1 + 0.003 * 99)) < 1e-6, "state after kill -9: %r" % st)
        # SIGTERM: clients get 1001, the process exits 0.
        p.send_signal(signal.SIGTERM)
        try:
            await asyncio.wait_for(ws.recv(), 10)
        except websockets.exceptions.ConnectionClosed as c:
            check(c.code == 1001, "close code on SIGTERM: %r" % c.code)
        check(p.wait(timeout=20) == 0, "exit code on SIGTERM")
    finally:
        if p.poll() is None:
            p.kill()

    # Delta frames: applied onto the previous image they equal the next keyframe (within the
    # delta threshold), and they are smaller than a keyframe.
    # No periodic keyframes, so the frames after the move are deltas unless most tiles change.
    p, port = start(state_dir + "-delta", "--delta-threshold", "0.3", "--tile", "16", "--keyframe-interval", "100000")
    try:
        ws, welcome = await hello(port)
        await ws.send(json.dumps({"type": "light.set", "light": {
            "id": "d", "type": "point", "position": [0.5, 0.05, 0.05], "intensity": 0.05}}))
        await recv_json(ws, "ok")
        await ws.send(json.dumps({"type": "subscribe", "stream": "lightmap", "encoding": "f32"}))
        img, key_bytes, deltas, W = None, 0, [], 0

        def apply(f, raw):
            nonlocal img, key_bytes, W
            W, H, S = f["width"], f["height"], f["tile"]
            if f["flags"] == 1:
                img = list(struct.unpack_from("<%df" % (W * H * 3), raw, 64))
                key_bytes = len(raw)
                return
            tiles = struct.unpack_from("<%dI" % f["tiles"], raw, 64)
            vals = struct.unpack_from("<%df" % (f["payload"] // 4), raw, 64 + 4 * f["tiles"])
            k, tw = 0, (W + S - 1) // S
            for t in tiles:
                x0, y0 = (t % tw) * S, (t // tw) * S
                for y in range(y0, min(y0 + S, H)):
                    for x in range(x0, min(x0 + S, W)):
                        img[3 * (y * W + x):3 * (y * W + x) + 3] = vals[k:k + 3]
                        k += 3
            deltas.append((f["tiles"], len(raw)))

        f, raw = await recv_frame(ws)
        check(f["flags"] == 1, "the first frame after subscribe is a keyframe")
        apply(f, raw)
        # Let the idle refinement converge (frames stop coming) before the small move: a move
        # from an unconverged state changes every tile, and rightly gives a keyframe.
        while True:
            try:
                f, raw = await recv_frame(ws, 0, timeout=1.5)
                apply(f, raw)
            except asyncio.TimeoutError:
                break
        check(f["revision"] >= 1, "frames reached revision 1")
        await ws.send(json.dumps({"type": "light.set", "light": {
            "id": "d", "type": "point", "position": [0.5, 0.05, 0.08], "intensity": 0.05}}))
        await recv_json(ws, "ok")
        while True:  # the move's frame, then its refinement frames until quiet
            try:
                f, raw = await recv_frame(ws, 0, timeout=1.5 if f["revision"] >= 2 else 15)
            except asyncio.TimeoutError:
                break
            check(f["crc_ok"] and f["length_ok"], "frame integrity")
            apply(f, raw)
        check(f["revision"] == 2, "frames reached revision 2")
        check(deltas and all(b < key_bytes for _, b in deltas), "deltas smaller than keyframes: %r vs %d" %
              (deltas, key_bytes))
        if deltas:
            print("delta frames (tiles, bytes): %r; keyframe %d bytes" % (deltas, key_bytes))
        await ws.send(json.dumps({"type": "snapshot"}))
        f2, raw2 = await recv_frame(ws, 2)
        check(f2["flags"] == 1 and f2["sequence"] == f["sequence"] + 1, "snapshot gives a keyframe next in sequence")
        key = struct.unpack_from("<%df" % (len(img)), raw2, 64)
        peak = max(key) or 1
        worst = max(abs(a - b) / max(abs(a), abs(b), 1e-3 * peak) for a, b in zip(img, key))
        check(worst <= 0.3 + 1e-6, "delta-applied image vs keyframe: worst relative difference %.4f" % worst)
        await ws.close()
    finally:
        p.terminate()
        p.wait(timeout=20)

    # Roles by token.
    cfg = os.path.join(state_dir, "lucentd.json")
    with open(cfg, "w") as fh:
        json.dump({"controller-tokens": ["ctl"], "viewer-tokens": ["view"]}, fh)
    p, port = start(state_dir, "--config", cfg, log_level="info")
    try:
        ws, welcome = await hello(port, token="view")
        check(welcome.get("role") == "viewer", "viewer role")
        await ws.send(json.dumps({"type": "light.remove", "light_id": "x"}))
        e = await recv_json(ws, "error")
        check(e.get("code") == "forbidden", "viewer cannot change: %r" % e)
        await ws.close()
        ws, welcome = await hello(port, token="wrong")
        check(welcome.get("code") == "unauthorized", "unknown token: %r" % welcome)
        try:
            await asyncio.wait_for(ws.recv(), 5)
        except websockets.exceptions.ConnectionClosed as c:
            check(c.code == 1008, "close after unauthorized: %r" % c.code)
        # hello required first
        ws = await websockets.connect("ws://127.0.0.1:%d/" % port, subprotocols=["lucent.v1"])
        await ws.send(json.dumps({"type": "state.get"}))
        e = await recv_json(ws, "error")
        check(e.get("code") == "hello_required", "hello first: %r" % e)
        # SIGHUP reloads the tokens: the new one works, the old one no longer does.
        with open(cfg, "w") as fh:
            json.dump({"controller-tokens": ["ctl2"], "viewer-tokens": ["view"]}, fh)
        # the reload is done when lucent_config_reloads_total counts it (server.c server_reload
        # counts after applying), and lucentd says so in its log
        await asyncio.get_running_loop().run_in_executor(None, lt.reload, p, port)
        check(p.log.find("SIGHUP: configuration reloaded") is not None,
              "no 'SIGHUP: configuration reloaded' log line after the reload: %r" % p.log.tail(400))
        ws, welcome = await hello(port, token="ctl2")
        check(welcome.get("role") == "controller", "new token after SIGHUP: %r" % welcome)
        await ws.close()
        ws, welcome = await hello(port, token="ctl")
        check(welcome.get("code") == "unauthorized", "old token after SIGHUP: %r" % welcome)
    finally:
        p.terminate()
        p.wait(timeout=20)

    # --check-config: a bad key is named, exit 2; a good file passes, exit 0.
    with open(cfg, "w") as fh:
        json.dump({"prot": 1}, fh)
    r = subprocess.run([LUCENTD, "--bake", BAKE, "--config", cfg, "--check-config"], capture_output=True, text=True)
    check(r.returncode == 2 and "prot" in r.stderr, "check-config bad key: %d %r" % (r.returncode, r.stderr))
    with open(cfg, "w") as fh:
        json.dump({"port": 7799, "rate": 50}, fh)
    r = subprocess.run([LUCENTD, "--bake", BAKE, "--config", cfg, "--check-config"], capture_output=True, text=True)
    check(r.returncode == 0, "check-config good: %d %r" % (r.returncode, r.stderr))

    # Static files on the same port, and no path traversal out of the www folder.
    www = os.path.join(state_dir + "-www")
    os.makedirs(www, exist_ok=True)
    with open(os.path.join(www, "index.html"), "w") as fh:
        fh.write("<p>lucent viewer</p>")
    with open(os.path.join(state_dir + "-secret.txt"), "w") as fh:
        fh.write("secret")
    p, port = start(state_dir + "-http", "--www", www)
    try:
        status, body = lt.http_get(port, "/")
        check(status == 200 and "lucent viewer" in body, "static index: %d %r" % (status, body))
        name = os.path.basename(state_dir) + "-secret.txt"
        for path in ["/../" + name, "/%2e%2e/" + name, "/..%2f" + name, "/./../" + name]:
            try:
                got = urllib.request.urlopen("http://127.0.0.1:%d%s" % (port, path), timeout=5).read().decode()
                check("secret" not in got, "path traversal %s served: %r" % (path, got))
            except urllib.error.HTTPError as e:
                check(e.code in (400, 403, 404), "traversal %s: HTTP %d" % (path, e.code))
            except Exception:
                pass  # connection refused/closed is a refusal too
        status, body = lt.healthz(port)
        check(status == 200 and body.startswith("ok"), "healthz beside static files: %d %r" % (status, body))
    finally:
        p.terminate()
        p.wait(timeout=20)

    # TLS: wss:// and https:// with a self-signed certificate.
    cert, key = os.path.join(www, "cert.pem"), os.path.join(www, "key.pem")
    subprocess.run(["openssl", "req", "-x509", "-newkey", "rsa:2048", "-nodes", "-keyout", key, "-out", cert,
                    "-days", "1", "-subj", "/CN=127.0.0.1"], check=True, capture_output=True)
    p, port = start(state_dir + "-tls", "--tls-cert", cert, "--tls-key", key)
    try:
        ctx = ssl.create_default_context()
        ctx.check_hostname = False
        ctx.verify_mode = ssl.CERT_NONE
        ws = await websockets.connect("wss://127.0.0.1:%d/" % port, subprotocols=["lucent.v1"], ssl=ctx)
        await ws.send(json.dumps({"type": "hello", "client": "tls"}))
        w = await recv_json(ws)
        check(w.get("type") == "welcome", "welcome over wss: %r" % w)
        await ws.close()
        status, body = lt.http_get(port, "/healthz", context=ctx)
        check(status == 200 and body.startswith("ok"), "healthz over https: %d %r" % (status, body))
    finally:
        p.terminate()
        p.wait(timeout=20)


async def slow_client_scenario(state_dir):
    """A client that never reads is dropped; the others keep getting the latest frames."""
    # --rate: the updates below go as fast as their frames come back, which can pass the
    # default 100/s; a rate_limited reply instead of the awaited ok would stall the loop.
    p, port = start(state_dir + "-slow", "--slow-timeout", "2", "--rate", "100000", log_level="warn")
    try:
        # a tiny receive buffer, and it never reads
        slow = lt.RawWS(port, rcvbuf=4096)
        check(slow.ok, "slow client upgrade: %r" % slow.status_line)
        slow.send_json({"type": "hello", "client": "sloth"})
        slow.send_json({"type": "subscribe", "stream": "lightmap", "encoding": "f32"})
        ws, _ = await hello(port, name="fast")
        await ws.send(json.dumps({"type": "subscribe", "stream": "lightmap", "encoding": "rgb9e5"}))
        await recv_json(ws, "ok")
        # Updates, each waiting for its ok and its frame on the fast client, until lucentd logs
        # that it dropped the slow one (server.c session_drop: "client 'sloth' <why>; dropping
        # it (1008)"), then one more: the fast client is served all along.
        i, dropped, rev, frames_ok = 0, None, 0, True
        end = time.monotonic() + 20
        while True:
            await ws.send(json.dumps({"type": "light.set", "id": "u%d" % i, "light": {
                "id": "orbit", "type": "point", "position": [0.28 + 0.1 * (i % 5) / 5, 0.4, 0.28], "intensity": 2}}))
            ok = await recv_json(ws, "ok", timeout=15)
            check(ok.get("id") == "u%d" % i, "update %d: %r" % (i, ok))
            rev = ok.get("revision", rev)
            try:
                f, _ = await recv_frame(ws, rev, timeout=15)
            except asyncio.TimeoutError:
                frames_ok = False
                break
            i += 1
            if dropped:
                break
            dropped = p.log.find("client 'sloth'", "dropping it")
            if time.monotonic() > end:
                break
        check(frames_ok, "the fast client got no frame for revision %d within 15 s while a slow client was "
              "connected" % rev)
        check(dropped is not None, "lucentd did not log dropping the slow client within 20 s (%d updates)" % i)
        # The slow client was dropped: its socket reads EOF or a reset once drained.
        slow.s.settimeout(5)
        closed = False
        try:
            while True:
                chunk = slow.s.recv(1 << 20)
                if not chunk:
                    closed = True
                    break
        except (ConnectionResetError, socket.timeout):
            closed = True
        check(closed, "slow client dropped")
        rss = 0
        with open("/proc/%d/status" % p.pid) as fh:
            for line in fh:
                if line.startswith("VmHWM:"):
                    rss = int(line.split()[1]) // 1024
        check(rss < 1024, "daemon peak RSS %d MiB stays bounded" % rss)
        await ws.close()
    finally:
        p.terminate()
        p.wait(timeout=20)


def main():
    if not os.path.exists(LUCENTD) or not os.path.exists(BAKE):
        print("SKIP: lucentd or the Cornell bake is not built")
        return 77
    with tempfile.TemporaryDirectory() as d:
        def logs():  # the daemons' stderr, for a failure
            for err in sorted(glob.glob(os.path.join(d, "*.err"))):
                print("--- %s (last 2000 bytes)\n%s" % (err, lt.DaemonLog(err).tail(2000)), file=sys.stderr)
        try:
            asyncio.run(scenario(os.path.join(d, "state")))
            asyncio.run(slow_client_scenario(os.path.join(d, "state")))
        except BaseException:
            logs()
            raise
        if FAILS:
            logs()
    print("%d failure(s)" % len(FAILS) if FAILS else "all checks passed")
    return 1 if FAILS else 0


if __name__ == "__main__":
    sys.exit(main())
