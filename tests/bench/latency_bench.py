#!/usr/bin/python3
"""lucentd update->frame latency benchmark.

Starts lucentd itself (--port 0, --backend cpu by default, a fresh temporary --state-dir for
every client count), connects N viewer connections subscribed to the lightmap (rgb9e5 by
default) and one controller connection that moves an orbiting point light with `light.set`
at a fixed rate. For every update it measures, at every client, the time from sending the
`light.set` to the arrival of the first binary frame whose header revision (u64 at offset 16)
is >= the revision the `ok` acknowledged.

Reported per N: latency p50/p99/max (ms), frames received per client, the fraction of
clients whose last frame is on the final revision, bytes per keyframe and per delta frame
(header flags bit 0 / bit 1, whole WebSocket message length), the frames carrying a few small
light moves (size / keyframe; median and worst), and the daemon's peak RSS (VmHWM) and CPU
seconds (utime+stime).

One more viewer, the *observer*, subscribes with `"delta": "residual"` (PROTOCOL.md §6.2.1; same
encoding): it is connected with the others but left out of every latency, bytes and
final-revision figure and of the client count N; it only measures the small moves a second
time, in the delta mode made for them (`small_move_residual`, next to `small_move` for client 0's
whole-tile deltas). The small-move target is judged on it.

Needs Debian's python3 with python3-websockets (asyncio API, 10.x). Example:

    /usr/bin/python3 tests/bench/latency_bench.py --clients 1,10,100 --json /tmp/lat.json
    /usr/bin/python3 tests/bench/latency_bench.py --bake sponza.lcb --scene sponza

The clients run in this one Python process on the same machine as the daemon, so on a small
machine they compete with it for CPU: the latencies are an upper bound for the daemon.
"""
import argparse
import asyncio
import json
import math
import os
import platform
import shutil
import sys
import tempfile
import time

try:
    import websockets
except ImportError:  # pragma: no cover
    sys.exit("latency_bench: needs python3-websockets (apt install python3-websockets); run with /usr/bin/python3")

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "lib"))
import lucent_testlib as lt  # noqa: E402

HEADER = lt.HEADER
MAGIC = lt.MAGIC
REPO = lt.REPO

TARGETS = [
    "Cornell, 10 clients: update->frame p50 <= 10 ms, p99 <= 30 ms",
    "100 clients at 10 updates/s: every client on the latest revision at the end",
    "small light move: delta frame <= 25% of a keyframe",
]


def default_lucentd():
    env = os.environ.get("LUCENT_BINARY_DIR")
    for d in ([env] if env else []) + [os.path.join(REPO, "build")]:
        p = os.path.join(d, "bin", "lucentd")
        if os.path.exists(p):
            return p
    return os.path.join(REPO, "build", "bin", "lucentd")


def percentile(sorted_vals, q):
    if not sorted_vals:
        return None
    k = (len(sorted_vals) - 1) * q
    lo, hi = math.floor(k), math.ceil(k)
    return sorted_vals[lo] + (sorted_vals[hi] - sorted_vals[lo]) * (k - lo)


def proc_stats(pid):
    """(VmHWM kB, VmRSS kB, CPU seconds utime+stime) of a live process."""
    hwm = rss = None
    with open("/proc/%d/status" % pid) as fh:
        for line in fh:
            if line.startswith("VmHWM:"):
                hwm = int(line.split()[1])
            elif line.startswith("VmRSS:"):
                rss = int(line.split()[1])
    with open("/proc/%d/stat" % pid) as fh:
        fields = fh.read().rsplit(")", 1)[1].split()
    tck = os.sysconf("SC_CLK_TCK")
    cpu = (int(fields[11]) + int(fields[12])) / tck  # utime, stime: fields 14 and 15 of stat
    return hwm, rss, cpu


class Daemon:
    """lucentd started by tests/lib/lucent_testlib.py (free port, stderr kept in a file)."""

    def __init__(self, args, n_clients):
        self.state_dir = tempfile.mkdtemp(prefix="lucent-bench-")
        extra = ["--listen", "127.0.0.1", "--max-clients", str(max(1000, n_clients + 10))]
        if args.fsync:
            extra += ["--fsync", args.fsync]
        extra += ["--keyframe-interval", str(args.keyframe_interval)]
        if args.threads is not None:
            extra += ["--threads", str(args.threads)]
        for more in args.daemon_arg:
            extra += more.split()
        try:
            self.p, self.port = lt.start_lucentd(os.path.join(self.state_dir, "state"), *extra, bake=args.bake,
                                                 lucentd=args.lucentd, backend=args.backend,
                                                 log_level=args.log_level)
        except lt.LucentdStartError as e:
            shutil.rmtree(self.state_dir, ignore_errors=True)
            raise SystemExit(str(e))

    def stats(self):
        return proc_stats(self.p.pid)

    def stop(self):
        rc = lt.stop(self.p)
        log = self.p.log.text()
        shutil.rmtree(self.state_dir, ignore_errors=True)
        return rc, log


def scrape_metrics(port):
    try:
        return lt.metrics(port)
    except Exception as e:  # pragma: no cover
        return {"error": str(e)}


async def recv_json(ws, want, timeout=15):
    return await lt.recv_json(ws, want, timeout)


class Client:
    """One subscribed viewer: records (revision, arrival time, size, flags, tiles) per frame."""

    def __init__(self, idx, verify_crc, delta=None):
        self.idx = idx
        self.delta = delta  # subscribe "delta" (None: the server's default, whole tiles)
        self.verify_crc = verify_crc
        self.revs = []
        self.times = []
        self.stamps = []  # header server timestamp (s since the epoch)
        self.recorded = []  # (revision, arrival, bytes, flags, tiles, sequence) of recorded frames
        self.key_bytes = []
        self.delta_bytes = []
        self.delta_tiles = []
        self.bad = 0
        self.seq_gaps = 0
        self.last_seq = 0
        self.closed = None
        self.ws = None
        self.first_frame = asyncio.get_running_loop().create_future()
        self.waiters = []  # (revision, future)
        self.record_from = 0.0
        self.last_arrival = 0.0  # monotonic time of the last frame (recorded or not)

    async def connect(self, port, encoding, max_rate, token):
        self.ws = await websockets.connect("ws://127.0.0.1:%d/" % port, subprotocols=["lucent.v1"],
                                           max_size=2 ** 26, max_queue=None, compression=None,
                                           ping_interval=None)
        await self.ws.send(json.dumps({"type": "hello", "id": 1, "client": "bench-%s" % self.idx,
                                       "token": token, "encodings": [encoding]}))
        w = await recv_json(self.ws, ("welcome", "error"))
        if w.get("type") != "welcome":
            raise RuntimeError("hello refused: %r" % w)
        sub = {"type": "subscribe", "id": "s", "stream": "lightmap", "encoding": encoding}
        if max_rate:
            sub["max_rate"] = max_rate
        if self.delta:
            sub["delta"] = self.delta
        await self.ws.send(json.dumps(sub))
        # The subscribe ok and the first keyframe are read by run().
        return w

    async def run(self):
        loop_time = time.monotonic
        try:
            async for m in self.ws:
                t = loop_time()
                if not isinstance(m, bytes):
                    continue
                if len(m) < 64:
                    self.bad += 1
                    continue
                (magic, _ver, _stream, _enc, flags, _hs, tiles, rev, seq, _ts, _w, _h, _d, _tile, plen,
                 crc) = HEADER.unpack_from(m, 0)
                if magic != MAGIC or len(m) != 64 + 4 * tiles + plen or (self.verify_crc and lt.frame_crc(m) != crc):
                    self.bad += 1
                if self.last_seq and seq != self.last_seq + 1:
                    self.seq_gaps += 1
                self.last_seq = seq
                self.last_arrival = t
                if not self.first_frame.done():
                    self.first_frame.set_result(rev)
                if t >= self.record_from:
                    self.revs.append(rev)
                    self.times.append(t)
                    self.stamps.append(_ts / 1e6)
                    self.recorded.append((rev, t, len(m), flags, tiles, seq))
                    if flags & 1:
                        self.key_bytes.append(len(m))
                    elif flags & 2:  # plain or residual (bit 2) delta
                        self.delta_bytes.append(len(m))
                        self.delta_tiles.append(tiles)
                if self.waiters:
                    keep = []
                    for r, fut in self.waiters:
                        if rev >= r:
                            if not fut.done():
                                fut.set_result((rev, t, len(m), flags, tiles, seq))
                        else:
                            keep.append((r, fut))
                    self.waiters = keep
        except websockets.exceptions.ConnectionClosed as c:
            self.closed = c.code
        else:
            self.closed = self.ws.close_code

    def wait_revision(self, rev):
        fut = asyncio.get_running_loop().create_future()
        if self.revs and self.revs[-1] >= rev:
            # the frame came before the ok: the first recorded frame of that revision or later
            fut.set_result(next(f for f in self.recorded if f[0] >= rev))
        else:
            self.waiters.append((rev, fut))
        return fut

    def last_revision(self):
        return self.revs[-1] if self.revs else None


class Controller:
    def __init__(self):
        self.ws = None
        self.acks = {}
        self.ack_times = {}
        self.errors = []
        self.pending = {}
        self.wall = {}

    async def connect(self, port, token):
        self.ws = await websockets.connect("ws://127.0.0.1:%d/" % port, subprotocols=["lucent.v1"],
                                           max_size=2 ** 26, max_queue=None, compression=None,
                                           ping_interval=None)
        await self.ws.send(json.dumps({"type": "hello", "id": 0, "client": "bench-controller", "token": token}))
        w = await recv_json(self.ws, ("welcome", "error"))
        if w.get("type") != "welcome" or w.get("role") != "controller":
            raise RuntimeError("controller hello refused: %r" % w)
        return w

    async def run(self):
        try:
            async for m in self.ws:
                if isinstance(m, bytes):
                    continue
                msg = json.loads(m)
                mid = msg.get("id")
                if msg.get("type") == "ok" and mid in self.pending:
                    self.acks[mid] = msg["revision"]
                    self.ack_times[mid] = time.monotonic()
                    self.pending.pop(mid).set_result(msg["revision"])
                elif msg.get("type") == "error":
                    self.errors.append(msg)
                    if mid in self.pending:
                        self.pending.pop(mid).set_exception(RuntimeError("error: %r" % msg))
        except websockets.exceptions.ConnectionClosed:
            pass

    async def send_light(self, mid, light):
        fut = asyncio.get_running_loop().create_future()
        self.pending[mid] = fut
        t = time.monotonic()
        self.wall[mid] = time.time()
        await self.ws.send(json.dumps({"type": "light.set", "id": mid, "light": light}))
        return t, fut


async def settled(viewers, quiet=0.3, limit=20.0):
    """Waits until no viewer has received a frame for `quiet` s: the progressive refinement
    passes of the last change are over (they follow it back to back). Returns the wait in s;
    raises WaitTimeout when frames keep coming for `limit` s."""
    loop_start = time.monotonic()
    while True:
        now = time.monotonic()
        last = max((c.last_arrival for c in viewers), default=0.0)
        if now - last >= quiet:
            return now - loop_start
        if now - loop_start > limit:
            raise lt.WaitTimeout("frames kept coming for %.0f s after the last change (no %.1f s quiet)" %
                                 (limit, quiet))
        await asyncio.sleep(max(0.01, quiet - (now - last)))


def orbit_geometry(welcome):
    g = welcome["scene"]["grid"]
    ext = [g["cell"] * (d - 1) for d in g["dims"]]
    lo = g["origin"]
    centre = [lo[i] + ext[i] / 2 for i in range(3)]
    radius = 0.3 * min(ext[0], ext[2])
    height = lo[1] + 0.75 * ext[1]
    return centre, radius, height


def light_at(args, geom, angle):
    centre, radius, height = geom
    return {"id": "bench-orbit", "type": "point", "intensity": args.intensity, "color": [1, 0.9, 0.8],
            "position": [centre[0] + radius * math.cos(angle), height, centre[2] + radius * math.sin(angle)]}


async def run_n(args, n):
    daemon = Daemon(args, n)
    result = {"clients": n}
    clients = []
    tasks = []
    try:
        ctl = Controller()
        welcome = await ctl.connect(daemon.port, args.token)
        tasks.append(asyncio.create_task(ctl.run()))
        geom = orbit_geometry(welcome)
        lm = welcome["scene"]["lightmap"]
        result["lightmap"] = [lm["width"], lm["height"], lm["tile"]]

        # Connect the viewers, a few at a time so the hello timeout is never at risk. The
        # observer (residual deltas) joins the first batch; it is in no statistic but the
        # small moves' small_move_residual.
        clients = [Client(i, args.verify_crc, delta=None if args.delta == "tiles" else args.delta) for i in range(n)]
        observer = Client("observer", args.verify_crc, delta="residual")
        viewers = [observer] + clients
        t0 = time.monotonic()
        for i in range(0, len(viewers), 20):
            await asyncio.gather(*(c.connect(daemon.port, args.encoding, args.max_rate, args.viewer_token)
                                   for c in viewers[i:i + 20]))
            for c in viewers[i:i + 20]:
                tasks.append(asyncio.create_task(c.run()))
        await asyncio.wait_for(asyncio.gather(*(c.first_frame for c in viewers)), 60)
        result["connect_s"] = round(time.monotonic() - t0, 3)

        # Place the light and wait until every client shows it (warm-up, not measured).
        angle = 0.0
        step = 2 * math.pi / (args.orbit_period * args.rate)
        _, fut = await ctl.send_light("warm", light_at(args, geom, angle))
        rev0 = await asyncio.wait_for(fut, 15)
        await asyncio.wait_for(asyncio.gather(*(c.wait_revision(rev0) for c in viewers)), 60)
        await settled(viewers)  # the progressive refinement of the warm-up is over

        hwm0, rss0, cpu0 = daemon.stats()
        start = time.monotonic()
        for c in viewers:
            c.record_from = start
        sends = []  # (send time, ack future)
        count = int(round(args.rate * args.duration))
        for i in range(count):
            target = start + i / args.rate
            delay = target - time.monotonic()
            if delay > 0:
                await asyncio.sleep(delay)
            angle += step
            t, fut = await ctl.send_light("u%d" % i, light_at(args, geom, angle))
            sends.append((t, fut))
        send_end = time.monotonic()
        revs = []
        for t, fut in sends:
            revs.append(await asyncio.wait_for(fut, 30))
        final = revs[-1]
        # Give every client up to --settle seconds to show the final revision.
        settle_deadline = time.monotonic() + args.settle
        pending = [asyncio.ensure_future(c.wait_revision(final)) for c in clients]
        done, not_done = await asyncio.wait(pending, timeout=max(0.0, settle_deadline - time.monotonic()))
        for f in not_done:
            f.cancel()
        on_final = sum(1 for c in clients if c.last_revision() is not None and c.last_revision() >= final)
        hwm1, rss1, cpu1 = daemon.stats()
        metrics = scrape_metrics(daemon.port)

        # Latencies: for each update, each client's first frame with revision >= the ack.
        import bisect
        lat = []
        server_ms = []  # send (wall clock) -> the frame's server timestamp: relight + queueing in the daemon
        missing = 0
        per_client_max = []
        for c in clients:
            # Revisions in a stream never decrease, so bisect on a running maximum.
            mx, runmax = -1, []
            for r in c.revs:
                mx = max(mx, r)
                runmax.append(mx)
            worst = 0.0
            for (t, _), r in zip(sends, revs):
                j = bisect.bisect_left(runmax, r)
                # The frame must also arrive after the send (it always does for a new revision).
                while j < len(runmax) and c.times[j] < t:
                    j += 1
                if j >= len(runmax):
                    missing += 1
                    continue
                ms = (c.times[j] - t) * 1000.0
                lat.append(ms)
                if c is clients[0]:
                    server_ms.append((c.stamps[j] - ctl.wall["u%d" % len(server_ms)]) * 1000.0)
                worst = max(worst, ms)
            per_client_max.append(worst)
        lat.sort()
        server_ms.sort()
        ack_ms = sorted((ctl.ack_times[f"u{i}"] - sends[i][0]) * 1000.0 for i in range(count)
                        if f"u{i}" in ctl.ack_times)
        key = [b for c in clients for b in c.key_bytes]
        delta = [b for c in clients for b in c.delta_bytes]
        tiles = [b for c in clients for b in c.delta_tiles]
        frames = [len(c.revs) for c in clients]

        # Small light moves (--small-move metres each, --small-moves of them, each once the frames
        # of the one before have stopped: its refinement passes are over) after
        # the run: the frame that carries each move (the first one of its revision) at client 0
        # (whole-tile deltas) and at the observer (residual deltas). A delta counts as its size /
        # the mean keyframe of the plain clients; a keyframe sent because the delta would not be
        # smaller counts as 100%; a scheduled one (every --keyframe-interval frames of that
        # connection) says nothing about deltas and is left out.
        small = small_res = None
        if args.small_move > 0 and args.small_moves > 0:
            await settled(viewers)  # the run's last refinement passes are over
            base = light_at(args, geom, angle)
            c0 = clients[0]
            key_mean = (sum(key) / len(key)) if key else None

            async def carrier(c, r):
                try:
                    return await asyncio.wait_for(c.wait_revision(r), 10)
                except asyncio.TimeoutError:
                    return None

            def move_entry(got):
                if got is None:
                    return {"bytes": None}
                _, _, nbytes, flags, move_tiles, seq = got
                periodic = bool(flags & 1) and seq is not None and (seq - 1) % args.keyframe_interval == 0
                frac = None if periodic or not key_mean or nbytes is None else \
                    (1.0 if flags & 1 else nbytes / key_mean)
                return {"bytes": nbytes, "keyframe": bool(flags & 1), "periodic_keyframe": periodic,
                        "tiles": move_tiles, "fraction": frac}

            def summary(moves):
                fr = sorted(m["fraction"] for m in moves if m.get("fraction") is not None)
                return {"move_m": args.small_move, "moves": moves,
                        "fraction_median": percentile(fr, 0.5), "fraction_max": fr[-1] if fr else None}

            moves, moves_res = [], []
            for k in range(args.small_moves):
                base["position"][0] += args.small_move
                _, fut = await ctl.send_light("small%d" % k, base)
                r = await asyncio.wait_for(fut, 15)
                got, got_res = await asyncio.gather(carrier(c0, r), carrier(observer, r))
                if got is not None or got_res is not None:
                    await settled([c0, observer])  # progressive refinement frames of the same move
                moves.append(move_entry(got))
                moves_res.append(move_entry(got_res))
            small, small_res = summary(moves), summary(moves_res)

        tpt = -(-lm["width"] // lm["tile"]) * -(-lm["height"] // lm["tile"])  # tiles in the lightmap
        result.update({
            "updates": count,
            "send_s": round(send_end - start, 3),
            "final_revision": final,
            "latency_ms": {"p50": percentile(lat, 0.5), "p99": percentile(lat, 0.99), "max": lat[-1] if lat else None,
                           "mean": sum(lat) / len(lat) if lat else None, "samples": len(lat),
                           "missing": missing},
            "server_ms": {"p50": percentile(server_ms, 0.5), "p99": percentile(server_ms, 0.99),
                          "max": server_ms[-1] if server_ms else None,
                          "note": "client 0: send -> the frame's header timestamp (relight done), wall clock"},
            "metrics": metrics,
            "ack_ms": {"p50": percentile(ack_ms, 0.5), "p99": percentile(ack_ms, 0.99),
                       "max": ack_ms[-1] if ack_ms else None},
            "frames_per_client": {"mean": sum(frames) / len(frames), "min": min(frames), "max": max(frames)},
            "final_fraction": on_final / n,
            "keyframe_bytes": {"count": len(key), "mean": sum(key) / len(key) if key else None},
            "delta_bytes": {"count": len(delta), "mean": sum(delta) / len(delta) if delta else None,
                            "max": max(delta) if delta else None,
                            "tiles_mean": sum(tiles) / len(tiles) if tiles else None, "tiles_total": tpt},
            "small_move": small,
            "small_move_residual": small_res,
            "observer": {"delta": "residual", "frames": len(observer.revs), "seq_gaps": observer.seq_gaps,
                         "bad_frames": observer.bad, "closed": observer.closed is not None,
                         "note": "left out of every other figure and of the client count"},
            "seq_gaps": sum(c.seq_gaps for c in clients),
            "bad_frames": sum(c.bad for c in clients),
            "closed_clients": sum(1 for c in clients if c.closed is not None),
            "controller_errors": ctl.errors[:5],
            "daemon": {"vmhwm_kb": hwm1, "vmrss_kb_before": rss0, "vmrss_kb_after": rss1,
                       "cpu_s_total": round(cpu1, 3), "cpu_s_run": round(cpu1 - cpu0, 3)},
        })
        for c in viewers + [ctl]:
            try:
                await asyncio.wait_for(c.ws.close(), 2)
            except Exception:
                pass
    finally:
        for t in tasks:
            t.cancel()
        rc, log = daemon.stop()
        warn = [l for l in log.splitlines() if l.strip()]
        result["daemon"] = dict(result.get("daemon", {}), exit_code=rc, log_lines=len(warn), log_tail=warn[-5:])
    return result


def fmt(v, spec="%.1f"):
    return "-" if v is None else spec % v


def print_table(results, args):
    print()
    print("lucentd update->frame latency  scene=%s  bake=%s" % (args.scene, args.bake or "(default)"))
    print("backend=%s  encoding=%s  rate=%g/s  duration=%gs  fsync=%s" % (
        args.backend, args.encoding, args.rate, args.duration, args.fsync or "(default)"))
    print("machine: %s, %d cores; the clients (one Python process) run on the same machine as the daemon"
          % (platform.machine(), os.cpu_count()))
    hdr = ("N", "p50 ms", "p99 ms", "max ms", "miss", "frames/cl", "on final", "key B", "delta B", "d/key",
           "small d/key", "small d/key res", "VmHWM MB", "CPU s")
    print("%5s %8s %8s %8s %5s %10s %9s %8s %8s %6s %11s %15s %9s %7s" % hdr)
    for r in results:
        L = r["latency_ms"]
        kb, db = r["keyframe_bytes"]["mean"], r["delta_bytes"]["mean"]
        smr = (r.get("small_move") or {}).get("fraction_median")
        smr_res = (r.get("small_move_residual") or {}).get("fraction_median")
        print("%5d %8s %8s %8s %5d %10s %8.0f%% %8s %8s %6s %11s %15s %9s %7s" % (
            r["clients"], fmt(L["p50"]), fmt(L["p99"]), fmt(L["max"]), L["missing"],
            fmt(r["frames_per_client"]["mean"]), 100 * r["final_fraction"], fmt(kb, "%.0f"), fmt(db, "%.0f"),
            fmt(db / kb * 100 if kb and db else None, "%.0f%%"), fmt(smr * 100 if smr is not None else None, "%.0f%%"),
            fmt(smr_res * 100 if smr_res is not None else None, "%.1f%%"),
            fmt(r["daemon"]["vmhwm_kb"] / 1024 if r["daemon"].get("vmhwm_kb") else None),
            fmt(r["daemon"].get("cpu_s_total"), "%.2f")))
    for r in results:
        if len(r.get("runs", [])) > 1:
            print("  N=%d: the run with the median p50 of %d; every run's p50/p99 ms: %s" % (
                r["clients"], len(r["runs"]), ", ".join("%s/%s" % (fmt(x["p50"]), fmt(x["p99"])) for x in r["runs"])))
    print()
    print("targets:")
    by_n = {r["clients"]: r for r in results}
    r10 = by_n.get(10)
    if r10:
        ok = r10["latency_ms"]["p50"] is not None and r10["latency_ms"]["p50"] <= 10 and \
            r10["latency_ms"]["p99"] <= 30
        print("  %-78s %s (p50 %s, p99 %s)%s" % (TARGETS[0], "MET" if ok else "NOT MET", fmt(r10["latency_ms"]["p50"]),
                                                fmt(r10["latency_ms"]["p99"]),
                                                "" if args.scene == "cornell" else " [scene is not Cornell]"))
    else:
        print("  %-78s (not run: no N=10)" % TARGETS[0])
    r100 = by_n.get(100)
    if r100:
        ok = r100["final_fraction"] == 1.0 and args.rate >= 10
        print("  %-78s %s (%.0f%% on final revision, rate %g/s)" % (TARGETS[1], "MET" if ok else "NOT MET",
                                                                  100 * r100["final_fraction"], args.rate))
    else:
        print("  %-78s (not run: no N=100)" % TARGETS[1])
    # The small-move target is judged on the residual observer (the delta mode made for small
    # changes); client 0's whole-tile deltas are printed for comparison.
    def small_of(key):
        sm = [r[key] for r in results if r.get(key) and r[key].get("fraction_median") is not None]
        if not sm:
            return None
        return max(s["fraction_median"] for s in sm), max(s["fraction_max"] for s in sm)

    tiles, res = small_of("small_move"), small_of("small_move_residual")
    tiles_txt = "whole-tile deltas: median %.0f%%, worst %.0f%%" % (tiles[0] * 100, tiles[1] * 100) if tiles else \
        "whole-tile deltas: no frame seen"
    if res:
        print("  %-78s %s (residual deltas: median %.1f%%, worst %.1f%% of a keyframe over %d moves of %.3f m; %s)" % (
            TARGETS[2], "MET" if res[0] <= 0.25 else "NOT MET", res[0] * 100, res[1] * 100, args.small_moves,
            args.small_move, tiles_txt))
    elif tiles:
        print("  %-78s %s (no residual-delta frame seen for the small moves; %s of a keyframe over %d moves of "
              "%.3f m)" % (TARGETS[2], "MET" if tiles[0] <= 0.25 else "NOT MET", tiles_txt, args.small_moves,
                           args.small_move))
    else:
        print("  %-78s (no frame seen for the small moves)" % TARGETS[2])
    for r in results:
        notes = []
        if r["seq_gaps"]:
            notes.append("%d sequence gaps" % r["seq_gaps"])
        if r["bad_frames"]:
            notes.append("%d malformed frames" % r["bad_frames"])
        if r["closed_clients"]:
            notes.append("%d clients closed by the server" % r["closed_clients"])
        if r["controller_errors"]:
            notes.append("controller errors: %r" % r["controller_errors"])
        if r["latency_ms"]["missing"]:
            notes.append("%d (update, client) pairs never saw a frame of that revision" % r["latency_ms"]["missing"])
        ob = r.get("observer") or {}
        if ob.get("seq_gaps") or ob.get("bad_frames") or ob.get("closed"):
            notes.append("residual observer: %d sequence gaps, %d malformed frames%s" % (
                ob.get("seq_gaps", 0), ob.get("bad_frames", 0), ", closed by the server" if ob.get("closed") else ""))
        if notes:
            print("  N=%d: %s" % (r["clients"], "; ".join(notes)))
    print("note: 'on final' = clients whose last frame shows the final acknowledged revision within --settle s;"
          " latencies include the Python clients' own scheduling on a shared machine. 'small d/key res': the"
          " residual-delta observer (one more connection, in no other column).")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--lucentd", default=default_lucentd(), help="lucentd binary (default: %(default)s)")
    ap.add_argument("--bake", default=None, help="bake file (default: the build's cornell.lcb next to bin/)")
    ap.add_argument("--scene", default=None, help="label for the report (default: the bake's file name)")
    ap.add_argument("--clients", default="1,10,100", help="comma-separated client counts (default %(default)s)")
    ap.add_argument("--rate", type=float, default=10.0, help="light.set updates per second (default %(default)s)")
    ap.add_argument("--duration", type=float, default=10.0, help="seconds of updates (default %(default)s)")
    ap.add_argument("--orbit-period", type=float, default=20.0, help="seconds per light orbit (default %(default)s)")
    ap.add_argument("--intensity", type=float, default=0.5, help="orbiting point light intensity (cd)")
    ap.add_argument("--small-move", type=float, default=0.005,
                    help="metres of each small move measured after the run (0 = skip; default %(default)s)")
    ap.add_argument("--small-moves", type=int, default=5,
                    help="small moves after the run, each after the previous one's frames stopped (default "
                         "%(default)s); the target uses their median")
    ap.add_argument("--keyframe-interval", type=int, default=30,
                    help="passed to lucentd; tells scheduled keyframes apart (default %(default)s)")
    ap.add_argument("--settle", type=float, default=5.0,
                    help="seconds the clients get to reach the final revision (default %(default)s)")
    ap.add_argument("--encoding", default="rgb9e5", choices=["rgb9e5", "rgba16f", "f32"])
    ap.add_argument("--max-rate", type=float, default=None, help="subscribe max_rate (default: none)")
    ap.add_argument("--delta", default="tiles", choices=["tiles", "residual"],
                    help="delta frames of the measured clients (default %(default)s; the observer always residual)")
    ap.add_argument("--backend", default="cpu", choices=["auto", "cpu", "egl"])
    ap.add_argument("--threads", type=int, default=None, help="lucentd --threads")
    ap.add_argument("--fsync", default=None, choices=["always", "everysec"], help="lucentd --fsync")
    ap.add_argument("--log-level", default="warn")
    ap.add_argument("--token", default="", help="controller token (if --daemon-arg sets tokens)")
    ap.add_argument("--viewer-token", default="", help="viewer token")
    ap.add_argument("--daemon-arg", action="append", default=[], help="extra lucentd arguments (repeatable)")
    ap.add_argument("--verify-crc", action="store_true", help="check every frame's CRC (costs client CPU)")
    ap.add_argument("--repeat", type=int, default=1,
                    help="runs per client count; the one with the median p50 is reported, all runs' p50/p99 "
                         "listed (default %(default)s)")
    ap.add_argument("--json", default=None, help="write the results as JSON to this file")
    args = ap.parse_args()

    if not os.path.exists(args.lucentd):
        sys.exit("latency_bench: no lucentd at %s (build it or pass --lucentd)" % args.lucentd)
    if args.bake is None:
        cand = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(args.lucentd))), "cornell.lcb")
        if os.path.exists(cand):
            args.bake = cand
    if args.scene is None:
        args.scene = os.path.splitext(os.path.basename(args.bake))[0] if args.bake else "cornell"
    counts = [int(x) for x in args.clients.split(",") if x.strip()]

    # 100+ sockets: make sure the descriptor limit is not the bottleneck.
    try:
        import resource
        soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
        want = min(hard, max(soft, 4 * max(counts) + 256))
        resource.setrlimit(resource.RLIMIT_NOFILE, (want, hard))
    except Exception:
        pass

    results = []
    for n in counts:
        runs = []
        for k in range(args.repeat):
            print("N=%d: running %g s at %g updates/s (run %d of %d) ..." % (n, args.duration, args.rate, k + 1,
                                                                          args.repeat), flush=True)
            r = asyncio.run(run_n(args, n))
            runs.append(r)
            L = r["latency_ms"]
            print("N=%d: p50 %s ms, p99 %s ms, max %s ms, %.0f%% on final revision" % (
                n, fmt(L["p50"]), fmt(L["p99"]), fmt(L["max"]), 100 * r["final_fraction"]), flush=True)
        # The run with the median p50 stands for N (a shared VM's speed drifts between runs);
        # every run's figures are kept beside it.
        ranked = sorted(runs, key=lambda r: r["latency_ms"]["p50"] if r["latency_ms"]["p50"] is not None else 1e9)
        r = ranked[(len(ranked) - 1) // 2]
        r["runs"] = [{"p50": x["latency_ms"]["p50"], "p99": x["latency_ms"]["p99"],
                      "final_fraction": x["final_fraction"]} for x in runs]
        results.append(r)
    print_table(results, args)
    if args.json:
        out = {"scene": args.scene, "bake": args.bake, "lucentd": args.lucentd, "backend": args.backend,
               "encoding": args.encoding, "delta": args.delta, "rate": args.rate, "duration": args.duration,
               "repeat": args.repeat,
               "orbit_period": args.orbit_period, "machine": {"arch": platform.machine(), "cores": os.cpu_count(),
                                                               "clients_same_machine": True},
               "targets": TARGETS, "results": results}
        with open(args.json, "w") as fh:
            json.dump(out, fh, indent=2)
        print("wrote", args.json)
    return 0


if __name__ == "__main__":
    sys.exit(main())
