"""A knot relaxed inside a container that is tight enough to matter: the trefoil of
docs/design.md (largest radius 3.0), ``--edges`` equal edges, inside a UV sphere of radius
``--radius`` (the free flow's relaxed trefoil does not fit in 2.4), exact engine. Prints the
iterations, seconds, energies, the least distance of a vertex to the wall, and checks every
iterate with the tests' independent ray-parity test::

    NUMBA_NUM_THREADS=2 .venv/bin/python bench/container_demo.py
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from moebius_addon import core  # noqa: E402
from tests.core.test_container import uv_sphere  # noqa: E402
from tests.mesh_checks import ray_parity_inside  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--edges", type=int, default=150)
    ap.add_argument("--radius", type=float, default=2.4)
    ap.add_argument("--iterations", type=int, default=200)
    args = ap.parse_args(argv)
    t = np.linspace(0.0, 2.0 * np.pi, 600, endpoint=False)
    K = np.c_[np.sin(t) + 2 * np.sin(2 * t), np.cos(t) - 2 * np.cos(2 * t), -np.sin(3 * t)]
    P = core.resample(K, args.edges)
    P = P * (0.95 * args.radius * np.cos(np.pi / 12) / np.linalg.norm(P, axis=1).max())
    V, F = uv_sphere(args.radius, 48, 24)
    rng = np.random.default_rng(0)
    print(f"{args.edges} edges in a sphere of radius {args.radius} ({len(F)} triangles), "
          f"load {os.getloadavg()[0]:.1f}")
    free = core.relax(P, max_iter=args.iterations, engine="exact")
    print(f"free: {free.nit} iterations, energy {free.history['energy'][0]:.4f} -> "
          f"{free.fun:.4f}, largest radius {np.linalg.norm(free.x, axis=1).max():.3f}, "
          f"vertices outside {int((~ray_parity_inside(free.x, V, F, rng)).sum())}")
    iterates = [P]
    t0 = time.perf_counter()
    r = core.relax(P, max_iter=args.iterations, engine="exact", container=(V, F),
                   callback=lambda s: iterates.append(s.x.copy()))
    secs = time.perf_counter() - t0
    outside = sum(int((~ray_parity_inside(X, V, F, rng)).sum()) for X in iterates)
    a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    n = np.cross(b - a, c - a)
    n /= np.linalg.norm(n, axis=1)[:, None]
    wall = float(np.min(np.einsum("kj,nkj->nk", n, a[None] - r.x[:, None])))
    print(f"contained: {r.nit} iterations in {secs:.1f} s ({r.message}), energy (Möbius plus "
          f"wall) {r.history['energy'][0]:.4f} -> {r.fun:.4f}, largest radius "
          f"{np.linalg.norm(r.x, axis=1).max():.3f}, least distance to the wall's planes "
          f"{wall:.4f} (edge length {np.linalg.norm(r.x[1] - r.x[0]):.4f}), vertices outside "
          f"in {len(iterates)} iterates: {outside}; load {os.getloadavg()[0]:.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
