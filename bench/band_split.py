"""The band of one long component in two halves (``banded.SPLIT_FROM``) against the whole band,
alternated in one process: the hs preconditioner's band solve and set-up, and one Möbius
iteration of the default flow. Prints measurements; not a test.

    NUMBA_NUM_THREADS=2 .venv/bin/python bench/band_split.py 100000 1000000 --rounds 3

Per size: the fine band of the hs preconditioner at FHW (``HsOperator.preconditioner_edges``)
built and solved with the whole band and with the halves (set-up best of 3, one right-hand
side best of 7, the solutions' relative difference), then ``rounds`` rounds of one E+g and
``core.relax(P, max_iter=1, engine="tree")`` with each, the order alternated, and the other
guests' share of the VM (``steal`` of /proc/stat) while each ran.
"""

from __future__ import annotations

import argparse
import gc
import os
import time

import numpy as np
from repulsor_compare import cpu_ticks  # bench/ is the script's folder

from moebius_addon import core
from moebius_addon.core.geometry.constraints import jacobian, make_constraints
from moebius_addon.core.geometry.layout import as_unit_layout
from moebius_addon.core.metrics import banded
from moebius_addon.core.tree.hs_metric import HsOperator

WHOLE = 10**12  # SPLIT_FROM beyond any curve: every block whole


def steal_seconds() -> float:
    """CPU seconds other guests took from this VM so far (0 where /proc/stat has none)."""
    ticks = cpu_ticks()
    return 0.0 if ticks is None else ticks[0] / os.sysconf("SC_CLK_TCK")


def best(f, k: int) -> float:
    times = []
    for _ in range(k):
        t = time.perf_counter()
        f()
        times.append(time.perf_counter() - t)
    return min(times)


def band_lines(P: np.ndarray, split_from: int) -> None:
    X, lay, _ = as_unit_layout(P)
    ln = np.linalg.norm(X[lay.nxt] - X, axis=1)
    jac = jacobian(X, make_constraints(X, lay, ln))
    parts = HsOperator(X, lay, "hs", single=True).preconditioner_edges()
    rng = np.random.default_rng(1)
    g = rng.standard_normal((lay.n, 3))
    r = np.zeros(jac.con.size)
    out = {}
    for name, at in (("whole", WHOLE), ("halves", split_from)):
        banded.SPLIT_FROM = at
        setup = best(lambda: banded.BandedSaddle(parts, jac, product=False), 3)
        solver = banded.BandedSaddle(parts, jac, product=False)
        out[name] = solver._solve(g, r)[0]
        solve = best(lambda s=solver: s._solve(g, r), 7)
        print(f"band edges={lay.n} band={name} setup_s={setup:.4f} solve_s={solve:.5f}", flush=True)
        del solver
    diff = np.linalg.norm(out["halves"] - out["whole"]) / np.linalg.norm(out["whole"])
    print(f"band edges={lay.n} rel_diff={diff:.2e}", flush=True)
    banded.SPLIT_FROM = split_from


def iteration_lines(P: np.ndarray, rounds: int, split_from: int) -> None:
    order = [("whole", WHOLE), ("halves", split_from)]
    for k in range(rounds):
        for name, at in order if k % 2 == 0 else order[::-1]:
            banded.SPLIT_FROM = at
            s0 = steal_seconds()
            t = time.perf_counter()
            core.energy_gradient(P, engine="tree")
            eg = time.perf_counter() - t
            r = core.relax(P, max_iter=1, engine="tree")
            sec = r.history["seconds"]
            it = sec[1] - sec[0]
            print(f"iteration edges={len(P)} round={k} band={name} eg_s={eg:.3f} "
                  f"setup_s={sec[0]:.3f} iteration_s={it:.3f} iteration_over_eg={it / eg:.2f} "
                  f"energy={r.history['energy'][1]:.12f} steal_s={steal_seconds() - s0:.1f}",
                  flush=True)
            del r
            gc.collect()
    banded.SPLIT_FROM = split_from


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("sizes", nargs="+", type=int)
    ap.add_argument("--rounds", type=int, default=3)
    args = ap.parse_args()
    split_from = banded.SPLIT_FROM
    core.relax(core.knots.freedman_unknot(600), max_iter=1, engine="tree")  # kernels first
    core.warm(("exact", "tree"), say=None)
    for n in args.sizes:
        P = core.knots.freedman_unknot(n)
        band_lines(P, split_from)
        iteration_lines(P, args.rounds, split_from)


if __name__ == "__main__":
    main()
