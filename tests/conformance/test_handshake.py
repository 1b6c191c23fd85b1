"""Handshake and session: §1.1, §3."""
import asyncio
import json
import time
import uuid

import pytest

from conftest import RawWS, Client, aio, connect, open_client, subscribe_keyframe, VALIDATORS

section = pytest.mark.section


@section("1.1")
def test_subprotocol_missing_refused(cfg):
    """A handshake that offers no subprotocol is refused (no 101)."""
    r = RawWS(cfg, subprotocol=None)
    try:
        assert not r.upgraded, "handshake without Sec-WebSocket-Protocol accepted: %r" % r.status_line
    finally:
        r.close()


@section("1.1")
def test_subprotocol_unknown_refused(cfg):
    """A handshake that offers only an unknown subprotocol (lucent.v2) is refused."""
    r = RawWS(cfg, subprotocol="lucent.v2")
    try:
        assert not r.upgraded, "handshake offering only lucent.v2 accepted: %r" % r.status_line
    finally:
        r.close()


@section("1.1")
@aio
async def test_subprotocol_selected_among_others(cfg):
    """Offering several subprotocols including lucent.v1: the server selects lucent.v1."""
    ws = await connect(cfg, subprotocols=("chat", "lucent.v1"))
    try:
        assert ws.subprotocol == "lucent.v1", "selected subprotocol %r" % ws.subprotocol
    finally:
        await ws.close()


@section("3.1")
@aio
async def test_hello_required_first(cfg):
    """Another message first -> error hello_required, then close 1008."""
    c = Client(await connect(cfg), cfg, "nohello")
    await c.send({"type": "state.get", "id": "first"})
    code, msgs = await c.wait_closed()
    errs = [m for m in msgs if m.get("type") == "error"]
    assert errs and errs[0]["code"] == "hello_required", "messages before close: %r" % msgs
    assert not [m for m in msgs if m.get("type") == "state"], "state was answered before hello: %r" % msgs
    assert code == 1008, "close code %r, expected 1008" % code


@section("3.1")
@aio
async def test_hello_timeout(cfg):
    """A silent client is closed with 1008 after the 5 s hello timeout (not before ~5 s, by 6.5 s)."""
    c = Client(await connect(cfg), cfg, "silent")
    t0 = time.monotonic()
    code, msgs = await c.wait_closed(timeout=6.5)
    dt = time.monotonic() - t0
    assert code == 1008, "close code %r, expected 1008" % code
    assert dt >= 4.0, "closed after %.1f s: the client has 5 s to send hello" % dt
    assert not [m for m in msgs if m.get("type") not in ("error",)], "unexpected messages: %r" % msgs


@section("3.2")
@aio
async def test_hello_unknown_token(cfg):
    """An unknown token -> error unauthorized, then close 1008 (needs a server with tokens)."""
    if not (cfg.controller_token or cfg.viewer_token):
        pytest.skip("no tokens given: the server may not authenticate")
    c = Client(await connect(cfg), cfg, "intruder")
    await c.send({"type": "hello", "id": 5, "client": "intruder", "token": "wrong-" + uuid.uuid4().hex})
    code, msgs = await c.wait_closed()
    assert msgs and msgs[0]["type"] == "error" and msgs[0]["code"] == "unauthorized", msgs
    assert msgs[0].get("id") == 5, "§2.5 the error must echo the hello id: %r" % msgs[0]
    assert code == 1008, "close code %r, expected 1008" % code


@section("3.2")
@aio
async def test_hello_invalid(cfg):
    """A hello without `client` is not a valid hello: it gets an error (invalid), never a welcome."""
    c = Client(await connect(cfg), cfg, "anon")
    try:
        await c.send({"type": "hello", "id": 6, "token": cfg.token})
        m = await c.recv_json()
        assert m["type"] == "error" and m["code"] == "invalid" and m["pointer"] in ("/client", ""), m
    except Exception as e:
        if type(e).__name__ == "ConnectionClosedOK" or "ConnectionClosed" in type(e).__name__:
            raise AssertionError("closed without an error reply")
        raise
    finally:
        await c.close()


@section("3.4")
@aio
async def test_welcome(cfg):
    """welcome: schema, echoes the id, protocol lucent/1, revision = state.get's revision, limits sane."""
    c = await open_client(cfg)
    try:
        w = c.welcome
        errs = list(VALIDATORS["welcome"].iter_errors(w))
        assert not errs, errs
        assert w["protocol"] == "lucent/1"
        lim = w["limits"]
        assert lim["max_message"] >= 1024 and lim["max_batch"] >= 1 and lim["rate"] >= 1, lim
        st = await c.request({"type": "state.get"})
        assert st["type"] == "state" and st["revision"] >= w["revision"], (w["revision"], st.get("revision"))
        mats = sorted(m["name"] for m in st["materials"])
        assert sorted(w["scene"]["materials"]) == mats or set(mats) <= set(w["scene"]["materials"]), \
            "state materials %r vs welcome %r" % (mats, w["scene"]["materials"])
    finally:
        await c.close()


@section("3.4")
@aio
async def test_welcome_matches_frames(cfg):
    """welcome.scene describes the frames: lightmap W/H/tile = frame header's; grid dims = shgrid's."""
    c = await open_client(cfg)
    try:
        sc = c.welcome["scene"]
        f = await subscribe_keyframe(c, "lightmap")
        assert f.encoding == 1, "§4.1 the default lightmap encoding is rgb9e5, got %d" % f.encoding
        lm = sc["lightmap"]
        assert (f.width, f.height, f.tile) == (lm["width"], lm["height"], lm["tile"]), (f, lm)
        g = await subscribe_keyframe(c, "shgrid")
        assert g.keyframe and g.encoding == 3, "§4.1 shgrid: keyframe, default f32: %r" % g
        assert [g.width, g.height, g.depth] == sc["grid"]["dims"], (g, sc["grid"])
        o = await subscribe_keyframe(c, "objects")
        assert o.keyframe and o.encoding == 3, "§4.1 objects: keyframe, default f32: %r" % o
        st = await c.request({"type": "state.get"})
        assert o.width == len(st["objects"]) or o.revision != st["revision"], \
            "objects frame count %d, state has %d objects" % (o.width, len(st["objects"]))
    finally:
        await c.close()


@section("3.3")
@aio
async def test_roles_by_token(cfg):
    """The controller token gives role controller, the viewer token role viewer."""
    if not cfg.viewer_token:
        pytest.skip("no --viewer-token")
    c = await open_client(cfg, token=cfg.controller_token)
    v = await open_client(cfg, token=cfg.viewer_token)
    try:
        assert c.welcome["role"] == "controller", c.welcome
        assert v.welcome["role"] == "viewer", v.welcome
    finally:
        await c.close()
        await v.close()
