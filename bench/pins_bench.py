"""Cost of pinned vertices: seconds per iteration of the explicit method on the FHW
unknot with 0, 10 and 50 pins (evenly spaced), on the exact and the tree engine.

    python bench/pins_bench.py                        # 1 000 (exact, tree) and 5 000 (tree)
    python bench/pins_bench.py --sizes 2000 --engines tree --pins 0 5 50 --iters 6

Runs alternate (every pin count once per round, ``--rounds`` rounds) so that a busy machine
hits them alike; the median over rounds is printed. Prints measurements; not a test.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from moebius_addon import core
from moebius_addon.core.runs.methods import make_run


def per_iteration(P, engine: str, pins: int, iters: int) -> tuple[float, float]:
    n = len(P)
    pinned = list(range(0, n, n // pins))[:pins] if pins else None
    run = make_run("projected_gradient", P, "hs", iters, 0.0, engine=engine, pinned=pinned)
    t = time.perf_counter()
    while run.step():
        pass
    return (time.perf_counter() - t) / max(run.nit, 1), run.E


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="*", default=[1000, 5000])
    ap.add_argument("--engines", nargs="*", default=["exact", "tree"])
    ap.add_argument("--pins", type=int, nargs="*", default=[0, 10, 50])
    ap.add_argument("--iters", type=int, default=5)
    ap.add_argument("--rounds", type=int, default=3)
    args = ap.parse_args()
    for engine in args.engines:  # compile every kernel before timing
        for pins in args.pins:
            per_iteration(core.knots.freedman_unknot(600), engine, pins, 1)
    print(f"{'N':>6s} {'engine':6s} {'pins':>4s} {'ms/iteration':>13s} {'E after':>10s}")
    for n in args.sizes:
        P = core.knots.freedman_unknot(n)
        for engine in args.engines:
            if engine == "exact" and n > 2000:
                continue  # O(N³) per iteration: minutes
            times = {p: [] for p in args.pins}
            energy = {}
            for _ in range(args.rounds):
                for p in args.pins:
                    t, energy[p] = per_iteration(P, engine, p, args.iters)
                    times[p].append(t)
            for p in args.pins:
                print(f"{n:6d} {engine:6s} {p:4d} {1e3 * np.median(times[p]):13.1f} "
                      f"{energy[p]:10.2f}")


if __name__ == "__main__":
    main()
