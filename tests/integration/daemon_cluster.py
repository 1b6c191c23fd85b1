#!/usr/bin/python3
"""lucentd --cluster (issue 21, PROTOCOL.md §9): replicas fed by one change log in a Redis stream,
against a redis-server this test starts on loopback (AOF, appendfsync always).

  converge    three replicas, changes sent to all three at once (own lights, one light every
              replica sets, a light all three remove): every ok has its own revision, the racing
              removes give one ok and unknown_id for the rest, every replica ends on the same
              revision with the same state and bit-identical converged lightmaps
  kill9       a replica killed with SIGKILL and started again catches up before /healthz says ok
  redis_down  Redis stopped: /healthz says read-only, state.get works, a change is refused with
              read_only; Redis back (from its AOF): every acknowledged change is there, changes
              work again on every replica
  late        a replica started after the log was trimmed behind snapshots starts from the
              snapshot and ends identical
  other_bake  a replica with another bake is refused (/healthz 503 names both bakes)
  other_limits  one with another --max-lights too (and its --fsync is said to be ignored)
  password    a Redis with requirepass: the URL's password lets a replica in; a wrong one keeps it
              starting (503) with Redis's refusal in /healthz
  lost_log    Redis restarted empty (AOF lost) and refilled past a stopped replica's revision by a
              fresh one: the stopped replica finds another entry at its revision and turns
              unavailable (503) keeping its state; one that saw the empty log says so too
"""
import array
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "lib"))
import lucent_testlib as lt  # noqa: E402
from lucent_testlib import RawWS, frame_payload, parse_frame, stop  # noqa: E402

FAILS = []
TMP = tempfile.mkdtemp(prefix="lucent-cluster-")
KEY = "lucent-test"
SNAPSHOT_EVERY = 10


def check(cond, msg):
    print(("ok: " if cond else "FAIL: ") + msg, file=sys.stdout if cond else sys.stderr)
    if not cond:
        FAILS.append(msg)
    return cond


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Redis:
    def __init__(self, name="redis", password=None):
        self.port = free_port()
        self.password = password
        self.dir = os.path.join(TMP, name)
        os.makedirs(self.dir, exist_ok=True)
        self.p = None

    def start(self):
        exe = shutil.which("redis-server")
        if not exe:
            sys.exit("daemon_cluster: needs redis-server (apt install redis-server; scripts/setup-deps.sh does)")
        self.p = subprocess.Popen([exe, "--port", str(self.port), "--bind", "127.0.0.1", "--dir", self.dir,
                                   "--appendonly", "yes", "--appendfsync", "always", "--save", "",
                                   "--protected-mode", "no",
                                   *(["--requirepass", self.password] if self.password else [])], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        lt.wait_for(lambda: self.cli("PING") == "PONG", 10, "redis-server answering PING")

    def cli(self, *args):
        auth = ["--no-auth-warning", "-a", self.password] if self.password else []
        r = subprocess.run(["redis-cli", "-p", str(self.port), *auth, *args], capture_output=True, text=True)
        return r.stdout.strip()

    def kill(self):
        self.p.send_signal(signal.SIGKILL)
        self.p.wait()

    @property
    def url(self):
        return "redis://127.0.0.1:%d/%s" % (self.port, KEY)


def start_replica(redis, name, bake=None, url=None, extra=()):
    args = ["--cluster", url or redis.url, "--cluster-snapshot-every", str(SNAPSHOT_EVERY), "--cluster-timeout", "1000",
            *extra]
    if bake:
        p, port = lt.start_lucentd(os.path.join(TMP, name), *args, bake=bake)
    else:
        p, port = lt.start_lucentd(os.path.join(TMP, name), *args)
    p.name = name
    return p, port


def health(port):
    try:
        return lt.healthz(port)
    except Exception as e:  # noqa: BLE001 - a replica being restarted
        return (0, str(e))


def wait_ready(port, what):
    lt.wait_for(lambda: health(port)[0] == 200 and "read-only" not in health(port)[1], 30, what)


def request(ws, msg, timeout=20):
    ws.send_json(msg)
    end = time.time() + timeout
    while time.time() < end:
        m = ws.recv_json()
        if m.get("id") == msg.get("id") and m.get("type") in ("ok", "error", "state"):
            return m
    return {}


def state_of(port):
    ws = RawWS(port, timeout=20)
    ws.hello()
    st = request(ws, {"type": "state.get", "id": "st"})
    ws.close()
    st.pop("id", None)
    return st


def light(lid, x, intensity=1.0):
    return {"id": lid, "type": "point", "position": [x, 0.4, 0.25], "intensity": intensity}


def pipelined(port, msgs, out):
    """Sends every message at once, then collects the replies by id into out."""
    ws = RawWS(port, timeout=30)
    ws.hello(client="writer-%d" % port)
    for m in msgs:
        ws.send_json(m)
    want = {m["id"] for m in msgs}
    end = time.time() + 30
    while want and time.time() < end:
        m = ws.recv_json()
        if m.get("id") in want and m.get("type") in ("ok", "error"):
            out[m["id"]] = m
            want.discard(m["id"])
    ws.close()


def converged_lightmap(port, revision):
    """The f32 lightmap of the converged keyframe of exactly `revision`."""
    ws = RawWS(port, timeout=30)
    ws.hello()
    request(ws, {"type": "subscribe", "id": 1, "stream": "lightmap", "encoding": "f32"})
    ws.send_json({"type": "snapshot", "id": 2})  # the subscription's keyframe may have come before its ok
    end, rid = time.time() + 40, 10
    try:
        while time.time() < end:
            ws.s.settimeout(max(0.01, end - time.time()))
            try:
                op, data = ws.recv_frame()
            except (socket.timeout, TimeoutError):
                break
            if op != 2:
                continue
            f = parse_frame(data)
            if f["revision"] > revision:
                return None
            if f["flags"] & 1 and f["revision"] == revision and f["converged"]:
                lm = array.array("f")
                lm.frombytes(frame_payload(data))
                return lm
            if f["revision"] == revision:
                rid += 1
                time.sleep(0.2)
                ws.send_json({"type": "snapshot", "id": rid})  # a keyframe of what is newest now
    finally:
        ws.close()
    return None


def same_everywhere(ports, what):
    """Waits until every replica shows the same revision, then checks states and lightmaps."""
    def revs():
        return [state_of(p).get("revision") for p in ports]
    lt.wait_for(lambda: len(set(revs())) == 1, 30, "%s: every replica on one revision" % what)
    states = [state_of(p) for p in ports]
    rev = states[0].get("revision")
    check(all(s == states[0] for s in states), "%s: identical state on %d replicas at revision %s" % (
        what, len(ports), rev))
    maps = [converged_lightmap(p, rev) for p in ports]
    check(all(m is not None for m in maps), "%s: a converged lightmap of revision %s from every replica" % (
        what, rev))
    if all(m is not None for m in maps):
        check(all(m.tobytes() == maps[0].tobytes() for m in maps),
              "%s: converged lightmaps bit-identical on every replica (%d floats, mean %.4f)" % (
                  what, len(maps[0]), sum(maps[0]) / max(1, len(maps[0]))))
    return states[0]


def case_converge(redis, replicas):
    ports = [port for _, port in replicas]
    for p in ports:
        wait_ready(p, "replica on port %d ready" % p)
    # Seed the light every replica will remove at once.
    ws = RawWS(ports[0], timeout=20)
    ws.hello()
    ok = request(ws, {"type": "light.set", "id": 1, "light": light("race", 0.2)})
    ws.close()
    check(ok.get("type") == "ok", "converge: light.set acknowledged: %s" % ok)
    results = [dict() for _ in ports]
    threads = []
    for k, port in enumerate(ports):
        msgs = [{"type": "light.set", "id": "r%d-%d" % (k, i), "light": light("own-%d" % k, 0.1 + 0.02 * i, 1 + i)}
                for i in range(8)]
        msgs += [{"type": "light.set", "id": "r%d-shared" % k, "light": light("shared", 0.3 + 0.05 * k)},
                 {"type": "light.remove", "id": "r%d-race" % k, "light_id": "race"}]
        threads.append(threading.Thread(target=pipelined, args=(port, msgs, results[k])))
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    replies = [m for r in results for m in r.values()]
    oks = [m for m in replies if m.get("type") == "ok"]
    check(len(replies) == 3 * 10, "converge: all %d changes answered (%d)" % (30, len(replies)))
    revs = [m["revision"] for m in oks]
    check(len(set(revs)) == len(revs), "converge: every ok has its own revision (%d oks)" % len(oks))
    for k, r in enumerate(results):
        own = [r["r%d-%d" % (k, i)].get("revision", 0) for i in range(8) if "r%d-%d" % (k, i) in r]
        check(own == sorted(own) and len(own) == 8, "converge: replica %d's oks in its clients' order %s" % (k, own))
    race = [r.get("r%d-race" % k, {}) for k, r in enumerate(results)]
    check(sorted(m.get("type", "") + ":" + m.get("code", "") for m in race) == ["error:unknown_id"] * 2 + ["ok:"],
          "converge: one racing remove wins, the others get unknown_id: %s" % race)
    st = same_everywhere(ports, "converge")
    ids = sorted(li["id"] for li in st.get("lights", []))
    check("race" not in ids and "shared" in ids and all("own-%d" % k in ids for k in range(3)),
          "converge: the state holds every replica's lights, without the removed one: %s" % ids)
    check(st.get("revision", 0) >= max(revs), "converge: the final revision %s covers every ok (max %s)" % (
        st.get("revision"), max(revs)))
    return max(revs)


def case_kill9(redis, replicas):
    p, port = replicas[2]
    p.send_signal(signal.SIGKILL)
    p.wait()
    ws = RawWS(replicas[0][1], timeout=20)
    ws.hello()
    acked = [request(ws, {"type": "light.set", "id": i, "light": light("after-kill", 0.1 + 0.01 * i)})
             for i in range(5)]
    ws.close()
    check(all(a.get("type") == "ok" for a in acked), "kill9: changes acknowledged while a replica is down")
    replicas[2] = start_replica(redis, "r2b")
    wait_ready(replicas[2][1], "kill9: the restarted replica ready")
    st = state_of(replicas[2][1])
    check(st.get("revision", 0) >= acked[-1].get("revision", 1 << 60),
          "kill9: the restarted replica is at revision %s >= the last ok %s when /healthz says ok" % (
              st.get("revision"), acked[-1].get("revision")))
    same_everywhere([port for _, port in replicas], "kill9")


def case_redis_down(redis, replicas):
    ports = [port for _, port in replicas]
    ws = RawWS(ports[1], timeout=20)
    ws.hello()
    last = request(ws, {"type": "light.set", "id": 1, "light": light("before-crash", 0.15, 2.0)})
    check(last.get("type") == "ok", "redis_down: a change acknowledged before Redis dies")
    redis.kill()  # SIGKILL: only what the AOF fsync'd survives
    lt.wait_for(lambda: all("read-only" in health(p)[1] for p in ports), 20, "every replica read-only")
    check(all(health(p)[0] == 200 for p in ports), "redis_down: /healthz 200 read-only on every replica")
    st = request(ws, {"type": "state.get", "id": 2})
    check(st.get("type") == "state" and st.get("revision") == last.get("revision"),
          "redis_down: state.get still answers (revision %s)" % st.get("revision"))
    ref = request(ws, {"type": "light.set", "id": 3, "light": light("refused", 0.2)})
    check(ref.get("type") == "error" and ref.get("code") == "read_only",
          "redis_down: a change is refused with read_only: %s" % ref)
    redis.start()
    for p in ports:
        wait_ready(p, "redis_down: replica on port %d writable again" % p)
    again = request(ws, {"type": "light.set", "id": 4, "light": light("after-restart", 0.25)})
    check(again.get("type") == "ok" and again.get("revision", 0) > last.get("revision", 0),
          "redis_down: changes work again after Redis restarts (revision %s)" % again.get("revision"))
    ws.close()
    st = same_everywhere(ports, "redis_down")
    ids = [li["id"] for li in st.get("lights", [])]
    check("before-crash" in ids and "refused" not in ids and "after-restart" in ids,
          "redis_down: the change acknowledged before the crash is kept, the refused one absent")


def case_late(redis, replicas):
    ws = RawWS(replicas[0][1], timeout=20)
    ws.hello()
    for i in range(2 * SNAPSHOT_EVERY + 3):  # past two snapshots: the log is trimmed
        request(ws, {"type": "light.set", "id": i, "light": light("late", 0.1 + 0.005 * i)})
    ws.close()
    first = redis.cli("XRANGE", KEY, "-", "+", "COUNT", "1").split("\n")[0]
    check(first not in ("", "0-1"), "late: the log was trimmed behind a snapshot (first entry %s)" % first)
    replicas.append(start_replica(redis, "late"))
    wait_ready(replicas[-1][1], "late: the new replica ready")
    check(lt.metric(replicas[-1][1], "lucent_cluster_snapshots_loaded_total", 0) >= 1,
          "late: the new replica started from a snapshot")
    same_everywhere([port for _, port in replicas], "late")


def case_other_bake(redis):
    other = os.path.join(TMP, "other.lcb")
    cornell = os.path.join(lt.SOURCE_DIR, "scenes", "cornell-box", "cornell-box.obj")
    subprocess.run([lt.LUCENT_BAKE, "bake", cornell, "-o", other, "--atlas-size", "32", "--surfels", "2048",
                    "--grid-max-samples", "256", "--quiet", "--no-write-glb"], check=True)
    p, port = start_replica(redis, "other", bake=other)
    try:
        lt.wait_for(lambda: health(port)[0] == 503 and "bake" in health(port)[1], 20, "other bake refused")
        check("every replica needs the same bake" in health(port)[1],
              "other_bake: /healthz 503 names the bakes: %s" % health(port)[1].strip()[:160])
    finally:
        stop(p)


def case_other_limits(redis):
    """A change that fits one replica's --max-lights but not another's would apply on one and be
    skipped on the other: replicas with other limits are refused like another bake."""
    p, port = start_replica(redis, "limits", extra=("--max-lights", "7", "--fsync", "everysec"))
    try:
        lt.wait_for(lambda: health(port)[0] == 503 and "limits" in health(port)[1], 20, "other limits refused")
        check("lights=7" in health(port)[1] and "--max-lights" in health(port)[1],
              "other_limits: /healthz 503 names both limits: %s" % health(port)[1].strip()[:200])
    finally:
        stop(p)
    check("--fsync is ignored with --cluster" in p.log.text(), "other_limits: --fsync said to be ignored")


def case_password():
    redis = Redis("redis-auth", password="s3cret:pw")
    redis.start()
    good = "redis://:s3cret%%3Apw@127.0.0.1:%d/%s" % (redis.port, KEY)
    bad = "redis://:wrong@127.0.0.1:%d/%s" % (redis.port, KEY)
    p1, port1 = start_replica(redis, "auth-good", url=good)
    p2, port2 = start_replica(redis, "auth-bad", url=bad)
    try:
        wait_ready(port1, "password: the replica with the right password ready")
        ws = RawWS(port1, timeout=20)
        ws.hello()
        ok = request(ws, {"type": "light.set", "id": 1, "light": light("auth", 0.2)})
        ws.close()
        check(ok.get("type") == "ok", "password: a change through an authenticated log: %s" % ok)
        lt.wait_for(lambda: "refused us" in health(port2)[1], 20, "the wrong password named")
        check(health(port2)[0] == 503, "password: a wrong password keeps the replica starting (503): %s" % (
            health(port2)[1].strip()[:160]))
    finally:
        stop(p1)
        stop(p2)
        redis.p.terminate()
        redis.p.wait()


def case_lost_log():
    """Redis restarts empty (its AOF lost) and a fresh replica refills the log past where a
    stopped replica stood: that replica must not read the new history on as if it were its own."""
    redis = Redis("redis-lost")
    redis.start()
    a, pa = start_replica(redis, "lost-a")
    b, pb = start_replica(redis, "lost-b")
    c = None
    try:
        wait_ready(pa, "lost_log: replica a ready")
        wait_ready(pb, "lost_log: replica b ready")
        ws = RawWS(pa, timeout=20)
        ws.hello()
        for i in range(3):
            request(ws, {"type": "light.set", "id": i, "light": light("old-%d" % i, 0.1 + 0.05 * i)})
        ws.close()
        lt.wait_for(lambda: state_of(pb).get("revision", 0) >= 3, 20, "lost_log: b at revision 3")
        b.send_signal(signal.SIGSTOP)  # b sees none of what follows until it runs again
        redis.kill()
        shutil.rmtree(redis.dir)
        os.makedirs(redis.dir)
        redis.start()
        c, pc = start_replica(redis, "lost-c")  # an empty log: c starts from the bake
        wait_ready(pc, "lost_log: the fresh replica c ready")
        ws = RawWS(pc, timeout=20)
        ws.hello()
        for i in range(6):
            request(ws, {"type": "light.set", "id": i, "light": light("new-%d" % i, 0.3 + 0.05 * i)})
        ws.close()
        b.send_signal(signal.SIGCONT)
        lt.wait_for(lambda: health(pb)[0] == 503, 20, "lost_log: b unavailable")
        check("another entry at revision 3" in health(pb)[1],
              "lost_log: b names the other history: %s" % health(pb)[1].strip()[:200])
        lt.wait_for(lambda: health(pa)[0] == 503, 20, "lost_log: a unavailable")
        check("lost acknowledged entries" in health(pa)[1],
              "lost_log: a, which saw the empty log, says so: %s" % health(pa)[1].strip()[:200])
        ids = [li["id"] for li in state_of(pb).get("lights", [])]
        check("old-2" in ids and "new-5" not in ids, "lost_log: b kept its own state (%s)" % ids)
        check(health(pc)[0] == 200, "lost_log: c serves the new history")
    finally:
        b.send_signal(signal.SIGCONT)
        for p in (a, b, c):
            if p:
                stop(p)
        redis.p.terminate()
        redis.p.wait()


def main():
    redis = Redis()
    redis.start()
    replicas = []
    try:
        replicas = [start_replica(redis, "r%d" % k) for k in range(3)]
        case_converge(redis, replicas)
        case_kill9(redis, replicas)
        case_redis_down(redis, replicas)
        case_late(redis, replicas)
        case_other_bake(redis)
        case_other_limits(redis)
        case_password()
        case_lost_log()
    finally:
        for p, _ in replicas:
            check(stop(p) == 0, "replica %s: clean stop" % p.name)
        if redis.p and redis.p.poll() is None:
            redis.p.terminate()
            redis.p.wait()
    if FAILS:
        print("%d check(s) failed; logs in %s" % (len(FAILS), TMP), file=sys.stderr)
        sys.exit(1)
    shutil.rmtree(TMP, ignore_errors=True)
    print("daemon_cluster: all checks passed")


if __name__ == "__main__":
    main()
