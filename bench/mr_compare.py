#!/usr/bin/python3
"""bench/mr.sh's comparison: the irradiance a client gets at each sparse point from the
mr.vpl stream against lucent-ref mr-truth (see bench/mr.sh). Usage: mr_compare.py OUT FRAMES.
Prints tables, writes OUT/mr.json."""
import json
import math
import os
import sys


def lum(c):
    return 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]


def vpl_lines(path):
    """{after_seq: records of mrcube} from a --vpl-out file (the last frame per upload wins)."""
    out = {}
    for line in open(path):
        f = json.loads(line)
        for o in f["objects"]:
            if o["id"] == "mrcube":
                out[f["after_seq"]] = o["records"]
    return out


def client_irradiance(rec, pts):
    """E_d at each sparse point as a client's Phong term gives it there (PROTOCOL §8.7)."""
    e = []
    for i, p in enumerate(pts):
        r = rec[12 * i:12 * i + 12]
        d = [r[3 + k] - p["position"][k] for k in range(3)]
        d2 = sum(x * x for x in d)
        cos = sum(d[k] * p["normal"][k] for k in range(3)) / math.sqrt(d2) if d2 > 0 else 0
        e.append([r[k] * max(cos, 0) / d2 if d2 > 0 else 0 for k in range(3)])
    return e


def stats(a, r, se=None):
    """Relative errors of luminance over the points where the reference is above 1% of its
    brightest (dark points cannot judge a relative error; their count is reported)."""
    ya, yr = [lum(x) for x in a], [lum(x) for x in r]
    thr = 0.01 * max(yr)
    idx = [i for i in range(len(yr)) if yr[i] > thr]
    rel = sorted(abs(ya[i] - yr[i]) / yr[i] for i in idx)
    n = len(rel)
    res = {"n": n, "n_dark": len(yr) - n,
           "mean": sum(rel) / n, "p50": rel[(n - 1) // 2], "p95": rel[max(0, math.ceil(0.95 * n) - 1)],
           "bias": (sum(ya[i] for i in idx) - sum(yr[i] for i in idx)) / sum(yr[i] for i in idx)}
    if se is not None:
        res["ref_noise"] = sum(lum(se[i]) / yr[i] for i in idx) / n
    return res


def temporal(series, noise=None):
    """Mean over points of the frame-to-frame coefficient of variation of E (luminance);
    with noise (per frame per point stderr), the Monte Carlo variance is taken out."""
    n_pts = len(series[0])
    covs = []
    for i in range(n_pts):
        y = [lum(f[i]) for f in series]
        m = sum(y) / len(y)
        if m <= 0.01 * max(lum(series[0][j]) for j in range(n_pts)):
            continue
        var = sum((v - m) ** 2 for v in y) / (len(y) - 1)
        if noise is not None:
            var = max(0.0, var - sum(lum(s[i]) ** 2 for s in noise) / len(noise))
        covs.append(math.sqrt(var) / m)
    return sum(covs) / len(covs)


def main():
    out, frames = sys.argv[1], int(sys.argv[2])
    truth = json.load(open(os.path.join(out, "truth-still.json")))
    pts = truth["points"]
    full = [p["full"] for p in pts]
    vis = [p["visible"] for p in pts]
    still = vpl_lines(os.path.join(out, "still.vpl.jsonl"))
    server = client_irradiance(still[max(still)], pts)
    res = {"points": len(pts), "spp": truth["spp"],
           "i_server_vs_visible": stats(server, vis, [p["visible_stderr"] for p in pts]),
           "ii_visible_vs_full": stats(vis, full, [p["full_stderr"] for p in pts]),
           "server_vs_full": stats(server, full, [p["full_stderr"] for p in pts])}
    # per face of the cube (the axis of each point's normal): server / visible / full means
    faces = {}
    for p, e in zip(pts, server):
        k = max(range(3), key=lambda c: abs(p["normal"][c]))
        f = faces.setdefault(("+" if p["normal"][k] > 0 else "-") + "xyz"[k], [0, 0.0, 0.0, 0.0])
        f[0] += 1
        f[1] += lum(e)
        f[2] += lum(p["visible"])
        f[3] += lum(p["full"])
    res["faces"] = {k: {"points": v[0], "server": v[1] / v[0], "visible": v[2] / v[0], "full": v[3] / v[0]}
                    for k, v in sorted(faces.items())}
    nomerge = vpl_lines(os.path.join(out, "still-nomerge.vpl.jsonl"))
    res["i_nomerge_vs_visible"] = stats(client_irradiance(nomerge[max(nomerge)], pts), vis,
                                        [p["visible_stderr"] for p in pts])
    # jitter: per frame the server's E and the visible truth of that frame
    jt = [json.load(open(os.path.join(out, "truth-jitter-%d.json" % k)))["points"] for k in range(1, frames + 1)]
    for name in ("jitter", "jitter-smooth"):
        v = vpl_lines(os.path.join(out, name + ".vpl.jsonl"))
        seqs = [k for k in range(1, frames + 1) if k in v]
        res[name] = {"frames": len(seqs),
                     "cov_server": temporal([client_irradiance(v[k], pts) for k in seqs])}
        if name == "jitter":
            res[name]["cov_visible_truth"] = temporal([[p["visible"] for p in jt[k - 1]] for k in seqs],
                                                      [[p["visible_stderr"] for p in jt[k - 1]] for k in seqs])
            per = [stats(client_irradiance(v[k], pts), [p["visible"] for p in jt[k - 1]])["mean"] for k in seqs]
            res[name]["mean_error_vs_visible"] = sum(per) / len(per)
    for name in ("still", "still-zlib", "still-nomerge", "jitter"):
        s = json.loads(open(os.path.join(out, name + ".summary")).read().splitlines()[-1])
        res["summary_" + name.replace("-", "_")] = s
    json.dump(res, open(os.path.join(out, "mr.json"), "w"), indent=1)

    print("\nLightSkin at the cube's %d sparse points, Cornell box capture 256x192 (truth %d samples/point)"
          % (len(pts), truth["spp"]))
    print("%-30s %5s %6s %8s %8s %8s %8s %9s" % ("comparison", "n", "dark", "mean", "p50", "p95", "bias", "ref noise"))
    for key, label in (("i_server_vs_visible", "(i) server vs visible"),
                       ("i_nomerge_vs_visible", "(i) no merging vs visible"),
                       ("ii_visible_vs_full", "(ii) visible vs full"), ("server_vs_full", "server vs full")):
        s = res[key]
        print("%-30s %5d %6d %7.1f%% %7.1f%% %7.1f%% %+7.1f%% %8.2f%%" % (
            label, s["n"], s["n_dark"], 100 * s["mean"], 100 * s["p50"], 100 * s["p95"], 100 * s["bias"],
            100 * s.get("ref_noise", 0)))
    print("per face (mean E, W/m^2): " + ", ".join("%s %.3f/%.3f/%.3f" % (k, f["server"], f["visible"], f["full"])
                                                   for k, f in res["faces"].items()) + "  (server/visible/full)")
    j, js = res["jitter"], res["jitter-smooth"]
    print("\ntemporal stability, %d frames jittered 5 mm / 0.5 deg (coefficient of variation of E per point):" % j["frames"])
    print("  server %.2f%%, smoothing 0.5 %.2f%%, visible truth %.2f%% (noise removed); per-frame error vs visible %.1f%%"
          % (100 * j["cov_server"], 100 * js["cov_server"], 100 * j["cov_visible_truth"], 100 * j["mean_error_vs_visible"]))
    s, z = res["summary_still"], res["summary_still_zlib"]
    nm = res["summary_still_nomerge"]
    print("\nper frame: %d lights, server %.1f ms, ack p50 %.1f ms (no merging: %d lights, %.1f ms); upload %.0f B raw, "
          "%.0f B with --zlib" % (s["lights_mean"], s["server_ms_mean"], s["ack_ms"]["p50"], nm["lights_mean"],
                                   nm["server_ms_mean"], s["bytes_raw_per_frame"], z["bytes_sent_per_frame"]))
    print("\nwrote", os.path.join(out, "mr.json"))


if __name__ == "__main__":
    main()
