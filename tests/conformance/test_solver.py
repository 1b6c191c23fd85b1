"""The light-transport solver: §3.4 (welcome.scene.solvers), §4.9 (settings.solver), §5.4.

A server lists the solvers it offers in `welcome.scene.solvers`; the cases skip on a server
without the list (an older one: it has pic only and ignores an unknown settings field, §2.2).
Setting a solver the list lacks, or an unknown name, is refused naming /settings/solver and
changes nothing; each listed solver is accepted and reported by state.get (the "probes" case
skips when the bake offers no probes solver). The settings are restored afterwards.
"""
import pytest

from conftest import aio, controller

section = pytest.mark.section
KNOWN = ("pic", "probes")


def _solvers(c):
    s = c.welcome["scene"].get("solvers")
    if s is None:
        pytest.skip("the server lists no solvers (no welcome.scene.solvers)")
    return s


async def _settings(c):
    st = await c.request({"type": "state.get"})
    assert st["type"] == "state", st
    return st["revision"], st["settings"]


@section("3.4")
@aio
async def test_welcome_solvers(cfg):
    """welcome.scene.solvers: a non-empty list of distinct known names; state.settings.solver
    (§5.4: every settings field) is one of them."""
    c = await controller(cfg)
    try:
        s = _solvers(c)
        assert isinstance(s, list) and s, "§3.4 scene.solvers must be a non-empty list: %r" % (s,)
        assert len(set(s)) == len(s) and all(n in KNOWN for n in s), (
            "§3.4 scene.solvers must hold distinct names of %r: %r" % (KNOWN, s))
        _, settings = await _settings(c)
        assert settings.get("solver") in s, (
            "§5.4 state.settings.solver must be one of welcome.scene.solvers %r: %r" % (s, settings))
    finally:
        await c.close()


@section("4.9")
@aio
async def test_solver_refused(cfg):
    """settings.set solver: an unknown name, a wrong type, or a known solver the server does not
    offer -> invalid naming /settings/solver (/ops/1/settings/solver inside a batch); nothing
    is applied."""
    c = await controller(cfg)
    try:
        offered = _solvers(c)
        rev, before = await _settings(c)
        bad = [n for n in KNOWN if n not in offered] + ["radiosity", "PIC", ""]
        for name in bad:
            await c.expect_error({"type": "settings.set", "settings": {"solver": name}}, "invalid",
                                 "/settings/solver")
        await c.expect_error({"type": "settings.set", "settings": {"solver": 1}}, "invalid", "/settings/solver")
        await c.expect_error({"type": "batch", "ops": [
            {"type": "settings.set", "settings": {"bounces": before["bounces"]}},
            {"type": "settings.set", "settings": {"solver": bad[0]}}]}, "invalid", "/ops/1/settings/solver")
        rev2, after = await _settings(c)
        assert rev2 == rev and after == before, (
            "a refused settings.set solver changed the state: rev %d -> %d, %r -> %r" % (rev, rev2, before, after))
        await c.ping_ok()
    finally:
        await c.close()


async def _switch_to(cfg, name):
    c = await controller(cfg)
    offered = _solvers(c)
    if name not in offered:
        await c.close()
        pytest.skip("the bake offers no %s solver (welcome.scene.solvers %r)" % (name, offered))
    _, s0 = await _settings(c)
    try:
        ok = await c.expect_ok({"type": "settings.set", "settings": {"solver": name}})
        rev, got = await _settings(c)
        assert rev == ok["revision"], (rev, ok["revision"])
        assert got["solver"] == name, "settings.set solver=%r, state says %r" % (name, got)
        rest = {k: v for k, v in got.items() if k != "solver"}
        assert rest == {k: v for k, v in s0.items() if k != "solver"}, (
            "settings.set solver changed other settings: %r -> %r" % (s0, got))
    finally:
        if "solver" in s0:
            await c.request({"type": "settings.set", "settings": {"solver": s0["solver"]}})
        await c.close()


@section("4.9")
@aio
async def test_solver_pic(cfg):
    """solver pic, when offered: ok, state.get reports it, the other settings stay."""
    await _switch_to(cfg, "pic")


@section("4.9")
@aio
async def test_solver_probes(cfg):
    """solver probes, when offered (a bake made with --solver probes or both): ok, state.get
    reports it, the other settings stay."""
    await _switch_to(cfg, "probes")
