"""Seconds per iteration of a run on open cables with pinned ends on the tree engine, and the
energy with its gradient tree against exact: ``n`` cables of ``m`` edges between two
parallel plates (z = 0 and z = 1, ends on a square grid, pinned), each bent by a few random
sines so that no two are parallel.

Usage: python bench/cables_tree.py [--cables 100] [--edges 200] [--iters 3] [--rounds 2]
       [--metric h1] [--engines tree,exact] [--theta 0.175]

Each round runs every engine once (alternated, one process): a run is timed after a first
iteration (compilation and the start's checks left out), seconds per iteration as the median
over its iterations; then one evaluation of the energy and its gradient per engine (the tree's
with its frame built). The best round is reported, with the load average before and after.
The exact engine's run holds the metric as a dense matrix and is refused above 15 000
vertices (solvers.base.check_dense_size): there only its energy and gradient are timed.
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


def seconds_per_iteration(parts, engine: str, metric: str, iters: int,
                          theta: float | None) -> tuple[float, float]:
    """Median seconds per iteration after the first, and the final energy (NaN, NaN where
    the run is refused for its size)."""
    pins = [[0, len(p) - 1] for p in parts]
    stamps = []
    try:
        res = core.relax(parts, closed=False, pinned=pins, engine=engine, metric=metric,
                         max_iter=iters + 1, theta=theta,
                         callback=lambda s: stamps.append(time.perf_counter()))
    except ValueError as e:
        print(f"  {engine}: {str(e)[:100]}...")
        return float("nan"), float("nan")
    return float(np.median(np.diff(stamps))), float(res.fun)


def seconds_per_evaluation(parts, engine: str, theta: float | None) -> float:
    """Seconds of one ``core.energy_gradient`` (the tree's frame built in it)."""
    t = time.perf_counter()
    core.energy_gradient(parts, closed=False, engine=engine, theta=theta)
    return time.perf_counter() - t


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cables", type=int, default=100)
    ap.add_argument("--edges", type=int, default=200)
    ap.add_argument("--iters", type=int, default=3)
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--metric", default="h1")
    ap.add_argument("--engines", default="tree,exact")
    ap.add_argument("--theta", type=float, default=None)
    a = ap.parse_args()
    parts = plates_scene(a.cables, a.edges)
    engines = a.engines.split(",")
    print(f"{a.cables} cables x {a.edges} edges ({a.cables * a.edges} edges), metric "
          f"{a.metric}, theta {a.theta or 'default'}, {a.iters} timed iterations, "
          f"NUMBA_NUM_THREADS="
          f"{os.environ.get('NUMBA_NUM_THREADS', 'all')}, load before {os.getloadavg()}")
    core.relax(plates_scene(4, 60), closed=False, pinned=[[0, 60]] * 4, engine="tree",
               metric=a.metric, max_iter=2)  # compile the tree's kernels outside the timing
    core.energy_gradient(plates_scene(4, 60), closed=False, engine="exact")
    best: dict[str, float] = {}
    evals: dict[str, float] = {}
    for r in range(a.rounds):
        for eng in engines:
            s, fun = seconds_per_iteration(parts, eng, a.metric, a.iters, a.theta)
            best[eng] = min(best.get(eng, np.inf), s)
            print(f"round {r}: {eng:5s} {s:.3f} s/iteration (energy after {a.iters + 1}: "
                  f"{fun:.6g})", flush=True)
        for eng in engines:
            s = seconds_per_evaluation(parts, eng, a.theta)
            evals[eng] = min(evals.get(eng, np.inf), s)
            print(f"round {r}: {eng:5s} {s:.3f} s per energy and gradient", flush=True)
    print("best per iteration: " + ", ".join(f"{e} {s:.3f} s" for e, s in best.items()))
    print("best per energy and gradient: " + ", ".join(f"{e} {s:.3f} s"
                                                      for e, s in evals.items()))
    if "tree" in evals and "exact" in evals:
        print(f"energy and gradient, exact / tree: {evals['exact'] / evals['tree']:.2f}")
    print(f"load after {os.getloadavg()}")


if __name__ == "__main__":
    main()
