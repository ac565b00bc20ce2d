"""Shared fixtures of the Python tests: third-party scenes, optional packages, meshes."""

from __future__ import annotations

import os
import pathlib

import numpy as np
import pytest

REPO = pathlib.Path(__file__).resolve().parents[2]


def scenes_dir() -> pathlib.Path:
    """The third-party scenes (``RAYPACK_SCENES``), or a loud skip."""
    root = os.environ.get("RAYPACK_SCENES")
    if not root:
        pytest.skip("SKIPPED: RAYPACK_SCENES is not set (e.g. RAYPACK_SCENES=../shared/scenes); third-party scenes not tested")
    return pathlib.Path(root)


def need(module: str):
    """Imports an optional package, or skips loudly."""
    return pytest.importorskip(module, reason=f"SKIPPED: the optional package {module!r} is not installed (pip install {module})")


def cli() -> pathlib.Path:
    """The raypack CLI of this checkout (``cargo build --release``), or a loud skip."""
    exe = pathlib.Path(os.environ.get("RAYPACK_CLI", REPO / "target" / "release" / "raypack"))
    if not exe.exists():
        pytest.skip(f"SKIPPED: no raypack CLI at {exe} (run cargo build --release, or set RAYPACK_CLI)")
    return exe


def uv_sphere(rings: int, segments: int, radius: float = 1.0, center=(0.0, 0.0, 0.0)):
    """A closed UV sphere: vertices (float64) and faces (int64), poles shared."""
    theta = np.linspace(0, np.pi, rings + 1)[1:-1]
    phi = np.linspace(0, 2 * np.pi, segments, endpoint=False)
    tt, pp = np.meshgrid(theta, phi, indexing="ij")
    ring = np.stack([np.sin(tt) * np.cos(pp), np.sin(tt) * np.sin(pp), np.cos(tt)], axis=-1).reshape(-1, 3)
    vertices = np.vstack([[0, 0, 1], ring, [0, 0, -1]]) * radius + np.asarray(center)
    faces = []
    idx = lambda r, s: 1 + r * segments + s % segments  # noqa: E731
    for s in range(segments):
        faces.append([0, idx(0, s), idx(0, s + 1)])
        bottom = len(vertices) - 1
        faces.append([bottom, idx(rings - 2, s + 1), idx(rings - 2, s)])
    for r in range(rings - 2):
        for s in range(segments):
            a, b, c, d = idx(r, s), idx(r, s + 1), idx(r + 1, s), idx(r + 1, s + 1)
            faces += [[a, c, b], [b, c, d]]
    return vertices, np.asarray(faces, dtype=np.int64)


def grid(n: int, size: float = 2.0, z: float = 0.0):
    """An n x n grid of squares (two triangles each) in the plane z, centred on the origin."""
    xs = np.linspace(-size / 2, size / 2, n + 1)
    xx, yy = np.meshgrid(xs, xs, indexing="ij")
    vertices = np.stack([xx, yy, np.full_like(xx, z)], axis=-1).reshape(-1, 3)
    i = np.arange(n)[:, None] * (n + 1) + np.arange(n)[None, :]
    a, b, c, d = i, i + 1, i + n + 1, i + n + 2
    faces = np.concatenate([np.stack([a, c, b], -1), np.stack([b, c, d], -1)]).reshape(-1, 3)
    return vertices, faces.astype(np.int64)


def soup(n: int, size: float, seed: int):
    """n random triangles of edge about ``size`` in the unit cube (they intersect freely)."""
    rng = np.random.default_rng(seed)
    centers = rng.random((n, 1, 3)) * 2 - 1
    vertices = (centers + (rng.random((n, 3, 3)) - 0.5) * size).reshape(-1, 3)
    return vertices, np.arange(3 * n, dtype=np.int64).reshape(-1, 3)


def random_rays(bounds, n: int, seed: int):
    """n rays from a sphere around ``bounds`` through random points inside it (float32)."""
    rng = np.random.default_rng(seed)
    lo, hi = np.asarray(bounds[0], np.float64), np.asarray(bounds[1], np.float64)
    center, radius = (lo + hi) / 2, np.linalg.norm(hi - lo)
    u = rng.normal(size=(n, 3))
    origins = center + u / np.linalg.norm(u, axis=1, keepdims=True) * radius
    targets = lo + (hi - lo) * rng.random((n, 3))
    d = targets - origins
    return origins.astype(np.float32), (d / np.linalg.norm(d, axis=1, keepdims=True)).astype(np.float32)
