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

from moebius_addon.core.energies.tangent_point_dense import tp_energy_gradient_x  # noqa: E402
from moebius_addon.core.geometry.layout import as_layout  # noqa: E402
from moebius_addon.core.tree.tangent_point import THETA, TangentPointFrame  # noqa: E402
from tests.conftest import varied_curves  # noqa: E402


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
    for name, P, closed in varied_curves(args.edges, rng):
        X, layout = as_layout(P, closed)
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
