"""The obstacle energy and gradient through the triangles' hierarchy against all pairs (issue
28): seconds (best of ``--repeat``, the two alternated in one process) and the errors, for a
loop of ``--edges`` edges around the tube of a torus of ``--triangles`` triangles, at each
``--tol``; or, with ``--cables``, for the start of bench/scenes.py's 100 cables with the torus
(20 000 edges, 2 048 triangles)::

    NUMBA_NUM_THREADS=2 .venv/bin/python bench/obstacle_tree_energy.py [--cables]
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
from moebius_addon.core.geometry.layout import as_layout  # noqa: E402
from moebius_addon.core.geometry.obstacles import ObstacleField  # noqa: E402


def torus(R, r, nu, nv):
    u = np.linspace(0, 2 * np.pi, nu, endpoint=False)
    v = np.linspace(0, 2 * np.pi, nv, endpoint=False)
    U, W = np.meshgrid(u, v, indexing="ij")
    V = np.stack([(R + r * np.cos(W)) * np.cos(U), (R + r * np.cos(W)) * np.sin(U),
                  r * np.sin(W)], -1).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(nu), np.arange(nv), indexing="ij")
    a, b = i * nv + j, (i + 1) % nu * nv + j
    c, d = (i + 1) % nu * nv + (j + 1) % nv, i * nv + (j + 1) % nv
    F = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3),
                        np.stack([a, c, d], -1).reshape(-1, 3)])
    return V, F


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--edges", type=int, default=2000)
    ap.add_argument("--triangles", type=int, default=80000)
    ap.add_argument("--tol", type=float, nargs="+", default=[1e-2, 1e-3, 1e-4])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--cables", action="store_true", help="the 100 cables with the torus")
    args = ap.parse_args(argv)
    nv = max(4, int(round(np.sqrt(args.triangles / 8))))
    nu = args.triangles // (2 * nv)
    V, F = torus(1.0, 0.3, nu, nv)
    t = np.linspace(0, 2 * np.pi, args.edges, endpoint=False)
    # a wobbly loop around the tube, 0.15–0.45 from its surface
    P = np.stack([1.0 + 0.6 * np.cos(t) + 0.1 * np.cos(3 * t), 0.15 * np.sin(5 * t),
                  0.6 * np.sin(t)], -1)
    X, layout = as_layout(P, True)
    if args.cables:
        sys.path.insert(0, str(Path(__file__).resolve().parent))
        from scenes import cables_torus

        scene = cables_torus()
        X, layout = as_layout(scene.parts, closed=scene.closed)
        (V, F), = scene.obstacles
    exact = ObstacleField([(V, F)])
    fields = {tol: ObstacleField([(V, F)], tol=tol) for tol in args.tol}
    print(f"{layout.n} vertices, {exact.triangles} triangles, {os.environ.get('NUMBA_NUM_THREADS')}"
          f" threads, load {os.getloadavg()[0]:.1f}")
    for f in (exact, *fields.values()):  # compile / load
        f.energy_gradient(X[:8], layout.nxt[:8] % 8, layout.prv[:8] % 8)
    best = {k: np.inf for k in ["exact", *args.tol]}
    out = {}
    for _ in range(args.repeat):  # alternated: the load changes under all of them alike
        for key, f in [("exact", exact), *fields.items()]:
            t0 = time.perf_counter()
            out[key] = f.energy_gradient(X, layout.nxt, layout.prv)
            best[key] = min(best[key], time.perf_counter() - t0)
    E0, G0 = out["exact"]
    print(f"all pairs: {best['exact']:.3f} s, E = {E0:.6g}")
    for tol in args.tol:
        E, G = out[tol]
        gerr = np.linalg.norm(G - G0, axis=1).max() / np.linalg.norm(G0, axis=1).max()
        gl2 = np.linalg.norm(G - G0) / np.linalg.norm(G0)
        print(f"tol {tol:g}: {best[tol]:.4f} s ({best['exact'] / best[tol]:.0f}x), energy "
              f"error {abs(E - E0) / E0:.2e}, gradient error {gl2:.2e} (l2), {gerr:.2e} "
              f"(largest vertex / largest gradient)")
    print(f"load {os.getloadavg()[0]:.1f}")
    _ = core
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
