"""Curve packing by length growth: a trefoil (``--edges`` equal edges) inside a UV
sphere (or ``--box``: a cube) grows to ``--factor`` times its length at ``--rate`` per
iteration (``length_target=``, ``length_growth=``), exact engine, adaptive resolution on (edges
grown past twice their start are split). Prints length, energy (Möbius plus the wall's),
iterations, seconds, edges, the least distance of a vertex to the wall, and checks every
iterate with the tests' independent ray-parity test::

    NUMBA_NUM_THREADS=2 .venv/bin/python bench/packing.py
    NUMBA_NUM_THREADS=2 .venv/bin/python bench/packing.py --box --energy tangent_point
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
from moebius_addon.core.geometry.container import check_container  # noqa: E402
from tests.core.test_container import uv_sphere  # noqa: E402
from tests.mesh_checks import ray_parity_inside  # noqa: E402


def cube(half: float):
    """A closed cube of half-width ``half`` around the origin, triangles facing outwards."""
    V = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float) * half
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    F = [t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))]
    return check_container((V, np.array(F)))


def wall_distance(X, V, F) -> float:
    """Least distance of the vertices to the planes of the (convex) container's triangles."""
    a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    n = np.cross(b - a, c - a)
    n /= np.linalg.norm(n, axis=1)[:, None]
    return float(np.min(np.einsum("kj,nkj->nk", n, a[None] - X[:, None])))


def length(X) -> float:
    return float(np.linalg.norm(np.roll(X, -1, 0) - X, axis=1).sum())


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--edges", type=int, default=100)
    ap.add_argument("--factor", type=float, default=3.0)
    ap.add_argument("--rate", type=float, default=0.02)
    ap.add_argument("--iterations", type=int, default=150)
    ap.add_argument("--box", action="store_true")
    ap.add_argument("--energy", default="moebius")
    args = ap.parse_args(argv)
    t = np.linspace(0.0, 2.0 * np.pi, 600, endpoint=False)
    K = np.c_[np.sin(t) + 2 * np.sin(2 * t), np.cos(t) - 2 * np.cos(2 * t), -np.sin(3 * t)]
    P = core.resample(K, args.edges)  # largest radius 3.0
    V, F = cube(3.3) if args.box else check_container(uv_sphere(3.3, 48, 24))
    L0 = length(P)
    rng = np.random.default_rng(0)
    print(f"trefoil, {args.edges} edges, length {L0:.3f}, in a "
          f"{'cube of half-width' if args.box else 'sphere of radius'} 3.3 ({len(F)} "
          f"triangles), growing to {args.factor:g}x at {100 * args.rate:g} % per iteration, "
          f"energy {args.energy}; load {os.getloadavg()[0]:.1f}")
    iterates = [P]
    t0 = time.perf_counter()
    r = core.relax(P, max_iter=args.iterations, engine="exact", container=(V, F),
                   length_target=args.factor * L0, length_growth=args.rate,
                   energy=args.energy, callback=lambda s: iterates.append(s.x.copy()))
    secs = time.perf_counter() - t0
    L = np.array(r.history["length"])
    reached = int(np.argmax(L >= args.factor * L0 * (1 - 1e-9))) if L[-1] >= (
        args.factor * L0 * (1 - 1e-9)) else None
    outside = sum(int((~ray_parity_inside(X, V, F, rng)).sum()) for X in iterates)
    print(f"{r.nit} iterations in {secs:.1f} s ({r.message}); length {L0:.3f} -> "
          f"{length(r.x):.3f} (target {args.factor * L0:.3f}, reached at iteration "
          f"{reached}, shortest step {np.diff(L).min():.2e}); energy {r.history['energy'][0]:.4f}"
          f" -> {r.fun:.4f}; edges {r.history['edges'][0]} -> {r.history['edges'][-1]}; least "
          f"distance to the wall {wall_distance(r.x, V, F):.4f} (mean edge "
          f"{length(r.x) / len(r.x):.4f}); vertices outside in {len(iterates)} iterates: "
          f"{outside}; load {os.getloadavg()[0]:.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
