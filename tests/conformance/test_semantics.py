"""Semantics: §1.3 (rate), §2.6, §3.3, §4.10, §5.3."""
import asyncio
import json

import pytest

from conftest import aio, controller, open_client

section = pytest.mark.section


def L(lid, **kw):
    d = {"id": lid, "type": "point", "position": [0.2, 0.3, 0.2], "intensity": 0.3}
    d.update(kw)
    return d


async def cleanup(c, prefix):
    st = await c.request({"type": "state.get"})
    ops = [{"type": "light.remove", "light_id": x["id"]} for x in st["lights"] if x["id"].startswith(prefix)]
    if ops:
        await c.request({"type": "batch", "ops": ops})


@section("4.10")
@aio
async def test_batch_atomic(cfg):
    """A batch whose op 2 fails: error with pointer /ops/2/..., nothing applied, revision unchanged."""
    c = await controller(cfg)
    p = cfg.uid("ba")
    try:
        st0 = await c.request({"type": "state.get"})
        e = await c.request({"type": "batch", "ops": [
            {"type": "light.set", "light": L(p + "-a")},
            {"type": "light.set", "light": L(p + "-b")},
            {"type": "light.set", "light": L(p + "-c", intensity=-1)}]})
        assert e["type"] == "error" and e["code"] == "out_of_range", e
        assert e["pointer"] == "/ops/2/light/intensity", e
        st1 = await c.request({"type": "state.get"})
        assert st1["revision"] == st0["revision"], "revision moved on a failed batch"
        assert not [x for x in st1["lights"] if x["id"].startswith(p)], "a failed batch applied ops: %r" % st1["lights"]
        # ops are validated against the state after the previous ops
        e = await c.request({"type": "batch", "ops": [
            {"type": "light.set", "light": L(p + "-a")},
            {"type": "light.remove", "light_id": p + "-a"},
            {"type": "light.remove", "light_id": p + "-a"}]})
        assert e["type"] == "error" and e["code"] == "unknown_id" and e["pointer"] == "/ops/2/light_id", e
        ok = await c.request({"type": "batch", "ops": [
            {"type": "light.set", "light": L(p + "-a")},
            {"type": "light.set", "light": L(p + "-a", intensity=0.7)},
            {"type": "light.set", "light": L(p + "-b")},
            {"type": "light.remove", "light_id": p + "-b"}]})
        assert ok["type"] == "ok" and ok["revision"] == st0["revision"] + 1, ok
        st2 = await c.request({"type": "state.get"})
        mine = [x for x in st2["lights"] if x["id"].startswith(p)]
        assert [x["id"] for x in mine] == [p + "-a"] and mine[0]["intensity"] == pytest.approx(0.7), mine
    finally:
        await cleanup(c, p)
        await c.close()


@section("5.3")
@aio
async def test_changed_broadcast(cfg):
    """An accepted change reaches every other client as `changed` (revision, by, ops, ids), not
    the sender; a batch is one `changed` listing each op."""
    a = await controller(cfg, name="conf-changer")
    b = await controller(cfg, name="conf-watcher")
    v = await open_client(cfg, token=cfg.viewer_token, name="conf-viewer") if cfg.viewer_token else None
    p = cfg.uid("ch")
    try:
        ok = await a.expect_ok({"type": "light.set", "light": L(p)})
        for w in [b] + ([v] if v else []):
            ch = await w.recv_json("changed")
            assert ch["revision"] == ok["revision"] and ch["by"] == "conf-changer", ch
            assert ch["ops"] == ["light.set"] and ch["ids"] == [p], ch
        ok = await a.expect_ok({"type": "batch", "ops": [{"type": "light.set", "light": L(p, intensity=1)},
                                                         {"type": "light.remove", "light_id": p}]})
        ch = await b.recv_json("changed")
        assert ch["revision"] == ok["revision"] and ch["ops"] == ["light.set", "light.remove"] and \
            ch["ids"] == [p, p], ch
        await a.pump(0.5)
        mine = [m for m in a.json_q if m.get("type") == "changed"]
        assert not mine, "§5.3 the sender got its own change broadcast: %r" % mine
    finally:
        await cleanup(a, p)
        for c in (a, b, v):
            if c:
                await c.close()


@section("3.3")
@aio
async def test_viewer_forbidden(cfg):
    """A viewer's change requests -> forbidden (connection stays); its allowed requests work."""
    if not cfg.viewer_token:
        pytest.skip("no --viewer-token")
    v = await open_client(cfg, token=cfg.viewer_token, name="conf-viewer")
    try:
        assert v.welcome["role"] == "viewer", v.welcome
        r0 = await v.revision()
        for msg in ({"type": "light.set", "light": L("conf-v")}, {"type": "light.remove", "light_id": "conf-v"},
                    {"type": "object.set", "object": {"id": "conf-v", "asset": "x"}},
                    {"type": "object.remove", "object_id": "conf-v"},
                    {"type": "material.set", "material": "x", "emission": [0, 0, 0]},
                    {"type": "environment.set", "environment": {"type": "none"}},
                    {"type": "settings.set", "settings": {"bounces": 1}},
                    {"type": "batch", "ops": [{"type": "light.remove", "light_id": "conf-v"}]}):
            e = await v.request(msg)
            assert e["type"] == "error" and e["code"] == "forbidden", "%s by a viewer: %r" % (msg["type"], e)
        await v.ping_ok()
        for msg in ({"type": "subscribe", "stream": "shgrid"}, {"type": "snapshot"},
                    {"type": "unsubscribe", "stream": "shgrid"}):
            await v.expect_ok(msg)
        assert await v.revision() == r0
    finally:
        await v.close()


@section("2.6")
@aio
async def test_state_survives_reconnect(cfg):
    """state.get on a new connection equals the state before (after a change and a disconnect)."""
    c = await controller(cfg)
    p = cfg.uid("rc")
    try:
        ok = await c.expect_ok({"type": "light.set", "light": L(p, color=[0.5, 0.25, 1], range=3)})
        st = await c.request({"type": "state.get"})
        await c.close()
        d = await controller(cfg)
        assert d.welcome["revision"] == ok["revision"], "welcome revision %d, last ok %d" % (
            d.welcome["revision"], ok["revision"])
        st2 = await d.request({"type": "state.get"})
        st.pop("id", None)
        st2.pop("id", None)
        assert st2 == st, "state changed across reconnect:\n%s\n%s" % (json.dumps(st)[:500], json.dumps(st2)[:500])
        await cleanup(d, p)
        await d.close()
    finally:
        await c.close()


@section("1.3")
@aio
async def test_rate_limited(cfg):
    """2*rate+50 pings as fast as possible: every one answered, some with rate_limited (echoing
    the id); the connection stays usable once the rate drops."""
    c = await controller(cfg)
    try:
        rate = c.welcome["limits"]["rate"]
        n = 2 * rate + 50
        for i in range(n):
            await c.ws.send('{"type":"ping","t":%d,"id":%d}' % (i, 10000 + i))
        pongs = limited = 0
        seen = set()
        while len(seen) < n:
            m = await c.recv_json(pred=lambda m: m.get("type") in ("pong", "error"))
            assert m.get("id") not in seen, "two replies for id %r" % m.get("id")
            seen.add(m.get("id"))
            if m["type"] == "pong":
                pongs += 1
            else:
                assert m["code"] == "rate_limited", m
                limited += 1
        assert limited >= 1, "%d requests in a burst, none rate_limited (rate %d, burst 2x)" % (n, rate)
        assert pongs >= rate, "only %d of %d answered normally (burst should allow ~%d)" % (pongs, n, 2 * rate)
        # Usable again once the rate drops: pings at the published rate (one per 1/rate s, the
        # time the server takes to earn a request back) until one is answered with pong; each
        # rate_limited reply means it has not yet. A server that stays limited fails after the
        # reply timeout.
        loop = asyncio.get_running_loop()
        deadline = loop.time() + cfg.timeout
        tries = 0
        while True:
            tries += 1
            r = await c.request({"type": "ping", "t": 12.5})
            if r["type"] == "pong":
                assert r["t"] == 12.5, r
                break
            assert r["type"] == "error" and r["code"] == "rate_limited", "ping after the burst: %r" % r
            assert loop.time() < deadline, ("§1.3 still rate_limited %.0f s after the burst (%d pings at %d/s): the "
                                            "connection never became usable again" % (cfg.timeout, tries, rate))
            await asyncio.sleep(1.0 / rate)
    finally:
        await c.close()
