#!/usr/bin/python3
"""What the replicated log adds to a change: the time from sending a `light.set` to its `ok`,
one change at a time, for

  journal     one lucentd with its local journal (--fsync always: the ok waits for fdatasync)
  cluster-1   one replica of lucentd --cluster (the ok waits for XADD with Redis's
              appendfsync always, then for the replica to read its own entry back)
  cluster-3   three replicas, changes sent to one of them, the others applying the same log

Redis runs on loopback (this machine); a network hop adds its round trips to the cluster rows.
Prints a table and writes --json. Example:

    /usr/bin/python3 tests/bench/ack_bench.py --count 300 --json /tmp/ack.json
"""
import argparse
import json
import os
import shutil
import socket
import subprocess
import sys
import tempfile
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "lib"))
import lucent_testlib as lt  # noqa: E402
from lucent_testlib import RawWS, stop  # noqa: E402


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def percentile(vals, q):
    vals = sorted(vals)
    return vals[min(len(vals) - 1, int(q * len(vals)))] if vals else None


def measure(port, count):
    ws = RawWS(port, timeout=30)
    ws.hello(client="ack-bench")
    lat = []
    for i in range(count):
        msg = {"type": "light.set", "id": i, "light": {"id": "bench", "type": "point",
                                                       "position": [0.1 + 0.001 * (i % 300), 0.4, 0.25]}}
        t0 = time.perf_counter()
        ws.send_json(msg)
        while True:
            m = ws.recv_json()
            if m.get("id") == i:
                break
        if m.get("type") != "ok":
            raise SystemExit("ack_bench: change %d refused: %s" % (i, m))
        lat.append((time.perf_counter() - t0) * 1e3)
    ws.close()
    return {"count": count, "p50_ms": percentile(lat, 0.5), "p90_ms": percentile(lat, 0.9),
            "p99_ms": percentile(lat, 0.99), "max_ms": max(lat), "mean_ms": sum(lat) / len(lat)}


def run_cluster(tmp, n_replicas, count, args):
    rport = free_port()
    rdir = os.path.join(tmp, "redis-%d" % n_replicas)
    os.makedirs(rdir)
    redis = subprocess.Popen(["redis-server", "--port", str(rport), "--bind", "127.0.0.1", "--dir", rdir,
                              "--appendonly", "yes", "--appendfsync", "always", "--save", ""],
                             stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    replicas = []
    try:
        lt.wait_for(lambda: subprocess.run(["redis-cli", "-p", str(rport), "PING"], capture_output=True,
                                           text=True).stdout.strip() == "PONG", 10, "redis-server")
        url = "redis://127.0.0.1:%d/ack-bench" % rport
        for k in range(n_replicas):
            replicas.append(lt.start_lucentd(os.path.join(tmp, "c%d-%d" % (n_replicas, k)), "--cluster", url,
                                             "--rate", "100000", bake=args.bake, lucentd=args.lucentd))
        for _, port in replicas:
            lt.wait_for(lambda: lt.healthz(port)[0] == 200, 30, "replica ready")
        return measure(replicas[0][1], count)
    finally:
        for p, _ in replicas:
            stop(p)
        redis.terminate()
        redis.wait()


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--count", type=int, default=300, help="changes per configuration (default %(default)s)")
    ap.add_argument("--bake", default=lt.CORNELL_LCB)
    ap.add_argument("--lucentd", default=lt.LUCENTD)
    ap.add_argument("--json")
    args = ap.parse_args()
    if not shutil.which("redis-server"):
        sys.exit("ack_bench: needs redis-server (scripts/setup-deps.sh installs it)")
    tmp = tempfile.mkdtemp(prefix="lucent-ack-")
    results = {}
    try:
        p, port = lt.start_lucentd(os.path.join(tmp, "journal"), "--fsync", "always", "--rate", "100000", bake=args.bake,
                                   lucentd=args.lucentd)
        try:
            results["journal"] = measure(port, args.count)
        finally:
            stop(p)
        results["cluster-1"] = run_cluster(tmp, 1, args.count, args)
        results["cluster-3"] = run_cluster(tmp, 3, args.count, args)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    print("change -> ok, one at a time, %d changes each (CPU backend, Cornell; Redis on loopback)" % args.count)
    print("%-10s %8s %8s %8s %8s" % ("config", "p50 ms", "p90 ms", "p99 ms", "max ms"))
    for name, r in results.items():
        print("%-10s %8.2f %8.2f %8.2f %8.2f" % (name, r["p50_ms"], r["p90_ms"], r["p99_ms"], r["max_ms"]))
    base = results["journal"]["p50_ms"]
    print("the log adds %.2f ms (1 replica) and %.2f ms (3 replicas) to the p50 over the local journal" % (
        results["cluster-1"]["p50_ms"] - base, results["cluster-3"]["p50_ms"] - base))
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"bench": "ack", "count": args.count, "results": results}, f, indent=2)


if __name__ == "__main__":
    main()
