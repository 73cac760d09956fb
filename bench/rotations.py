"""Iterations of the FHW flow to the round circle under random rotations of the start.

The energy is invariant under rotations, the iterates are not bit for bit: this shows how much
the iteration count of bench/core_bench.py depends on rounding, per engine (each rotation run
by every engine named, in turn, so that the engines share the machine's state).

    .venv/bin/python bench/rotations.py [edges] [seeds] [engine ...]
        # defaults: 1648, 5, auto (e.g. ``1648 10 tree exact``)
"""

import sys
import time

import numpy as np

from moebius_addon.core.runs.methods import Relaxation
from moebius_addon.core.topology import knots


def main():
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 1648
    seeds = int(sys.argv[2]) if len(sys.argv) > 2 else 5
    engines = sys.argv[3:] or ["auto"]
    P = knots.freedman_unknot(n)
    counts = {e: [] for e in engines}
    for seed in range(1, seeds + 1):
        Q, _ = np.linalg.qr(np.random.default_rng(seed).standard_normal((3, 3)))
        for engine in engines:
            run = Relaxation(P @ Q.T, max_iter=600, energy_target=4.01, engine=engine)
            t = time.perf_counter()
            while run.step():
                pass
            counts[engine].append(run.nit)
            print(f"seed {seed}, {engine}: {run.nit} iterations, "
                  f"{time.perf_counter() - t:.1f} s, E = {run.E:.6f} ({run.message})",
                  flush=True)
    for engine, c in counts.items():
        print(f"FHW {n} edges, {engine}: median {np.median(c):g}, mean {np.mean(c):.1f}, "
              f"range {min(c)}–{max(c)}, within 200: {sum(k <= 200 for k in c)} of {len(c)}")


if __name__ == "__main__":
    main()
