"""The flow's accuracy on the tree. Prints measurements.

    python bench/tree_accuracy.py                 # FHW 1 648 edges to E <= 4.01, 4 rotations,
                                                  # theta 0.175, 0.125, 0.1; the round n-gon
    python bench/tree_accuracy.py --thetas 0.175 --rotations 8 --exact

Iterations of ``core.relax(P, max_iter=400, energy_target=4.01, engine="tree", theta=θ)`` per
random rotation of the Freedman–He–Wang unknot (rotations by a seeded generator; ``--exact``
adds the exact engine), then the energy of the round n-gon by the tree and the exact sum, and
the seconds of the exact energy alone (what a tree run pays to report its result's exact
energy, ``engine.EXACT_RESULT_MAX``).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from moebius_addon import core  # noqa: E402
from tests.conftest import random_rotation  # noqa: E402 - the tests' rotations, seeded


def rotations(k: int, seed: int = 7) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    return [random_rotation(rng) for _ in range(k)]


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--edges", type=int, default=1648)
    ap.add_argument("--rotations", type=int, default=4)
    ap.add_argument("--thetas", type=float, nargs="+", default=[0.175, 0.125, 0.1])
    ap.add_argument("--exact", action="store_true", help="the exact engine too (slow)")
    a = ap.parse_args(argv)
    P0 = core.knots.freedman_unknot(a.edges)
    runs = [("exact", {"engine": "exact"})] if a.exact else []
    runs += [(f"tree θ {t:g}", {"engine": "tree", "theta": t}) for t in a.thetas]
    print(f"FHW {a.edges} edges to E <= 4.01, iterations (seconds):", flush=True)
    for k, q in enumerate(rotations(a.rotations)):
        P = P0 @ q.T
        for name, kw in runs:
            t0 = time.perf_counter()
            r = core.relax(P, max_iter=400, energy_target=4.01, **kw)
            print(f"  rotation {k} {name:12s} {r.nit:4d} ({time.perf_counter() - t0:.1f} s), "
                  f"E {r.fun:.6f}", flush=True)
    print("round n-gon: tree / exact energy, seconds of the exact energy alone:", flush=True)
    for n in (1648, 5000, 20000):
        t = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
        C = np.c_[np.cos(t), np.sin(t), np.zeros(n)]
        trees = " ".join(f"θ {th:g}: {core.energy(C, engine='tree', theta=th):.7f}"
                         for th in a.thetas)
        F = core.knots.freedman_unknot(n)
        t0 = time.perf_counter()
        core.energy(F, engine="exact")
        s = time.perf_counter() - t0
        print(f"  {n:6d}: {trees}; exact {core.energy(C, engine='exact'):.15f}; "
              f"exact energy of FHW {s:.3f} s", flush=True)


if __name__ == "__main__":
    main()
