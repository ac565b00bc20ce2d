"""pytest plugin of ``tools/trimesh-suite``: runs trimesh's own test files with a chosen ray
engine where trimesh would use its embree one, and counts the ray queries that engine answers.

``-p trimesh_suite_plugin --ray-engine=raypack`` makes ``trimesh.ray.ray_pyembree.
RayMeshIntersector`` (what ``Trimesh(use_embree=True)``, trimesh's default, and the tests that
name it construct) a counting subclass of ``pyraypack.trimesh.RayMeshIntersector``;
``--ray-engine=embree`` leaves trimesh's embree intersector in place (it needs embreex) and
counts its queries. Either way the plugin checks at start-up that a fresh ``Trimesh`` gets
the chosen engine, and fails the session if that engine answered no query. With
``--ray-report=FILE`` it writes, per test, its outcome, the skip reason, and the queries and
rays the engine traced during it (JSON).

A query is one call that hands rays to the engine: raypack's ``_rays`` (every
``intersects_*`` call that traces), embree's ``_EmbreeWrap.run`` (trimesh calls it once per
pass of its multiple-hit loop, so the two counts differ for the same test).
"""

from __future__ import annotations

import json
import sys
import types

import pytest

_totals = {"queries": 0, "rays": 0}
_tests: dict[str, dict] = {}
_current: dict | None = None
_engine: str | None = None


def _record(rays: int) -> None:
    _totals["queries"] += 1
    _totals["rays"] += rays
    if _current is not None:
        _current["queries"] += 1
        _current["rays"] += rays


def pytest_addoption(parser):
    group = parser.getgroup("trimesh-suite")
    group.addoption("--ray-engine", choices=["raypack", "embree"], help="the engine behind trimesh's embree intersector")
    group.addoption("--ray-report", help="write per-test outcomes and query counts here (JSON)")


def _swap_in_raypack():
    import pyraypack.trimesh
    import trimesh.ray

    class RaypackIntersector(pyraypack.trimesh.RayMeshIntersector):
        """raypack's adapter, counting the rays it traces."""

        def _rays(self, ray_origins, ray_directions):
            out = super()._rays(ray_origins, ray_directions)
            _record(len(out[0]))
            return out

    # Importable by name (pickling a mesh's intersector looks its class up).
    RaypackIntersector.__module__ = __name__
    RaypackIntersector.__qualname__ = "RaypackIntersector"
    globals()["RaypackIntersector"] = RaypackIntersector
    if trimesh.ray.has_embree:
        trimesh.ray.ray_pyembree.RayMeshIntersector = RaypackIntersector
    else:
        # No embreex: trimesh would use its numpy intersector; stand in for the embree module
        # so that trimesh picks raypack where it would pick embree.
        module = types.ModuleType("trimesh.ray.ray_pyembree", "raypack standing in for trimesh's embree intersector")
        module.RayMeshIntersector = RaypackIntersector
        sys.modules["trimesh.ray.ray_pyembree"] = module
        trimesh.ray.ray_pyembree = module
        trimesh.ray.has_embree = True
    return RaypackIntersector


def _count_embree():
    from trimesh.ray import ray_pyembree  # needs embreex: an error here is the answer

    run = ray_pyembree._EmbreeWrap.run

    def counted_run(self, origins, normals, **kwargs):
        _record(len(origins))
        return run(self, origins, normals, **kwargs)

    ray_pyembree._EmbreeWrap.run = counted_run
    return ray_pyembree.RayMeshIntersector


def pytest_configure(config):
    global _engine
    _engine = config.getoption("--ray-engine")
    if _engine is None:
        return
    import trimesh

    expected = _swap_in_raypack() if _engine == "raypack" else _count_embree()
    mesh = trimesh.creation.box()
    assert type(mesh.ray) is expected, f"--ray-engine={_engine}: a new Trimesh got {type(mesh.ray)}, not {expected}"
    before = _totals["queries"]
    assert mesh.ray.intersects_any([[0, 0, 5.0]], [[0, 0, -1.0]]).tolist() == [True]
    assert _totals["queries"] > before, f"--ray-engine={_engine}: a query was not counted"
    _totals.update(queries=0, rays=0)
    config._trimesh_suite = {"engine": _engine, "trimesh": trimesh.__version__, "class": f"{expected.__module__}.{expected.__qualname__}"}


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item, nextitem):
    global _current
    _current = _tests.setdefault(item.nodeid, {"outcome": None, "reason": None, "queries": 0, "rays": 0})
    yield
    _current = None


def pytest_runtest_logreport(report):
    entry = _tests.setdefault(report.nodeid, {"outcome": None, "reason": None, "queries": 0, "rays": 0})
    # The first failing phase decides; a skip in setup or call is a skip.
    if report.failed:
        if entry["outcome"] != "failed":
            entry["outcome"] = "failed" if report.when == "call" else "error"
            crash = getattr(report.longrepr, "reprcrash", None)
            text = crash.message if crash is not None else report.longreprtext
            entry["reason"] = " ".join(text.split())[:300] if text else None
    elif report.skipped and entry["outcome"] is None:
        entry["outcome"] = "skipped"
        longrepr = report.longrepr
        entry["reason"] = longrepr[2] if isinstance(longrepr, tuple) else str(longrepr)
    elif report.when == "call" and report.passed and entry["outcome"] is None:
        entry["outcome"] = "passed"


def pytest_sessionfinish(session, exitstatus):
    if _engine is None:
        return
    config = session.config
    path = config.getoption("--ray-report")
    if path:
        with open(path, "w") as f:
            json.dump({**config._trimesh_suite, **_totals, "tests": _tests}, f, indent=1)
    if _totals["queries"] == 0 and session.testscollected:
        session.exitstatus = pytest.ExitCode.TESTS_FAILED


def pytest_terminal_summary(terminalreporter, exitstatus, config):
    if _engine is None:
        return
    traced = sum(1 for t in _tests.values() if t["queries"])
    terminalreporter.write_line(
        f"trimesh-suite: engine {_engine} ({config._trimesh_suite['class']}, trimesh {config._trimesh_suite['trimesh']}): "
        f"{_totals['queries']} queries, {_totals['rays']} rays, in {traced} of {len(_tests)} tests"
    )
    if _totals["queries"] == 0:
        terminalreporter.write_line(f"trimesh-suite: FAILED: the {_engine} engine answered no query")
