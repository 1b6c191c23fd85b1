"""Client messages, valid and invalid forms: §1.2, §1.3, §2.2, §2.5, §3.4, §4, §5.1, §5.2.

LUCENT_CONF_EXPECT_TRANSFER (optional, e.g. "cube=32x4"): assets the scene under test has
transfer data for, NAME=DIMSxCOEFFICIENTS separated by spaces; welcome.scene.asset_info must
then name each with those figures (run_local.sh sets it for its Cornell bake)."""
import asyncio
import json
import os

import pytest
import websockets

from conftest import RawWS, VALIDATORS, aio, controller, scene_asset

section = pytest.mark.section
P = "conf-p-"  # light ids used by the valid-form cases (removed again)


def light(**kw):
    d = {"id": P + "l", "type": "point", "position": [0.2, 0.3, 0.2], "intensity": 0.5}
    d.update(kw)
    return d


# --------------------------------------------------------------------------- valid forms

def _first_material(w, st):
    if not st["materials"]:
        pytest.skip("the scene has no materials")
    m = st["materials"][0]
    return {"type": "material.set", "material": m["name"], "emission": m["emission"]}


VALID_CHANGES = [
    ("light.set-point", "4.3", lambda w, st: {"type": "light.set", "light": light(
        id=P + "pt", color=[1, 0.9, 0.8], range=0)}),
    ("light.set-spot", "4.3", lambda w, st: {"type": "light.set", "light": light(
        id=P + "spot", type="spot", direction=[0, -1, 0], innerConeAngle=0.2, outerConeAngle=0.6, range=2)}),
    ("light.set-directional", "4.3", lambda w, st: {"type": "light.set", "light": {
        "id": P + "dir", "type": "directional", "direction": [0.3, -1, 0.2], "intensity": 0.1}}),
    ("light.set-area-quad", "4.3", lambda w, st: {"type": "light.set", "light": light(
        id=P + "quad", type="area", direction=[0, -1, 0], size=[0.1, 0.05], tangent=[1, 0, 0])}),
    ("light.set-area-disc", "4.3", lambda w, st: {"type": "light.set", "light": light(
        id=P + "disc", type="area", shape="disc", direction=[0, -1, 0], size=[0.05])}),
    ("light.set-unknown-field-ignored", "2.2", lambda w, st: {"type": "light.set", "future": {"x": 1},
                                                               "light": light(id=P + "fut", future2=3)}),
    ("light.remove", "4.4", lambda w, st: {"type": "light.remove", "light_id": P + "pt"}),
    ("object.set", "4.5", lambda w, st: {"type": "object.set", "object": {
        "id": P + "obj", "asset": scene_asset(w), "translation": [0.1, 0, 0.1], "rotation": [0, 0, 0, 2],
        "scale": [1, 1, 1], "visible": True}}),
    ("object.remove", "4.6", lambda w, st: {"type": "object.remove", "object_id": P + "obj"}),
    ("material.set", "4.7", _first_material),
    ("environment.set", "4.8", lambda w, st: {"type": "environment.set", "environment": st["environment"]}),
    ("settings.set", "4.9", lambda w, st: {"type": "settings.set", "settings": {
        k: v for k, v in st["settings"].items() if k in ("bounces", "progressive")}}),
    ("batch", "4.10", lambda w, st: {"type": "batch", "ops": [
        {"type": "light.set", "light": light(id=P + "b1")},
        {"type": "light.set", "light": light(id=P + "b2", intensity=0.25)},
        {"type": "light.remove", "light_id": P + "b1"}]}),
]


@pytest.mark.parametrize("name,sec,build", [pytest.param(n, s, b, id=n, marks=section(s)) for n, s, b in VALID_CHANGES])
@aio
async def test_valid_change(cfg, name, sec, build):
    """A valid change -> ok whose revision is exactly the previous one + 1 (a batch counts once)."""
    c = await controller(cfg)
    try:
        st = await c.request({"type": "state.get"})
        if name in ("light.remove", "object.remove"):  # make sure the target exists
            if name == "object.remove":
                await c.expect_ok(VALID_CHANGES[7][2](c.welcome, st))
            else:
                await c.expect_ok({"type": "light.set", "light": light(id=P + "pt")})
            st = await c.request({"type": "state.get"})
        msg = build(c.welcome, st)
        errs = list(VALIDATORS[msg["type"]].iter_errors(msg))
        assert not errs or name.endswith("ignored"), "suite bug: the valid form fails its schema: %r" % errs
        ok = await c.expect_ok(msg)
        assert ok["revision"] == st["revision"] + 1, "§2.6 revision %d after %d (must be +1)" % (
            ok["revision"], st["revision"])
        st2 = await c.request({"type": "state.get"})
        assert st2["revision"] == ok["revision"], "state.get revision %d != ok's %d" % (st2["revision"], ok["revision"])
        ids = [x["id"] for x in st2["lights"]]
        assert ids == sorted(ids), "§5.4 lights must be sorted by id: %r" % ids
        oids = [x["id"] for x in st2["objects"]]
        assert oids == sorted(oids), "§5.4 objects must be sorted by id: %r" % oids
        if msg["type"] == "light.set":
            got = [x for x in st2["lights"] if x["id"] == msg["light"]["id"]]
            assert got and got[0]["type"] == msg["light"]["type"], "light not in state: %r" % st2["lights"]
            for k in ("intensity", "position", "color"):
                if k in msg["light"]:
                    assert got[0].get(k) == pytest.approx(msg["light"][k], rel=1e-6), (k, got[0])
        if name == "light.remove":
            assert P + "pt" not in ids
        if name == "batch":
            assert P + "b2" in ids and P + "b1" not in ids, "batch ops not all applied: %r" % ids
        if name == "object.set":
            o = [x for x in st2["objects"] if x["id"] == P + "obj"]
            assert o and o[0]["rotation"] == pytest.approx([0, 0, 0, 1], abs=1e-6), "§4.5 rotation normalised: %r" % o
    finally:
        st = await c.request({"type": "state.get"})
        ops = [{"type": "light.remove", "light_id": x["id"]} for x in st["lights"] if x["id"].startswith(P)]
        ops += [{"type": "object.remove", "object_id": x["id"]} for x in st["objects"] if x["id"].startswith(P)]
        if ops:
            await c.request({"type": "batch", "ops": ops})
        await c.close()


VALID_OTHER = [
    ("subscribe", "4.1", {"type": "subscribe", "stream": "shgrid", "encoding": "rgba16f", "max_rate": 0.5}),
    ("unsubscribe", "4.2", {"type": "unsubscribe", "stream": "lightmap"}),
    ("snapshot", "4.12", {"type": "snapshot"}),
]


@pytest.mark.parametrize("name,sec,msg", [pytest.param(n, s, m, id=n, marks=section(s)) for n, s, m in VALID_OTHER])
@aio
async def test_valid_request(cfg, name, sec, msg):
    """subscribe / unsubscribe / snapshot -> ok carrying the current revision (unchanged)."""
    c = await controller(cfg)
    try:
        r0 = await c.revision()
        ok = await c.expect_ok(msg)
        assert ok["revision"] == r0, "ok revision %d, current %d (no change: must be equal)" % (ok["revision"], r0)
        assert await c.revision() == r0, "a non-change request changed the revision"
    finally:
        await c.close()


@section("4.11")
@aio
async def test_state_get(cfg):
    """state.get -> state (schema-valid), echoes the id; welcome revision <= state revision."""
    c = await controller(cfg)
    try:
        st = await c.request({"type": "state.get", "id": "st-1"})
        assert st["type"] == "state" and st["id"] == "st-1", st
        assert st["revision"] >= c.welcome["revision"]
    finally:
        await c.close()


@section("4.13")
@aio
async def test_ping(cfg):
    """ping -> pong with the same t (fractional too) and server_time_us, echoing the id."""
    c = await controller(cfg)
    try:
        for t in (0, 1.5, -3.25, 1234567890123):
            r = await c.request({"type": "ping", "t": t})
            assert r["type"] == "pong" and r["t"] == t, r
            assert r["server_time_us"] > 1_000_000_000 * 1_000_000, "server_time_us is not µs since 1970: %r" % r
    finally:
        await c.close()


@section("2.5")
@aio
async def test_request_ids_echoed(cfg):
    """Request ids, string 1..64 bytes or integer in [0, 2^53), are echoed exactly."""
    c = await controller(cfg)
    try:
        for rid in ("a", "x" * 64, "é" * 32, 0, 2 ** 53 - 1):
            await c.send({"type": "ping", "t": 1, "id": rid})
            r = await c.recv_json("pong")
            assert r.get("id") == rid, "id %r echoed as %r" % (rid, r.get("id"))
    finally:
        await c.close()


# --------------------------------------------------------------------------- invalid forms

LONG_ID = "x" * 65
def deep(n):
    """A ping whose extra field makes the whole message n levels deep (the object itself is 1)."""
    inner = "1"
    for _ in range(n - 1):
        inner = "[" + inner + "]"
    return '{"type":"ping","t":1,"id":"deep","x":%s}' % inner


INVALID = [
    # (case id, section, message (dict or raw text), code, accepted pointers)
    ("not-json", "5.2", '{"type": "ping", ', "bad_json", [""]),
    ("json-array", "5.2", '[{"type": "ping", "t": 1}]', "bad_json", [""]),
    ("json-string", "5.2", '"ping"', "bad_json", [""]),
    ("nan-literal", "2.2", '{"type":"light.set","light":{"id":"n","type":"point","position":[0,0,0],"intensity":NaN}}',
     "bad_json", [""]),
    ("type-missing", "4", {"t": 1}, "unknown_type", ["/type", ""]),
    ("type-unknown", "4", {"type": "frobnicate"}, "unknown_type", ["/type"]),
    ("type-not-string", "4", {"type": 7}, "unknown_type", ["/type"]),
    ("intensity-wrong-type", "4.3", {"type": "light.set", "light": light(intensity="3")}, "invalid",
     ["/light/intensity"]),
    ("intensity-nan-string", "2.2", {"type": "light.set", "light": light(intensity="NaN")}, "invalid",
     ["/light/intensity"]),
    ("intensity-1e400", "2.2", '{"type":"light.set","light":{"id":"conf-x","type":"point","position":[0,0,0],'
     '"intensity":1e400}}', "out_of_range", ["/light/intensity"]),
    ("intensity-negative", "4.3", {"type": "light.set", "light": light(intensity=-1)}, "out_of_range",
     ["/light/intensity"]),
    ("intensity-too-big", "4.3", {"type": "light.set", "light": light(intensity=2e9)}, "out_of_range",
     ["/light/intensity"]),
    ("color-component", "4.3", {"type": "light.set", "light": light(color=[1, 2e6, 1])}, "out_of_range",
     ["/light/color/1"]),
    ("color-length", "4.3", {"type": "light.set", "light": light(color=[1, 1])}, "invalid", ["/light/color"]),
    ("position-out-of-range", "4.3", {"type": "light.set", "light": light(position=[0, 2e6, 0])}, "out_of_range",
     ["/light/position/1"]),
    ("light-missing", "4.3", {"type": "light.set"}, "invalid", ["/light", ""]),
    ("light-not-object", "4.3", {"type": "light.set", "light": [1]}, "invalid", ["/light"]),
    ("point-missing-position", "4.3", {"type": "light.set", "light": {"id": "conf-x", "type": "point"}},
     "invalid", ["/light/position", "/light"]),
    ("light-type-unknown", "4.3", {"type": "light.set", "light": light(type="laser")}, "invalid", ["/light/type"]),
    ("light-id-65-bytes", "1.3", {"type": "light.set", "light": light(id=LONG_ID)}, "invalid", ["/light/id"]),
    ("light-id-empty", "4.3", {"type": "light.set", "light": light(id="")}, "invalid", ["/light/id"]),
    ("spot-outer-below-inner", "4.3", {"type": "light.set", "light": light(
        type="spot", direction=[0, -1, 0], innerConeAngle=0.5, outerConeAngle=0.4)}, "out_of_range",
     ["/light/outerConeAngle"]),
    ("spot-cone-over-90deg", "4.3", {"type": "light.set", "light": light(
        type="spot", direction=[0, -1, 0], outerConeAngle=2.0)}, "out_of_range", ["/light/outerConeAngle"]),
    ("direction-zero", "4.3", {"type": "light.set", "light": {
        "id": "conf-x", "type": "directional", "direction": [0, 0, 0]}}, ("out_of_range", "invalid"),
     ["/light/direction"]),
    ("area-size-zero", "4.3", {"type": "light.set", "light": light(
        type="area", direction=[0, -1, 0], size=[0, 1])}, "out_of_range", ["/light/size/0"]),
    ("request-id-65-bytes", "2.5", '{"type":"ping","t":1,"id":"%s"}' % LONG_ID, "invalid", ["/id"]),
    ("request-id-negative", "2.5", '{"type":"ping","t":1,"id":-1}', ("invalid", "out_of_range"), ["/id"]),
    ("request-id-2^53", "2.5", '{"type":"ping","t":1,"id":9007199254740992}', ("invalid", "out_of_range"), ["/id"]),
    ("string-257-bytes", "1.3", {"type": "light.set", "light": light(shape="q" * 257, type="area",
                                                                      direction=[0, -1, 0], size=[1, 1])},
     "invalid", ["/light/shape"]),
    ("too-deep-17", "1.3", deep(17), "too_deep", None),
    ("light.remove-unknown", "4.4", {"type": "light.remove", "light_id": "conf-does-not-exist"}, "unknown_id",
     ["/light_id"]),
    ("light.remove-missing-id", "4.4", {"type": "light.remove"}, "invalid", ["/light_id", ""]),
    ("object.set-unknown-asset", "4.5", {"type": "object.set", "object": {"id": "conf-o", "asset": "no-such-asset"}},
     "unknown_asset", ["/object/asset"]),
    ("object.set-scale-zero", "4.5", {"type": "object.set", "object": {"id": "conf-o", "asset": "no-such-asset",
                                                                       "scale": [1, 0, 1]}},
     ("out_of_range", "unknown_asset"), ["/object/scale/1", "/object/asset"]),
    ("object.set-rotation-zero", "4.5", {"type": "object.set", "object": {
        "id": "conf-o", "asset": "x", "rotation": [0, 0, 0, 0]}}, ("out_of_range", "invalid", "unknown_asset"),
     ["/object/rotation", "/object/asset"]),
    ("object.remove-unknown", "4.6", {"type": "object.remove", "object_id": "conf-does-not-exist"}, "unknown_id",
     ["/object_id"]),
    ("material.set-unknown", "4.7", {"type": "material.set", "material": "no-such-material", "emission": [0, 0, 0]},
     "unknown_material", ["/material"]),
    ("material.set-emission-negative", "4.7", {"type": "material.set", "material": "no-such-material",
                                               "emission": [0, -1, 0]},
     ("out_of_range", "unknown_material"), ["/emission/1", "/material"]),
    ("environment-type-unknown", "4.8", {"type": "environment.set", "environment": {"type": "sky"}}, "invalid",
     ["/environment/type"]),
    ("environment-sh-missing", "4.8", {"type": "environment.set", "environment": {"type": "sh"}}, "invalid",
     ["/environment/sh", "/environment"]),
    ("environment-sh-26", "4.8", {"type": "environment.set", "environment": {"type": "sh", "sh": [0] * 26}},
     "invalid", ["/environment/sh"]),
    ("environment-intensity", "4.8", {"type": "environment.set", "environment": {"type": "constant",
                                                                                 "intensity": 1e8}},
     "out_of_range", ["/environment/intensity"]),
    ("settings-bounces-17", "4.9", {"type": "settings.set", "settings": {"bounces": 17}}, "out_of_range",
     ["/settings/bounces"]),
    ("settings-bands-0", "4.9", {"type": "settings.set", "settings": {"bands": 0}}, "out_of_range",
     ["/settings/bands"]),
    ("settings-bounces-wrong-type", "4.9", {"type": "settings.set", "settings": {"bounces": "2"}}, "invalid",
     ["/settings/bounces"]),
    ("settings-progressive-wrong-type", "4.9", {"type": "settings.set", "settings": {"progressive": 1}}, "invalid",
     ["/settings/progressive"]),
    ("settings-dnrt-wrong-type", "4.9", {"type": "settings.set", "settings": {"dnrt": 1}}, "invalid",
     ["/settings/dnrt"]),
    ("settings-dnrt-blockers-wrong-type", "4.9", {"type": "settings.set", "settings": {"dnrt_blockers": "yes"}},
     "invalid", ["/settings/dnrt_blockers"]),
    ("settings-chroma-bands-over-bands", "4.9", {"type": "settings.set", "settings": {"bands": 2, "chroma_bands": 3}},
     "out_of_range", ["/settings/chroma_bands"]),
    ("subscribe-unknown-stream", "4.1", {"type": "subscribe", "stream": "video"}, "invalid", ["/stream"]),
    ("subscribe-unknown-encoding", "4.1", {"type": "subscribe", "stream": "lightmap", "encoding": "png"}, "invalid",
     ["/encoding"]),
    ("subscribe-shgrid-rgb9e5", "4.1", {"type": "subscribe", "stream": "shgrid", "encoding": "rgb9e5"}, "invalid",
     ["/encoding"]),
    ("subscribe-max-rate-0", "4.1", {"type": "subscribe", "stream": "lightmap", "max_rate": 0}, "out_of_range",
     ["/max_rate"]),
    ("subscribe-max-rate-121", "4.1", {"type": "subscribe", "stream": "lightmap", "max_rate": 121}, "out_of_range",
     ["/max_rate"]),
    ("unsubscribe-missing-stream", "4.2", {"type": "unsubscribe"}, "invalid", ["/stream", ""]),
    ("ping-missing-t", "4.13", {"type": "ping"}, "invalid", ["/t", ""]),
    ("ping-t-string", "4.13", {"type": "ping", "t": "now"}, "invalid", ["/t"]),
    ("batch-empty", "4.10", {"type": "batch", "ops": []}, "invalid", ["/ops"]),
    ("batch-not-array", "4.10", {"type": "batch", "ops": {}}, "invalid", ["/ops"]),
    ("batch-nested", "4.10", {"type": "batch", "ops": [{"type": "batch", "ops": [
        {"type": "light.set", "light": light()}]}]}, ("invalid", "unknown_type"), ["/ops/0/type", "/ops/0"]),
    ("batch-non-change-op", "4.10", {"type": "batch", "ops": [{"type": "ping", "t": 1}]},
     ("invalid", "unknown_type"), ["/ops/0/type", "/ops/0"]),
    ("batch-over-max", "1.3", {"type": "batch", "ops": [
        {"type": "light.remove", "light_id": "conf-x%d" % i} for i in range(65)]}, "limit_exceeded", ["/ops"]),
    ("hello-again", "3.2", {"type": "hello", "client": "again"}, "invalid", ["/type", ""]),
]


@pytest.mark.parametrize("msg,code,pointers", [pytest.param(m, c, p, id=n, marks=section(s))
                                               for n, s, m, c, p in INVALID])
@aio
async def test_invalid(cfg, msg, code, pointers):
    """An invalid form -> error with the documented code and a JSON pointer to the offending
    member; nothing changes (revision unchanged) and the connection stays usable (ping -> pong)."""
    c = await controller(cfg)
    try:
        r0 = await c.revision()
        codes = code if isinstance(code, tuple) else (code,)
        if isinstance(msg, dict):
            msg = dict(msg, id="bad-1")
            r = await c.request(msg)
            assert r.get("id") == "bad-1", "§2.5 the error must echo the request id: %r" % r
        else:
            await c.send(msg)
            r = await c.recv_json(pred=lambda m: m.get("type") in ("ok", "error", "state", "pong"))
        assert r["type"] == "error", "expected error %s, got %r" % ("/".join(codes), r)
        assert r["code"] in codes, "expected code %s, got %r" % ("/".join(codes), r)
        if pointers is not None:
            assert r["pointer"] in pointers, "pointer %r, expected %s" % (r["pointer"], " or ".join(map(repr, pointers)))
        await c.ping_ok()
        assert await c.revision() == r0, "§5.2 a refused request changed the revision"
    finally:
        await c.close()


@section("1.3")
@aio
async def test_depth_16_accepted(cfg):
    """Nesting of exactly 16 levels (the default limit) is accepted (the unknown field ignored)."""
    c = await controller(cfg)
    try:
        await c.send(deep(16))
        r = await c.recv_json(pred=lambda m: m.get("id") == "deep")
        assert r["type"] == "pong", "16 levels deep: %r" % r
    finally:
        await c.close()


@section("1.3")
@aio
async def test_too_large(cfg):
    """A message over limits.max_message -> error too_large, then close 1009."""
    c = await controller(cfg)
    n = c.welcome["limits"]["max_message"]
    pad = "x" * (n + 10)
    await c.send('{"type":"ping","t":1,"pad":"%s"}' % pad)
    code, msgs = await c.wait_closed()
    errs = [m for m in msgs if m.get("type") == "error"]
    assert errs and errs[0]["code"] == "too_large", "messages before close: %r" % msgs
    assert code == 1009, "close code %r, expected 1009" % code


@section("1.3")
@aio
async def test_max_message_accepted(cfg):
    """A message of exactly limits.max_message bytes is accepted."""
    c = await controller(cfg)
    try:
        n = c.welcome["limits"]["max_message"]
        head = '{"type":"ping","t":1,"id":"big","pad":"'
        msg = head + "x" * (n - len(head) - 2) + '"}'
        assert len(msg.encode()) == n
        await c.send(msg)
        r = await c.recv_json(pred=lambda m: m.get("id") == "big")
        assert r["type"] == "pong", r
    finally:
        await c.close()


@section("5.2")
@aio
async def test_bad_utf8(cfg):
    """A text frame that is not UTF-8 -> the connection closes with 1007 (bad_utf8 error optional)."""
    c = await controller(cfg)
    await c.ws.write_frame(True, 0x1, b'{"type":"ping","t":1,"x":"\xc3\x28\xff"}')
    code, msgs = await c.wait_closed()
    errs = [m for m in msgs if m.get("type") == "error"]
    assert all(e["code"] == "bad_utf8" for e in errs), "error before the close: %r" % errs
    assert not [m for m in msgs if m.get("type") == "pong"], "the invalid message was answered: %r" % msgs
    assert code == 1007, "close code %r, expected 1007" % code


@section("1.2")
@aio
async def test_binary_not_allowed(cfg):
    """A binary frame from the client -> error binary_not_allowed; the connection stays."""
    c = await controller(cfg)
    try:
        await c.send(json.dumps({"type": "ping", "t": 1}).encode())
        r = await c.recv_json()
        assert r["type"] == "error" and r["code"] == "binary_not_allowed", r
        await c.ping_ok()
    finally:
        await c.close()


@section("1.2")
@aio
async def test_fragmented_text(cfg):
    """A text message split over continuation frames is one message (RFC 6455)."""
    c = await controller(cfg)
    try:
        await c.ws.send(iter(['{"type":"ping",', '"t":7,', '"id":"frag"}']))
        r = await c.recv_json(pred=lambda m: m.get("id") == "frag")
        assert r["type"] == "pong" and r["t"] == 7, r
    finally:
        await c.close()


# --------------------------------------------------------------------------- DNRT (issue 17)

@section("4.9")
@aio
async def test_settings_dnrt(cfg):
    """settings.set dnrt / dnrt_blockers -> ok; state.get reports the new values (§5.4: every
    settings field) and leaves the other settings as they were. The settings are restored."""
    c = await controller(cfg)
    st0 = await c.request({"type": "state.get"})
    s0 = st0["settings"]
    try:
        assert isinstance(s0.get("dnrt"), bool) and isinstance(s0.get("dnrt_blockers"), bool), (
            "§5.4 state.settings must report dnrt and dnrt_blockers: %r" % s0)
        for dnrt, blockers in ((not s0["dnrt"], s0["dnrt_blockers"]), (s0["dnrt"], not s0["dnrt_blockers"]),
                               (not s0["dnrt"], not s0["dnrt_blockers"])):
            ok = await c.expect_ok({"type": "settings.set", "settings": {"dnrt": dnrt, "dnrt_blockers": blockers}})
            st = await c.request({"type": "state.get"})
            assert st["revision"] == ok["revision"], (st["revision"], ok["revision"])
            got = st["settings"]
            assert got["dnrt"] is dnrt and got["dnrt_blockers"] is blockers, (
                "settings.set dnrt=%r dnrt_blockers=%r, state says %r" % (dnrt, blockers, got))
            rest = {k: v for k, v in got.items() if k not in ("dnrt", "dnrt_blockers")}
            assert rest == {k: v for k, v in s0.items() if k not in ("dnrt", "dnrt_blockers")}, (
                "settings.set of the dnrt fields changed other settings: %r -> %r" % (s0, got))
        # one field alone changes only that field
        await c.expect_ok({"type": "settings.set", "settings": {"dnrt": s0["dnrt"]}})
        got = (await c.request({"type": "state.get"}))["settings"]
        assert got["dnrt"] is s0["dnrt"] and got["dnrt_blockers"] is (not s0["dnrt_blockers"]), got
    finally:
        await c.request({"type": "settings.set", "settings": {"dnrt": s0.get("dnrt", True),
                                                              "dnrt_blockers": s0.get("dnrt_blockers", True)}})
        await c.close()


@section("4.5")
@aio
async def test_object_dnrt(cfg):
    """object.set dnrt: default true, false kept, reported in state (§5.4); "dnrt": 5 -> invalid
    naming /object/dnrt (also inside a batch), nothing applied."""
    c = await controller(cfg)
    p = cfg.uid("dnrt")
    try:
        asset = scene_asset(c.welcome)
        await c.expect_ok({"type": "batch", "ops": [
            {"type": "object.set", "object": {"id": p + "-a", "asset": asset}},
            {"type": "object.set", "object": {"id": p + "-b", "asset": asset, "dnrt": False}}]})
        st = await c.request({"type": "state.get"})
        mine = {o["id"]: o for o in st["objects"] if o["id"].startswith(p)}
        assert mine[p + "-a"].get("dnrt") is True, "§4.5 dnrt defaults to true: %r" % mine[p + "-a"]
        assert mine[p + "-b"].get("dnrt") is False, "dnrt false not kept: %r" % mine[p + "-b"]
        r0 = st["revision"]
        await c.expect_error({"type": "object.set", "object": {"id": p + "-c", "asset": asset, "dnrt": 5}},
                             "invalid", "/object/dnrt")
        await c.expect_error({"type": "batch", "ops": [
            {"type": "object.set", "object": {"id": p + "-c", "asset": asset}},
            {"type": "object.set", "object": {"id": p + "-a", "asset": asset, "dnrt": "off"}}]},
            "invalid", "/ops/1/object/dnrt")
        st = await c.request({"type": "state.get"})
        assert st["revision"] == r0 and not [o for o in st["objects"] if o["id"] == p + "-c"], (
            "a refused object.set changed the state")
        await c.ping_ok()
    finally:
        st = await c.request({"type": "state.get"})
        ops = [{"type": "object.remove", "object_id": o["id"]} for o in st["objects"] if o["id"].startswith(p)]
        if ops:
            await c.request({"type": "batch", "ops": ops})
        await c.close()


def _expected_transfer():
    out = {}
    for item in os.environ.get("LUCENT_CONF_EXPECT_TRANSFER", "").split():
        name, _, dims = item.partition("=")
        d, _, k = dims.partition("x")
        out[name] = (int(d), int(k))
    return out


@section("3.4")
@aio
async def test_welcome_asset_info(cfg):
    """welcome.scene.asset_info (optional): schema-valid, one entry per asset of scene.assets,
    each {} or {"transfer": {dims, coefficients, bytes, outer_radius}}; with
    LUCENT_CONF_EXPECT_TRANSFER, the named assets have transfer data of those dims and
    coefficients."""
    c = await controller(cfg)
    try:
        sc = c.welcome["scene"]
        expect = _expected_transfer()
        info = sc.get("asset_info")
        if info is None:
            assert not expect, "LUCENT_CONF_EXPECT_TRANSFER names %r but welcome has no scene.asset_info" % expect
            pytest.skip("the server sends no welcome.scene.asset_info (optional, §3.4)")
        errs = list(VALIDATORS["welcome"].iter_errors(c.welcome))
        assert not errs, "welcome with asset_info fails its schema: %s" % "; ".join(e.message for e in errs[:3])
        assert sorted(info) == sorted(sc["assets"]), "asset_info keys %r, scene.assets %r" % (
            sorted(info), sorted(sc["assets"]))
        for name, ai in info.items():
            t = ai.get("transfer")
            if t is not None:
                assert t["bytes"] >= t["dims"] ** 3, "%s: %d bytes for %d^3 vertices" % (name, t["bytes"], t["dims"])
                assert t["outer_radius"] > 0, (name, t)
        for name, (dims, coeffs) in expect.items():
            assert name in info, "asset %r is not in asset_info %r" % (name, sorted(info))
            t = info[name].get("transfer")
            assert t, "asset %r has no transfer data: %r" % (name, info[name])
            assert t["dims"] == dims and t["coefficients"] == coeffs, (
                "asset %r: transfer dims %r coefficients %r, expected %d and %d" % (
                    name, t["dims"], t["coefficients"], dims, coeffs))
    finally:
        await c.close()
