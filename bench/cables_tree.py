"""Seconds per iteration of a run on open cables with pinned ends, tree engine against exact
(issue 28): ``n`` cables of ``m`` edges between two parallel plates (z = 0 and z = 1, ends on a
square grid, pinned), each bent by a few random sines so that no two are parallel.

Usage: python bench/cables_tree.py [--cables 100] [--edges 200] [--iters 3] [--rounds 2]
       [--metric h1] [--engines tree,exact]

Each round runs every engine once (alternated, one process); a run is timed after a first
iteration (compilation and the start's checks left out): seconds per iteration as the
median over its iterations, the best round reported, with the load average before and after.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

from moebius_addon import core


def plates_scene(cables: int = 100, edges: int = 200, spacing: float = 0.1,
                 jitter: float = 0.02, seed: int = 0) -> list[np.ndarray]:
    """Equilateral open cables of ``edges`` edges from z = 0 to z = 1 on a square grid of
    ``spacing``, bent in x and y by ``jitter`` times random sines."""
    rng = np.random.default_rng(seed)
    k = int(np.ceil(np.sqrt(cables)))
    t = np.linspace(0.0, 1.0, 4 * edges + 1)
    parts = []
    for c in range(cables):
        x0, y0 = spacing * (c % k), spacing * (c // k)
        w = rng.uniform(-1.0, 1.0, (2, 2)) * jitter
        ph = rng.uniform(0.0, 2 * np.pi, 2)
        P = np.c_[x0 + w[0, 0] * np.sin(np.pi * t) + w[0, 1] * np.sin(2 * np.pi * t + ph[0]),
                  y0 + w[1, 0] * np.sin(np.pi * t) + w[1, 1] * np.sin(2 * np.pi * t + ph[1]),
                  t]
        parts.append(P)
    return core.resample(parts, [edges + 1] * cables, closed=False)


def seconds_per_iteration(parts, engine: str, metric: str, iters: int) -> tuple[float, float]:
    """Median seconds per iteration after the first, and the final energy."""
    pins = [[0, len(p) - 1] for p in parts]
    stamps = []
    res = core.relax(parts, closed=False, pinned=pins, engine=engine, metric=metric,
                     max_iter=iters + 1, callback=lambda s: stamps.append(time.perf_counter()))
    return float(np.median(np.diff(stamps))), float(res.fun)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cables", type=int, default=100)
    ap.add_argument("--edges", type=int, default=200)
    ap.add_argument("--iters", type=int, default=3)
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--metric", default="h1")
    ap.add_argument("--engines", default="tree,exact")
    a = ap.parse_args()
    parts = plates_scene(a.cables, a.edges)
    engines = a.engines.split(",")
    print(f"{a.cables} cables x {a.edges} edges ({a.cables * a.edges} edges), metric "
          f"{a.metric}, {a.iters} timed iterations, NUMBA_NUM_THREADS="
          f"{os.environ.get('NUMBA_NUM_THREADS', 'all')}, load before {os.getloadavg()}")
    core.relax(plates_scene(4, 60), closed=False, pinned=[[0, 60]] * 4, engine="tree",
               metric=a.metric, max_iter=2)  # compile the tree's kernels outside the timing
    best: dict[str, float] = {}
    for r in range(a.rounds):
        for eng in engines:
            s, fun = seconds_per_iteration(parts, eng, a.metric, a.iters)
            best[eng] = min(best.get(eng, np.inf), s)
            print(f"round {r}: {eng:5s} {s:.3f} s/iteration (energy after {a.iters + 1}: "
                  f"{fun:.6g})", flush=True)
    print("best: " + ", ".join(f"{e} {s:.3f} s" for e, s in best.items()))
    if "tree" in best and "exact" in best:
        print(f"exact / tree: {best['exact'] / best['tree']:.2f}")
    print(f"load after {os.getloadavg()}")


if __name__ == "__main__":
    main()
