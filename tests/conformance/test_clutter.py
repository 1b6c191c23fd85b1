"""Clutter objects: §4.5 (object.set mode), §5.4 (state transport), §5.5 (object.transport).

The cases that need operators skip on a server without `welcome.scene.clutter` (it keeps every
object dynamic, §4.5); the mode field itself is checked on every server. Builds are waited for
with BUILD_TIMEOUT (a few seconds per object on lucentd; sanitizer builds are slower).
"""
import asyncio

import pytest

from conftest import RecvTimeout, aio, controller, scene_asset

section = pytest.mark.section
BUILD_TIMEOUT = 90.0


def _clutter(w):
    c = w["scene"].get("clutter")
    if c is None:
        pytest.skip("the server does not build clutter operators (no welcome.scene.clutter)")
    return c


def _obj(oid, asset, **kw):
    d = {"id": oid, "asset": asset, "translation": [0.3, 0, 0.3], "rotation": [0, 0, 0, 1], "scale": [1, 1, 1]}
    d.update(kw)
    return d


async def _objects(c, prefix):
    st = await c.request({"type": "state.get"})
    return {o["id"]: o for o in st["objects"] if o["id"].startswith(prefix)}


async def _remove_all(c, prefix):
    ops = [{"type": "object.remove", "object_id": i} for i in await _objects(c, prefix)]
    if ops:
        await c.request({"type": "batch", "ops": ops})


async def _transport(c, oid, timeout=BUILD_TIMEOUT):
    return await c.recv_json("object.transport", timeout=timeout, pred=lambda m: m["object_id"] == oid)


async def _no_transport(c, oid, seconds):
    """AssertionError if an object.transport for oid arrives within `seconds`."""
    try:
        m = await _transport(c, oid, timeout=seconds)
    except RecvTimeout:
        return
    raise AssertionError("unexpected object.transport: %r" % m)


@section("4.5")
@aio
async def test_mode_field(cfg):
    """mode defaults to dynamic, each of dynamic/clutter/auto is kept and reported in state with a
    read-only transport; other values -> invalid naming /object/mode (also inside a batch),
    nothing applied; a client's transport is ignored."""
    c = await controller(cfg)
    p = cfg.uid("mode")
    try:
        asset = scene_asset(c.welcome)
        await c.expect_ok({"type": "batch", "ops": [
            {"type": "object.set", "object": _obj(p + "-none", asset)},
            {"type": "object.set", "object": _obj(p + "-dyn", asset, mode="dynamic", transport="clutter")},
            {"type": "object.set", "object": _obj(p + "-clu", asset, mode="clutter", translation=[0.2, 0, 0.2])},
            {"type": "object.set", "object": _obj(p + "-auto", asset, mode="auto", translation=[0.4, 0, 0.2])}]})
        mine = await _objects(c, p)
        want = {"-none": "dynamic", "-dyn": "dynamic", "-clu": "clutter", "-auto": "auto"}
        for suffix, mode in want.items():
            o = mine[p + suffix]
            assert o.get("mode") == mode, "§4.5 %s: mode %r, expected %r" % (suffix, o.get("mode"), mode)
            assert o.get("transport") in ("dynamic", "clutter"), "§5.4 state object without transport: %r" % o
        assert mine[p + "-dyn"]["transport"] == "dynamic", "a client's transport was taken: %r" % mine[p + "-dyn"]
        r0 = (await c.request({"type": "state.get"}))["revision"]
        for bad in ("static", "", 3, None, True):
            await c.expect_error({"type": "object.set", "object": _obj(p + "-bad", asset, mode=bad)},
                                 "invalid", "/object/mode")
        await c.expect_error({"type": "batch", "ops": [
            {"type": "object.set", "object": _obj(p + "-bad", asset)},
            {"type": "object.set", "object": _obj(p + "-none", asset, mode="resting")}]},
            "invalid", "/ops/1/object/mode")
        st = await c.request({"type": "state.get"})
        assert st["revision"] == r0 and p + "-bad" not in {o["id"] for o in st["objects"]}, (
            "a refused object.set changed the state")
        await c.ping_ok()
    finally:
        await _remove_all(c, p)
        await c.close()


@section("5.5")
@aio
async def test_clutter_lifecycle(cfg):
    """A clutter object gets object.transport clutter (build_ms, bytes) and state transport clutter;
    a move drops the operators in the move's own revision (transport dynamic), then they are
    built again for the new placement without a new revision; mode dynamic drops them; a
    removal sends no object.transport."""
    c = await controller(cfg)
    p = cfg.uid("clu")
    oid = p + "-a"
    try:
        asset = scene_asset(c.welcome)
        _clutter(c.welcome)
        ok = await c.expect_ok({"type": "object.set", "object": _obj(oid, asset, mode="clutter")})
        m = await _transport(c, oid)
        assert m["transport"] == "clutter", "§5.5 first transport of a clutter object: %r" % m
        assert m["revision"] >= ok["revision"], "§5.5 revision %d before the object.set's %d" % (
            m["revision"], ok["revision"])
        assert m["build_ms"] > 0 and m["bytes"] > 0, "§5.5 clutter event without its build: %r" % m
        assert (await _objects(c, p))[oid]["transport"] == "clutter", "§5.4 state transport after the event"

        moved = await c.expect_ok({"type": "object.set", "object": _obj(oid, asset, mode="clutter",
                                                                        translation=[0.25, 0, 0.35])})
        m = await _transport(c, oid, timeout=cfg.timeout)
        assert m["transport"] == "dynamic" and m["revision"] == moved["revision"], (
            "§5.5 a move drops the operators in its own revision %d: %r" % (moved["revision"], m))
        assert "build_ms" not in m and "bytes" not in m, "§5.5 dynamic event with build fields: %r" % m
        m = await _transport(c, oid)
        assert m["transport"] == "clutter" and m["revision"] == moved["revision"], (
            "§5.5 the rebuilt operators keep the revision %d: %r" % (moved["revision"], m))

        # Only dnrt changes: the operators stay.
        kept = await c.expect_ok({"type": "object.set", "object": _obj(oid, asset, mode="auto", dnrt=False,
                                                                       translation=[0.25, 0, 0.35])})
        await _no_transport(c, oid, 2.0)
        assert (await _objects(c, p))[oid]["transport"] == "clutter", (
            "§4.5 mode clutter -> auto and dnrt changes keep the operators (revision %d)" % kept["revision"])

        dyn = await c.expect_ok({"type": "object.set", "object": _obj(oid, asset, mode="dynamic",
                                                                      translation=[0.25, 0, 0.35])})
        m = await _transport(c, oid, timeout=cfg.timeout)
        assert m["transport"] == "dynamic" and m["revision"] == dyn["revision"], (
            "§5.5 mode dynamic drops the operators in revision %d: %r" % (dyn["revision"], m))

        await c.expect_ok({"type": "object.set", "object": _obj(oid, asset, mode="clutter",
                                                                translation=[0.25, 0, 0.35])})
        assert (await _transport(c, oid))["transport"] == "clutter"
        await c.expect_ok({"type": "object.remove", "object_id": oid})
        await _no_transport(c, oid, 2.0)
    finally:
        await _remove_all(c, p)
        await c.close()


@section("4.5")
@aio
async def test_auto_promotion(cfg):
    """mode auto: dynamic while it moves, promoted no earlier than welcome.scene.clutter.rest
    seconds after its last placement change; hidden, it is not promoted."""
    c = await controller(cfg)
    p = cfg.uid("auto")
    oid = p + "-a"
    try:
        asset = scene_asset(c.welcome)
        rest = _clutter(c.welcome)["rest"]
        loop = asyncio.get_running_loop()
        await c.expect_ok({"type": "object.set", "object": _obj(oid, asset, mode="auto")})
        # Keep it moving for longer than the rest time: no operators meanwhile.
        t_end = loop.time() + rest * 1.5
        x = 0.3
        while loop.time() < t_end:
            x += 0.01
            await c.expect_ok({"type": "object.set", "object": _obj(oid, asset, mode="auto", translation=[x, 0, 0.3])})
            await _no_transport(c, oid, rest / 4)
        t_last = loop.time()
        m = await _transport(c, oid, timeout=rest + BUILD_TIMEOUT)
        waited = loop.time() - t_last
        assert m["transport"] == "clutter", m
        assert waited >= rest - 0.25, "§4.5 promoted %.2f s after the last move (rest %.2f s)" % (waited, rest)

        # Hidden: dropped at once, and not promoted while hidden.
        hid = await c.expect_ok({"type": "object.set", "object": _obj(oid, asset, mode="auto", visible=False,
                                                                      translation=[x, 0, 0.3])})
        m = await _transport(c, oid, timeout=cfg.timeout)
        assert m["transport"] == "dynamic" and m["revision"] == hid["revision"], m
        await _no_transport(c, oid, rest + 2.0)
    finally:
        await _remove_all(c, p)
        await c.close()
