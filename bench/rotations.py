"""Iterations of the FHW flow to the round circle under random rotations of the start.

The energy is invariant under rotations, the iterates are not bit for bit: this shows how much
the iteration count of bench/core_bench.py depends on rounding.

    .venv/bin/python bench/rotations.py [edges] [seeds]      # defaults: 1648, 5
"""

import sys
import time

import numpy as np

from moebius_addon.core import knots
from moebius_addon.core.solvers import Relaxation


def main():
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 1648
    seeds = int(sys.argv[2]) if len(sys.argv) > 2 else 5
    P = knots.freedman_unknot(n)
    counts = []
    for seed in range(1, seeds + 1):
        Q, _ = np.linalg.qr(np.random.default_rng(seed).standard_normal((3, 3)))
        run = Relaxation(P @ Q.T, max_iter=600, energy_target=4.01)
        t = time.perf_counter()
        while run.step():
            pass
        counts.append(run.nit)
        print(f"seed {seed}: {run.nit} iterations, {time.perf_counter() - t:.1f} s, "
              f"E = {run.E:.6f} ({run.message})", flush=True)
    print(f"FHW {n} edges: median {int(np.median(counts))}, range {min(counts)}–{max(counts)}")


if __name__ == "__main__":
    main()
