"""Krylov iterations of the tree's hs solves against the metric's order: short
tree-engine runs of the Möbius energy (order 3/2) and of the tangent-point energy with
exponents of order (β − 1)/α = 3/2, 5/3, 7/5 from the same start. Prints measurements; not a
test.

    python bench/metric_order_bench.py                    # 7_2 at 2 000 edges, 10 iterations
    python bench/metric_order_bench.py --curve 3_1 --edges 4000 --iterations 20
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

from moebius_addon import core

CASES = (
    ("moebius", {}),
    ("tangent_point(2, 4)", {"energy": "tangent_point", "alpha": 2, "beta": 4}),
    ("tangent_point(3, 6)", {"energy": "tangent_point", "alpha": 3, "beta": 6}),
    ("tangent_point(2.5, 5)", {"energy": "tangent_point", "alpha": 2.5, "beta": 5}),
)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--curve", default="7_2")
    ap.add_argument("--edges", type=int, default=2000)
    ap.add_argument("--iterations", type=int, default=10)
    args = ap.parse_args()
    P = core.resample(core.knots.named(args.curve), args.edges)
    print(f"{args.curve} at {args.edges} edges, {args.iterations} iterations, tree engine, "
          f"hs, projected_gradient; load {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    for label, kw in CASES:
        order = core.check_energy(**kw).metric_order
        t0 = time.perf_counter()
        r = core.relax(P, engine="tree", max_iter=args.iterations, tol=0.0, refine=False, **kw)
        sec = time.perf_counter() - t0
        its = [k for k in r.stats["krylov_iterations"] if k > 0]
        E = r.history["energy"]
        print(f"{label:22s} order {order:.4f}: Krylov per solve median {np.median(its):.0f}, "
              f"max {max(its)}, mean {np.mean(its):.1f} over {len(its)} solves; "
              f"{r.nit} iterations in {sec:.1f} s; E {E[0]:.6g} -> {E[-1]:.6g}; "
              f"load {os.getloadavg()[0]:.1f}")
        print(f"{'':22s} {its}")


if __name__ == "__main__":
    main()
