"""Stalls on the tree engine: a run that stalls with its strands apart is started afresh with the
tree's θ halved (``solvers.adaptive.FRESH_THETA``, not below ``FRESH_THETA_FLOOR`` times the
first), against fresh starts that keep θ (``FRESH_THETA`` = 1, the behaviour before). Prints
measurements; not a test.

Each curve (catalogue knots and the FHW unknot, resampled to ``--edges``) is relaxed by
``core.relax(P, engine="tree", energy=E, max_iter=…, max_seconds=…)`` once per variant, the
variants alternated per curve in one process; printed per run: iterations, seconds, why it
stopped, the fresh starts (iteration, θ) and the *exact* energy of the result (the tree's own
value differs by its error, which is what is compared here)::

    .venv/bin/python bench/tree_stalls.py                          # tangent point, 2 000 edges
    .venv/bin/python bench/tree_stalls.py --energy moebius --curves 7_4 9_2
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from moebius_addon import core  # noqa: E402
from moebius_addon.core.runs import adaptive  # noqa: E402
from moebius_addon.core.topology import knots  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--curves", nargs="+", default=["7_4", "9_2", "FHW"])
    ap.add_argument("--edges", type=int, default=2000)
    ap.add_argument("--energy", default="tangent_point")
    ap.add_argument("--max-iter", type=int, default=300)
    ap.add_argument("--max-seconds", type=float, default=200.0)
    args = ap.parse_args()
    variants = {"theta kept": 1.0, "theta halved": adaptive.FRESH_THETA}
    warm = core.resample(knots.freedman_unknot(), 600)  # compile (or load) the kernels first
    core.relax(warm, engine="tree", energy=args.energy, max_iter=2)
    print(f"# {args.energy}, {args.edges} edges, threads={os.environ.get('NUMBA_NUM_THREADS')}, "
          f"load {os.getloadavg()[0]:.2f}", flush=True)
    for name in args.curves:
        P0 = knots.freedman_unknot() if name == "FHW" else knots.named(name)
        P = core.resample(P0, args.edges)
        for label, factor in variants.items():
            adaptive.FRESH_THETA = factor
            t0 = time.perf_counter()
            r = core.relax(P, engine="tree", energy=args.energy, max_iter=args.max_iter,
                           max_seconds=args.max_seconds)
            seconds = time.perf_counter() - t0
            exact = core.energy(r.x, energy=args.energy, engine="exact")
            print(json.dumps({
                "curve": name, "variant": label, "iterations": r.nit,
                "seconds": round(seconds, 1), "status": r.status.name,
                "fresh_starts": [(f["iteration"], f["theta"]) for f in r.stats["fresh_starts"]],
                "exact_energy": round(exact, 4)}), flush=True)


if __name__ == "__main__":
    main()
