"""The tangent-point tree's error against the exact sums over varied curves: knots of the table
(a 10-crossing one among them), the FHW unknot, a chain of three rings, a nearly critical
round ring, open cables and a trefoil with noise; energy and gradient (2-norm), relative, at
the default θ and others. Prints measurements; not a test::

    NUMBA_NUM_THREADS=2 .venv/bin/python bench/tp_accuracy.py --edges 5000 --thetas 0.3 0.25 0.2
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
from moebius_addon.core.energies.tangent_point_dense import tp_energy_gradient_x  # noqa: E402
from moebius_addon.core.geometry.layout import as_layout  # noqa: E402
from moebius_addon.core.tree.tangent_point import THETA, TangentPointFrame  # noqa: E402


def curves(n: int, rng: np.random.Generator):
    """``(name, parts, closed)`` of about ``n`` edges each."""
    out = []
    for kind in ("3_1", "7_2", "10_1", "10_132"):
        out.append((kind, core.resample(core.knots.named(kind), n), True))
    out.append(("fhw", core.knots.freedman_unknot(n), True))
    t = np.linspace(0, 2 * np.pi, 400, endpoint=False)
    ring = np.c_[np.cos(t), np.sin(t), 0 * t]
    out.append(("three rings", core.resample([ring, ring[:, [0, 2, 1]] + [1.2, 0, 0],
                                              ring + [2.4, 0, 0]], [n // 3] * 3), True))
    out.append(("round ring", core.resample(ring, n), True))
    s = np.linspace(0, 1, 4 * n // 10 + 1)
    cables = []
    for c in range(10):
        w = rng.uniform(-0.02, 0.02, 2)
        cables.append(np.c_[0.1 * (c % 4) + w[0] * np.sin(np.pi * s),
                            0.1 * (c // 4) + w[1] * np.sin(2 * np.pi * s), s])
    out.append(("ten cables", core.resample(cables, [n // 10 + 1] * 10, closed=False), False))
    P = core.resample(core.knots.named("3_1"), n)
    h = float(np.linalg.norm(P[1] - P[0]))
    out.append(("noisy trefoil", P + 0.1 * h * rng.standard_normal(P.shape), True))
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--edges", type=int, default=5000)
    ap.add_argument("--thetas", type=float, nargs="+", default=[THETA])
    args = ap.parse_args(argv)
    print(f"{os.cpu_count()} cores, NUMBA_NUM_THREADS {os.environ.get('NUMBA_NUM_THREADS', '-')},"
          f" load {os.getloadavg()[0]:.2f}; default theta {THETA}; (alpha, beta) the defaults;"
          f" energy / gradient relative errors", flush=True)
    rng = np.random.default_rng(20261202)
    worst = {th: (0.0, 0.0) for th in args.thetas}
    for name, P, closed in curves(args.edges, rng):
        X, layout = as_layout(P, closed if isinstance(P, list) else closed)
        t = time.perf_counter()
        E0, G0 = tp_energy_gradient_x(X, layout)
        t = time.perf_counter() - t
        row = []
        for th in args.thetas:
            E1, G1 = TangentPointFrame(X, layout, theta=th).energy_gradient(X)
            e = abs(E1 - E0) / abs(E0)
            g = float(np.linalg.norm(G1 - G0) / np.linalg.norm(G0))
            worst[th] = (max(worst[th][0], e), max(worst[th][1], g))
            row.append(f"theta {th:g}: {e:.2e} / {g:.2e}")
        print(f"{name:14s} {layout.n:6d} vertices (exact {t:.1f} s): " + "; ".join(row),
              flush=True)
    print("worst: " + "; ".join(f"theta {th:g}: {e:.2e} / {g:.2e}"
                                for th, (e, g) in worst.items()))
    return 0


if __name__ == "__main__":
    sys.exit(main())
