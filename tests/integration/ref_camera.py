#!/usr/bin/python3
"""lucent-ref camera against closed forms and on the embedded Cornell box.

A scene baked here: a 20 m diffuse floor (albedo rho) and a small upward-facing lamp of albedo
0 lying 2 cm above it. Pixels are classified by where the rays through their four corners meet
the planes (the regions are convex, so the whole pixel is inside when its corners are), with
the camera's formulas written out again here (three.js's PerspectiveCamera + lookAt):
  - floor pixels far from the lamp see L = rho (E cos(theta) / pi + L_env) exactly: the sun by
    one shadow ray, the constant sky by cosine sampling where every path escapes;
  - lamp pixels see the state's emission (material.set overrides the bake's), without a state
    the bake's; pixels past the floor's far edge see the environment (or black);
  - --max-depth 0 leaves emitters and the environment only;
  - the PNG is round(255 sRGB(tonemap(exposure L))) of the EXR, for none and neutral.
Cornell (build/cornell.lcb): deterministic for a seed on 1 and 2 threads, the lamp's pixels
are its emission (exactly at --max-depth 0; plus its small reflection otherwise), two seeds
differ by what the reported standard error predicts, a placed object shows, and bad flags
exit 2 naming the flag."""
import math
import os
import struct
import subprocess
import sys
import tempfile
import zlib

BIN = os.environ.get("LUCENT_BINARY_DIR", "")
REF = os.path.join(BIN, "bin", "lucent-ref")
BAKE = os.environ.get("LUCENT_BAKE", "")
CORNELL = os.path.join(BIN, "cornell.lcb")
FAILS = []


def check(cond, msg):
    if not cond:
        FAILS.append(msg)
        print("FAIL:", msg, file=sys.stderr)
    return cond


# --- image readers (independent of OpenImageIO) ---------------------------------------------


def read_exr(path):
    """Scanline OpenEXR (float or half; no, ZIPS or ZIP compression) -> (w, h, {'R': [...], ...})."""
    d = open(path, "rb").read()
    assert d[:4] == b"\x76\x2f\x31\x01", "not an OpenEXR file"
    pos, attrs = 8, {}
    while d[pos] != 0:
        e = d.index(b"\0", pos)
        name = d[pos:e].decode()
        pos = d.index(b"\0", e + 1) + 1
        (size,) = struct.unpack_from("<i", d, pos)
        attrs[name] = d[pos + 4:pos + 4 + size]
        pos += 4 + size
    pos += 1
    chans, cl, p = [], attrs["channels"], 0
    while cl[p] != 0:
        e = cl.index(b"\0", p)
        (ptype,) = struct.unpack_from("<i", cl, e + 1)
        chans.append((cl[p:e].decode(), ptype))
        p = e + 17
    comp = attrs["compression"][0]
    x0, y0, x1, y1 = struct.unpack("<4i", attrs["dataWindow"])
    w, h = x1 - x0 + 1, y1 - y0 + 1
    lines = {0: 1, 2: 1, 3: 16}[comp]
    offsets = struct.unpack_from("<%dQ" % ((h + lines - 1) // lines), d, pos)
    out = {c: [0.0] * (w * h) for c, _ in chans}
    for off in offsets:
        y, size = struct.unpack_from("<ii", d, off)
        data = d[off + 8:off + 8 + size]
        nl = min(lines, y1 - y + 1)
        raw_len = sum(w * (2 if t == 1 else 4) for _, t in chans) * nl
        if comp != 0 and size < raw_len:  # else the chunk is stored raw
            t = bytearray(zlib.decompress(data))
            for i in range(1, len(t)):
                t[i] = (t[i - 1] + t[i] - 128) & 0xFF
            half = (len(t) + 1) // 2
            u = bytearray(len(t))
            u[0::2], u[1::2] = t[:half], t[half:]
            data = bytes(u)
        q = 0
        for line in range(nl):
            row = (y - y0 + line) * w
            for c, t in chans:
                fmt, n = ("<%de" % w, 2) if t == 1 else ("<%df" % w, 4)
                out[c][row:row + w] = struct.unpack_from(fmt, data, q)
                q += n * w
    return w, h, out


def read_png(path):
    """8-bit RGB(A) non-interlaced PNG -> (w, h, channels, bytes)."""
    d = open(path, "rb").read()
    assert d[:8] == b"\x89PNG\r\n\x1a\n", "not a PNG"
    pos, idat = 8, b""
    while pos < len(d):
        (n,) = struct.unpack_from(">I", d, pos)
        kind, body = d[pos + 4:pos + 8], d[pos + 8:pos + 8 + n]
        pos += 12 + n
        if kind == b"IHDR":
            w, h, depth, ctype, _, _, interlace = struct.unpack(">IIBBBBB", body)
            assert depth == 8 and ctype in (2, 6) and interlace == 0, (depth, ctype, interlace)
        elif kind == b"IDAT":
            idat += body
    bpp = 3 if ctype == 2 else 4
    raw, stride = zlib.decompress(idat), w * bpp
    out, prev = bytearray(), bytearray(stride)
    for j in range(h):
        f = raw[j * (stride + 1)]
        line = bytearray(raw[j * (stride + 1) + 1:(j + 1) * (stride + 1)])
        for i in range(stride):
            a = line[i - bpp] if i >= bpp else 0
            b = prev[i]
            c = prev[i - bpp] if i >= bpp else 0
            if f == 1:
                line[i] = (line[i] + a) & 0xFF
            elif f == 2:
                line[i] = (line[i] + b) & 0xFF
            elif f == 3:
                line[i] = (line[i] + (a + b) // 2) & 0xFF
            elif f == 4:
                pp = a + b - c
                pa, pb, pc = abs(pp - a), abs(pp - b), abs(pp - c)
                line[i] = (line[i] + (a if pa <= pb and pa <= pc else b if pb <= pc else c)) & 0xFF
        out += line
        prev = line
    return w, h, bpp, bytes(out)


# --- the camera, written out again ------------------------------------------------------------


def sub(a, b):
    return [a[0] - b[0], a[1] - b[1], a[2] - b[2]]


def cross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def norm(a):
    n = math.sqrt(sum(x * x for x in a))
    return [x / n for x in a]


def corner_rays(eye, target, fov, w, h, up=(0, 1, 0)):
    """rays(i, j): the directions through pixel (i, j)'s four corners (three.js conventions)."""
    f = norm(sub(target, eye))
    r = norm(cross(f, list(up)))
    u = cross(r, f)
    ty = math.tan(math.radians(fov) / 2)
    tx = ty * w / h

    def ray(px, py):
        x, y = 2 * px / w - 1, 1 - 2 * py / h
        return norm([f[k] + x * tx * r[k] + y * ty * u[k] for k in range(3)])

    return lambda i, j: [ray(i + a, j + b) for a, b in ((0, 0), (1, 0), (0, 1), (1, 1))]


def hit_plane_y(eye, d, y):
    """Where the ray meets the plane Y = y (None behind the eye or parallel)."""
    if abs(d[1]) < 1e-12:
        return None
    t = (y - eye[1]) / d[1]
    return None if t <= 0 else [eye[0] + t * d[0], y, eye[2] + t * d[2]]


def run(args, want=0, what="", command="camera"):
    p = subprocess.run([REF] + ([command] if command else []) + args, capture_output=True, text=True, timeout=600)
    check(p.returncode == want, "%s: lucent-ref %s exited %d, expected %d: %s" %
          (what, " ".join(args), p.returncode, want, p.stderr[-600:]))
    return p


def lum(c, k):
    return 0.2126 * c["R"][k] + 0.7152 * c["G"][k] + 0.0722 * c["B"][k]


def srgb8(v):
    v = min(max(v, 0.0), 1.0)
    e = 12.92 * v if v <= 0.0031308 else 1.055 * v ** (1 / 2.4) - 0.055
    return int(math.floor(255 * e + 0.5))


def neutral(c):
    """Khronos PBR Neutral (three.js NeutralToneMapping), from its published formula."""
    start, desat = 0.8 - 0.04, 0.15
    x = min(c)
    off = x - 6.25 * x * x if x < 0.08 else 0.04
    c = [v - off for v in c]
    peak = max(c)
    if peak < start:
        return c
    d = 1 - start
    new_peak = 1 - d * d / (peak + d - start)
    c = [v * new_peak / peak for v in c]
    g = 1 - 1 / (desat * (peak - new_peak) + 1)
    return [v * (1 - g) + new_peak * g for v in c]


# --- the closed-form scene ----------------------------------------------------------------------

RHO = (0.6, 0.5, 0.4)
SUN_LUX, THETA = 3.0, math.radians(40)
ENV = (0.2 * 2, 0.3 * 2, 0.4 * 2)  # colour x intensity
LAMP_BAKE, LAMP_STATE = (5.0, 5.0, 5.0), (3.0, 2.0, 1.0)
LAMP_X, LAMP_Z = (1.0, 2.0), (-1.0, 0.0)
EYE, TARGET, FOV, W, H = (0.0, 2.0, 4.0), (0.0, 0.0, 0.0), 50.0, 64, 48

OBJ = """mtllib scene.mtl
o floor
usemtl floor
v -10 0 -10
v -10 0 10
v 10 0 10
v 10 0 -10
f 1 2 3 4
o lamp
usemtl lamp
v 1 0.02 -1
v 1 0.02 0
v 2 0.02 0
v 2 0.02 -1
f 5 6 7 8
"""
MTL = "newmtl floor\nKd %g %g %g\nKe 0 0 0\nnewmtl lamp\nKd 0 0 0\nKe %g %g %g\n" % (RHO + LAMP_BAKE)


def state_json(sun=True, env=True):
    light = ('{"id":"sun","type":"directional","color":[1,1,1],"intensity":%r,"direction":[%r,%r,0]}' %
             (SUN_LUX, math.sin(THETA), -math.cos(THETA)))
    envj = ('{"type":"constant","color":[0.2,0.3,0.4],"intensity":2}' if env else '{"type":"none"}')
    return ('{"type":"state","revision":3,"lights":[%s],"objects":[],"materials":[{"name":"floor","emission":[0,0,0]},'
            '{"name":"lamp","emission":[%g,%g,%g]}],"environment":%s,"settings":{}}' %
            (light if sun else "", *LAMP_STATE, envj))


def classify():
    """{(i, j): 'floor' | 'lamp' | 'sky'} for the pixels wholly inside one region."""
    rays = corner_rays(EYE, TARGET, FOV, W, H)
    out = {}
    for j in range(H):
        for i in range(W):
            ds = rays(i, j)
            floor = [hit_plane_y(EYE, d, 0.0) for d in ds]
            lamp = [hit_plane_y(EYE, d, 0.02) for d in ds]
            if all(p and LAMP_X[0] < p[0] < LAMP_X[1] and LAMP_Z[0] < p[2] < LAMP_Z[1] for p in lamp):
                out[(i, j)] = "lamp"
            elif all(p and p[2] < -10 for p in floor):
                out[(i, j)] = "sky"
            elif all(p and abs(p[0]) < 10 and abs(p[2]) < 10 and
                     math.hypot(max(LAMP_X[0] - p[0], 0, p[0] - LAMP_X[1]),
                                max(LAMP_Z[0] - p[2], 0, p[2] - LAMP_Z[1])) > 1.0 for p in floor):
                out[(i, j)] = "floor"
    return out


def expect_regions(exr, regions, want, what, tol):
    """Every classified pixel within tol (relative, absolute below 1) of want[region]."""
    if not check(os.path.exists(exr), "%s: no %s" % (what, exr)):
        return
    w, h, c = read_exr(exr)
    check((w, h) == (W, H), "%s: %dx%d image" % (what, w, h))
    worst, count = 0.0, {}
    for (i, j), reg in regions.items():
        k = j * w + i
        for ch, e in zip("RGB", want[reg]):
            err = abs(c[ch][k] - e) / max(1.0, abs(e))
            if err > worst:
                worst = err
            if not check(err <= tol, "%s: %s pixel (%d, %d) %s = %.7g, expected %.7g" %
                         (what, reg, i, j, ch, c[ch][k], e)):
                return
        count[reg] = count.get(reg, 0) + 1
    print("%s: %s pixels match (worst relative error %.2g)" % (what, count, worst))


def test_closed_forms(tmp):
    with open(os.path.join(tmp, "scene.obj"), "w") as f:
        f.write(OBJ)
    with open(os.path.join(tmp, "scene.mtl"), "w") as f:
        f.write(MTL)
    lcb = os.path.join(tmp, "scene.lcb")
    p = subprocess.run([BAKE, "bake", os.path.join(tmp, "scene.obj"), "-o", lcb, "--quality", "draft",
                        "--atlas-size", "32", "--no-write-glb", "--quiet"], capture_output=True, text=True,
                       timeout=600)
    if not check(p.returncode == 0, "bake of the closed-form scene: %s" % p.stderr[-400:]):
        return
    regions = classify()
    n = {r: sum(1 for v in regions.values() if v == r) for r in ("floor", "lamp", "sky")}
    check(n["floor"] > 500 and n["lamp"] > 10 and n["sky"] >= 64, "pixel classes %s" % n)
    # the lamp (x in 1..2) lies right of the view's centre line: three.js's +x is the image's right
    check(all(i > W // 2 for (i, j), r in regions.items() if r == "lamp"), "the lamp is not on the right")
    states = {}
    for name, sun, env in (("full", True, True), ("sun", True, False)):
        states[name] = os.path.join(tmp, name + ".json")
        with open(states[name], "w") as f:
            f.write(state_json(sun, env))
    cam = ["--eye", "%g,%g,%g" % EYE, "--target", "%g,%g,%g" % TARGET, "--fov", "%g" % FOV,
           "--width", str(W), "--height", str(H), "--spp", "4", "--quiet"]
    direct = [r * SUN_LUX * math.cos(THETA) / math.pi for r in RHO]
    full = os.path.join(tmp, "full.exr")
    run([lcb, "--state", states["full"], "--exr", full, "--png", os.path.join(tmp, "none.png"),
         "--tonemap", "none", "--exposure", "0.5"] + cam, what="sun + sky")
    expect_regions(full, regions, {"floor": [d + r * e for d, r, e in zip(direct, RHO, ENV)], "lamp": LAMP_STATE,
                                   "sky": ENV}, "sun + sky", 1e-4)
    sun = os.path.join(tmp, "sun.exr")
    run([lcb, "--state", states["sun"], "--exr", sun, "--threads", "1"] + cam, what="sun")
    expect_regions(sun, regions, {"floor": direct, "lamp": LAMP_STATE, "sky": (0, 0, 0)}, "sun, environment none",
                   1e-4)
    bare = os.path.join(tmp, "bare.exr")
    run([lcb, "--exr", bare] + cam, what="no state")
    expect_regions(bare, regions, {"floor": (0, 0, 0), "lamp": LAMP_BAKE, "sky": (0, 0, 0)},
                   "no --state (the bake's emission, no lights)", 1e-6)
    depth0 = os.path.join(tmp, "depth0.exr")
    run([lcb, "--state", states["full"], "--exr", depth0, "--max-depth", "0"] + cam, what="max-depth 0")
    expect_regions(depth0, regions, {"floor": (0, 0, 0), "lamp": LAMP_STATE, "sky": ENV}, "--max-depth 0", 1e-6)
    # the PNGs: the tone map of the EXR's values, 8-bit sRGB
    run([lcb, "--state", states["full"], "--exr", full, "--png", os.path.join(tmp, "neutral.png"),
         "--tonemap", "neutral", "--exposure", "2"] + cam, what="neutral")
    w, h, c = read_exr(full)
    for png, tm in (("none.png", lambda v: [min(max(0.5 * x, 0), 1) for x in v]),
                    ("neutral.png", lambda v: neutral([2 * x for x in v]))):
        pw, ph, bpp, px = read_png(os.path.join(tmp, png))
        if not check((pw, ph) == (w, h), "%s is %dx%d" % (png, pw, ph)):
            continue
        off = 0
        for k in range(w * h):
            want = [srgb8(x) for x in tm([c["R"][k], c["G"][k], c["B"][k]])]
            got = list(px[k * bpp:k * bpp + 3])
            if want != got:
                off += 1
                check(max(abs(a - b) for a, b in zip(want, got)) <= 1, "%s pixel %d: %s, expected %s" %
                      (png, k, got, want))
        check(off <= w * h // 1000, "%s: %d pixels off by one" % (png, off))
        print("%s: every pixel = round(255 sRGB(tonemap)) (%d off by one)" % (png, off))


# --- Cornell -------------------------------------------------------------------------------------

CEYE, CTARGET, CFOV, CW, CH = (0.278, 0.273, -0.8), (0.278, 0.273, 0.0), 39.3, 160, 120
CLAMP_LE, CLAMP_Y = (17.0, 12.0, 4.0), 0.5488


def lamp_pixels(grow=None):
    """The pixels wholly on the lamp; with grow (m), those with a corner within the lamp grown by it."""
    rays = corner_rays(CEYE, CTARGET, CFOV, CW, CH)
    g = grow or 0.0
    out = []
    for j in range(CH // 3):
        for i in range(CW):
            ps = [hit_plane_y(CEYE, d, CLAMP_Y) for d in rays(i, j)]
            inside = [p and 0.213 - g < p[0] < 0.343 + g and 0.227 - g < p[2] < 0.332 + g for p in ps]
            if (any(inside) if grow else all(inside)):
                out.append(j * CW + i)
    return out


def test_cornell(tmp):
    if not check(os.path.exists(CORNELL), "%s not built" % CORNELL):
        return
    cam = ["--eye", "%g,%g,%g" % CEYE, "--target", "%g,%g,%g" % CTARGET, "--fov", "%g" % CFOV,
           "--width", str(CW), "--height", str(CH), "--spp", "128"]
    a, b, c = (os.path.join(tmp, n + ".exr") for n in ("c1", "c1t1", "c2"))
    pa = run([CORNELL, "--exr", a, "--png", os.path.join(tmp, "c1.png"), "--tonemap", "neutral", "--threads", "2"] +
             cam, what="cornell seed 1")
    check("camera rows" in pa.stderr, "no progress on stderr: %s" % pa.stderr[-300:])
    run([CORNELL, "--exr", b, "--threads", "1", "--quiet"] + cam, what="cornell seed 1, 1 thread")
    pc = run([CORNELL, "--exr", c, "--seed", "2", "--quiet"] + cam, what="cornell seed 2")
    if FAILS:
        return
    _, _, ia = read_exr(a)
    _, _, ib = read_exr(b)
    _, _, ic = read_exr(c)
    check(ia == ib, "seed 1 on 1 and 2 threads differs")
    check(ia != ic, "seeds 1 and 2 give the same image")
    # two seeds: the mean relative difference over the lit pixels is what the reported standard
    # error predicts (E|a - b| = 2 sigma / sqrt(pi) for two independent estimates)
    noise = [float(line.split("stderr ")[1].split()[0]) for line in (pa.stderr + pc.stderr).splitlines()
             if "noise: mean relative stderr" in line]
    n = CW * CH
    ymean = sum(lum(ia, k) for k in range(n)) / n
    lit = [k for k in range(n) if lum(ia, k) > 0.05 * ymean and lum(ic, k) > 0.05 * ymean]
    mad = sum(abs(lum(ia, k) - lum(ic, k)) / (0.5 * (lum(ia, k) + lum(ic, k))) for k in lit) / len(lit)
    if check(len(noise) == 2, "no noise line: %s" % pa.stderr[-300:]):
        pred = math.sqrt(2 / math.pi) * math.sqrt(noise[0] ** 2 + noise[1] ** 2)
        check(0.6 * pred < mad < 1.4 * pred, "seeds differ by %.4f, the reported stderr (%s) predicts %.4f" %
              (mad, noise, pred))
        print("cornell: reported relative stderr %s; seeds 1 and 2 differ by %.4f (mean |a-b|/mean over %d lit "
              "pixels; predicted %.4f)" % (noise, mad, len(lit), pred))
    ya, yc = sum(lum(ia, k) for k in range(n)), sum(lum(ic, k) for k in range(n))
    check(abs(ya - yc) / ya < 0.01, "image mean luminance: seed 1 %.5f, seed 2 %.5f" % (ya / n, yc / n))
    # the lamp: its emission, plus what its albedo (0.78) reflects of the box (~1%)
    lamp = lamp_pixels()
    if check(len(lamp) > 30, "only %d lamp pixels" % len(lamp)):
        ratios = [ia[ch][k] / le for k in lamp for ch, le in zip("RGB", CLAMP_LE)]
        check(1.0 <= min(ratios) and max(ratios) < 1.03, "lamp pixels / emission in [%.4f, %.4f]" %
              (min(ratios), max(ratios)))
        d0 = os.path.join(tmp, "d0.exr")
        run([CORNELL, "--exr", d0, "--max-depth", "0", "--quiet"] + cam[:-2] + ["--spp", "4"], what="cornell depth 0")
        _, _, i0 = read_exr(d0)
        worst = max(abs(i0[ch][k] - le) / le for k in lamp for ch, le in zip("RGB", CLAMP_LE))
        check(worst < 1e-6, "--max-depth 0: lamp pixels off its emission by %.2g" % worst)
        near = set(lamp_pixels(0.01))
        lit0 = [k for k in range(CW * CH) if lum(i0, k) != 0 and k not in near]
        check(not lit0, "--max-depth 0: %d pixels away from the lamp are lit" % len(lit0))
        print("cornell: %d lamp pixels at %.4f..%.4f x the emission (exact at --max-depth 0)" %
              (len(lamp), min(ratios), max(ratios)))
    # a placed object (the bake's cube asset, 10 cm, its origin at the bottom centre) on the floor
    st = os.path.join(tmp, "cube.json")
    with open(st, "w") as f:
        f.write('{"type":"state","revision":1,"lights":[],"objects":[{"id":"c","asset":"cube",'
                '"translation":[0.42,0,0.1],"rotation":[0,0,0,1],"scale":[1,1,1],"visible":true}],'
                '"materials":[],"environment":{"type":"none"},"settings":{}}')
    obj = os.path.join(tmp, "cube.exr")
    run([CORNELL, "--state", st, "--exr", obj, "--quiet"] + cam[:-2] + ["--spp", "16"], what="cornell with a cube")
    _, _, io = read_exr(obj)
    rays = corner_rays(CEYE, CTARGET, CFOV, CW, CH)
    # the cube's front face (z = 0.05, x 0.37..0.47, y 0..0.1), seen head-on
    front = []
    for j in range(CH):
        for i in range(CW):
            ps = [[CEYE[q] + (0.05 - CEYE[2]) / d[2] * d[q] for q in range(3)] for d in rays(i, j)]
            if all(0.38 < p[0] < 0.46 and 0.01 < p[1] < 0.09 for p in ps):
                front.append(j * CW + i)
    changed = sum(1 for k in front if abs(lum(io, k) - lum(ia, k)) > 0.2 * lum(ia, k))
    check(len(front) > 20 and changed > 0.9 * len(front), "the cube: %d of its %d front pixels changed" %
          (changed, len(front)))


def test_errors(tmp):
    base = [CORNELL, "--eye", "0.278,0.273,-0.8", "--target", "0.278,0.273,0", "--png", os.path.join(tmp, "e.png"),
            "--width", "8", "--height", "6", "--spp", "1", "--quiet"]
    for extra, flag in ((["--fov", "0"], "--fov"), (["--fov", "180"], "--fov"), (["--fov", "nan"], "--fov"),
                        (["--width", "0"], "--width"), (["--height", "-3"], "--height"),
                        (["--target", "0.278,0.273,-0.8"], "--target"), (["--up", "0,0,1"], "--up"),
                        (["--eye", "1,2"], "--eye"), (["--tonemap", "aces"], "--tonemap"),
                        (["--exposure", "-1"], "--exposure"), (["--max-depth", "-1"], "--max-depth"),
                        (["--spp", "0"], "--spp"), (["--png", os.path.join(tmp, "e.jpg")], "--png")):
        p = run(base + extra, want=2, what="refusal of %s" % flag)
        check(flag in p.stderr, "%s: stderr does not name %s: %s" % (" ".join(extra), flag, p.stderr[-300:]))
    no_out = [a for a in base if not a.endswith("e.png") and a != "--png"]
    p = run(no_out, want=2, what="no output")
    check("--exr" in p.stderr and "--png" in p.stderr, "missing output: %s" % p.stderr[-300:])
    p = run([x for x in no_out if x != "--eye" and x != "0.278,0.273,-0.8"] + ["--exr", os.path.join(tmp, "e.exr")],
            want=2, what="no --eye")
    check("--eye" in p.stderr, "missing --eye: %s" % p.stderr[-300:])
    p = run(["/nonexistent.lcb"] + base[1:], want=1, what="missing bake")
    p = run(["--help"], want=0, what="--help", command=None)
    check("lucent-ref camera" in p.stdout and "--tonemap" in p.stdout, "--help lacks the camera")


def main():
    if not os.access(REF, os.X_OK) or not os.access(BAKE, os.X_OK):
        print("lucent-ref or lucent-bake not built: skip")
        return 77
    with tempfile.TemporaryDirectory() as tmp:
        test_closed_forms(tmp)
        test_errors(tmp)
        test_cornell(tmp)
    if FAILS:
        print("%d failure(s)" % len(FAILS), file=sys.stderr)
        return 1
    print("all checks passed")
    return 0


if __name__ == "__main__":
    sys.exit(main())
