#!/usr/bin/python3
"""What a renderer fetches from lucentd besides the streams (issue 15):

  scene_glb    GET /scene.glb: model/gltf-binary, a valid GLB whose triangles and bake id are
               the bake's, named by welcome.scene.geometry / bake_id; the ETag is the bake id
  assets       GET /assets/NAME.glb for every welcome.scene.asset_geometry entry; an unknown
               asset is 404
  www          a .glb under --www is served as model/gltf-binary (was 415); a file named
               scene.glb under --www does not shadow the bake's; the CSP header is strict
               (script-src 'self', no inline) and present on pages
  default_www  without --www, lucentd serves the build's viewer folder (share/lucent/www
               beside bin/) at / when it exists; --www "" serves none (404)
  passes       frames of one revision count their refinement pass up from 0 and the last
               sets converged (flags bits 8-15, bit 3)"""
import json
import os
import struct
import sys
import tempfile
import urllib.request

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "lib"))
import lucent_testlib as lt  # noqa: E402
from lucent_testlib import RawWS, stop  # noqa: E402

FAILS = []
TMP = tempfile.mkdtemp(prefix="lucent-geometry-")


def check(cond, msg):
    if not cond:
        FAILS.append(msg)
        print("FAIL:", msg, file=sys.stderr)
    return cond


def get(port, path):
    """(status, headers dict lower-case, body bytes)."""
    try:
        with urllib.request.urlopen("http://127.0.0.1:%d%s" % (port, path), timeout=20) as r:
            return r.status, {k.lower(): v for k, v in r.headers.items()}, r.read()
    except urllib.error.HTTPError as e:
        return e.code, {k.lower(): v for k, v in e.headers.items()}, e.read()


def parse_glb(data):
    """(json dict, bin bytes) of a GLB, checking its framing; raises AssertionError."""
    assert len(data) >= 20, "shorter than a GLB header"
    magic, version, length = struct.unpack_from("<III", data, 0)
    assert magic == 0x46546C67 and version == 2, "magic/version %x/%d" % (magic, version)
    assert length == len(data), "header length %d, body %d" % (length, len(data))
    jlen, jtype = struct.unpack_from("<II", data, 12)
    assert jtype == 0x4E4F534A and jlen % 4 == 0, "first chunk is not a padded JSON chunk"
    doc = json.loads(data[20:20 + jlen].decode())
    binary = b""
    if 20 + jlen < len(data):
        blen, btype = struct.unpack_from("<II", data, 20 + jlen)
        assert btype == 0x004E4942, "second chunk is not BIN"
        binary = data[28 + jlen:28 + jlen + blen]
    return doc, binary


def triangle_count(doc):
    n = 0
    for mesh in doc["meshes"]:
        for prim in mesh["primitives"]:
            n += doc["accessors"][prim["indices"]]["count"] // 3
    return n


def bake_counts():
    out = lt.subprocess.run([lt.LUCENT_BAKE, "info", lt.CORNELL_LCB, "--json"], capture_output=True, text=True,
                            check=True).stdout
    return json.loads(out)


def welcome(port):
    ws = RawWS(port)
    w = ws.hello()
    ws.close()
    return w


def case_scene_and_assets(port):
    w = welcome(port)
    scene = w.get("scene", {})
    check(scene.get("geometry") == "/scene.glb", "welcome.scene.geometry: %r" % scene.get("geometry"))
    bake_id = scene.get("bake_id")
    check(isinstance(bake_id, str) and len(bake_id) > 0, "welcome.scene.bake_id: %r" % bake_id)
    status, hdr, body = get(port, "/scene.glb")
    if not check(status == 200, "GET /scene.glb -> %d %r" % (status, body[:200])):
        return
    check(hdr.get("content-type", "").startswith("model/gltf-binary"), "content-type %r" % hdr.get("content-type"))
    check(hdr.get("etag") == '"%s"' % bake_id, "ETag %r, bake id %r" % (hdr.get("etag"), bake_id))
    check(int(hdr.get("content-length", -1)) == len(body), "content-length vs body")
    try:
        doc, _ = parse_glb(body)
    except AssertionError as e:
        check(False, "/scene.glb is not a valid GLB: %s" % e)
        return
    tris = bake_counts()["counts"]["triangles"]
    check(triangle_count(doc) == tris, "/scene.glb has %d triangles, the bake %d" % (triangle_count(doc), tris))
    extras = doc.get("asset", {}).get("extras", {}).get("lucent", {})
    check(extras.get("bake_id") == bake_id, "asset.extras.lucent.bake_id %r vs welcome %r" % (extras, bake_id))
    attrs = [p["attributes"] for m in doc["meshes"] for p in m["primitives"]]
    check(all("TEXCOORD_1" in a and "NORMAL" in a for a in attrs), "every primitive has NORMAL and TEXCOORD_1")
    assets = scene.get("asset_geometry", {})
    check(set(assets) == set(scene.get("assets", [])), "asset_geometry names %r vs assets %r" %
          (sorted(assets), scene.get("assets")))
    for name, path in assets.items():
        status, hdr, body = get(port, path)
        if check(status == 200, "GET %s -> %d" % (path, status)):
            try:
                adoc, _ = parse_glb(body)
                check(triangle_count(adoc) > 0, "%s has no triangles" % path)
            except AssertionError as e:
                check(False, "%s is not a valid GLB: %s" % (path, e))
    status, _, _ = get(port, "/assets/no-such-asset.glb")
    check(status == 404, "GET /assets/no-such-asset.glb -> %d, want 404" % status)


def case_www(state):
    www = os.path.join(TMP, "www")
    os.makedirs(www)
    with open(os.path.join(www, "index.html"), "w") as f:
        f.write("<!doctype html><title>x</title>\n")
    with open(os.path.join(www, "model.glb"), "wb") as f:
        f.write(b"glTF" + b"\0" * 16)
    with open(os.path.join(www, "scene.glb"), "wb") as f:
        f.write(b"not the bake's scene")
    p, _ = lt.start_lucentd(state, "--www", www)
    try:
        status, hdr, body = get(p.port, "/model.glb")
        check(status == 200 and hdr.get("content-type", "").startswith("model/gltf-binary"),
              "a .glb under --www: %d %r" % (status, hdr.get("content-type")))
        status, hdr, body = get(p.port, "/scene.glb")
        check(status == 200 and body[:4] == b"glTF", "a scene.glb under --www shadows the bake's (%d %r)" %
              (status, body[:20]))
        status, hdr, _ = get(p.port, "/")
        csp = hdr.get("content-security-policy", "")
        check(status == 200 and "script-src 'self'" in csp and "unsafe-inline" not in csp,
              "the page's CSP: %d %r" % (status, csp))
    finally:
        stop(p)


def case_default_www(state):
    viewer = os.path.join(lt.BINARY_DIR, "share", "lucent", "www", "index.html")
    p, _ = lt.start_lucentd(state + "-a")
    try:
        status, _, body = get(p.port, "/")
        if os.path.exists(viewer):
            check(status == 200 and body == open(viewer, "rb").read(),
                  "without --www, / is not the build's viewer (%d)" % status)
        else:
            print("no viewer in this build (node absent): default www case reduced", file=sys.stderr)
            check(status == 404, "without a viewer / answers %d" % status)
    finally:
        stop(p)
    p, _ = lt.start_lucentd(state + "-b", "--www", "")
    try:
        status, _, _ = get(p.port, "/")
        check(status == 404, '--www "" still serves / (%d)' % status)
    finally:
        stop(p)


def case_passes(port):
    ws = RawWS(port, timeout=30.0)
    ws.hello()
    ws.send_json({"type": "subscribe", "id": 2, "stream": "lightmap"})
    frames = []
    deadline = lt.time.time() + 60
    rev = None
    while lt.time.time() < deadline:
        op, data = ws.recv_frame()
        if op == 1:
            msg = json.loads(data)
            if msg.get("type") == "ok" and msg.get("id") == 3:
                rev = msg["revision"]
            if msg.get("type") == "ok" and msg.get("id") == 2:
                ws.send_json({"type": "light.set", "id": 3, "light": {
                    "id": "pass-test", "type": "point", "position": [0.2, 0.3, 0.25], "intensity": 0.5}})
            continue
        if op != 2:
            continue
        f = lt.parse_frame(data)
        if rev is not None and f["revision"] == rev:
            frames.append(f)
            if f["converged"]:
                break
    ws.close()
    passes = [f["refine_pass"] for f in frames]
    check(frames and frames[-1]["converged"], "no converged frame of revision %r (passes %r)" % (rev, passes))
    check(passes and passes == list(range(len(passes))), "passes of one revision: %r" % passes)
    check(len(passes) > 1, "progressive refinement gave a single frame (passes %r)" % passes)


def main():
    p, _ = lt.start_lucentd(os.path.join(TMP, "state"))
    try:
        case_scene_and_assets(p.port)
        case_passes(p.port)
    finally:
        stop(p)
    case_www(os.path.join(TMP, "state-www"))
    case_default_www(os.path.join(TMP, "state-default"))
    if FAILS:
        print("%d failure(s)" % len(FAILS), file=sys.stderr)
        sys.exit(1)
    print("all checks passed")


if __name__ == "__main__":
    main()
