"""Time ``core.identify`` on relaxed curves of the table: a seeded sample of knots of 12
crossings and links of 11, resampled to N edges, relaxed a number of iterations, identified.

    .venv/bin/python bench/identify_bench.py --edges 2000 --iterations 20 --sample 4

Prints one line per curve: name, edges, iterations, crossings of the diagram read, the names
found, whether the name is among them, seconds of the identification (and of the relaxation),
and the load average at the start and the end.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from moebius_addon import core  # noqa: E402
from moebius_addon.core.topology import knots  # noqa: E402


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--edges", type=int, default=2000)
    p.add_argument("--iterations", type=int, default=20)
    p.add_argument("--sample", type=int, default=4)
    p.add_argument("--seed", type=int, default=0)
    args = p.parse_args()
    rng = np.random.default_rng(args.seed)
    twelve = [n for n in knots.names("knot") if n.startswith("12")]
    eleven = [n for n in knots.names("link") if n.startswith("L11")]
    names = ([twelve[i] for i in rng.choice(len(twelve), args.sample, replace=False)]
             + [eleven[i] for i in rng.choice(len(eleven), max(1, args.sample // 2),
                                               replace=False)])
    core.identify(knots.named("3_1"))  # compile the kernels first
    print(f"load average at the start: {os.getloadavg()}", flush=True)
    for name in names:
        P = knots.named(name)
        if isinstance(P, list):
            lengths = [np.linalg.norm(np.roll(c, -1, 0) - c, axis=1).sum() for c in P]
            counts = np.maximum(np.round(np.array(lengths) / sum(lengths) * args.edges), 9)
            P = [core.resample(c, int(k)) for c, k in zip(P, counts, strict=True)]
        else:
            P = core.resample(P, args.edges)
        method = "projected_gradient_implicit" if not isinstance(P, list) else (
            "projected_gradient")
        t0 = time.perf_counter()
        r = core.relax(P, method=method, max_iter=args.iterations)
        t_relax = time.perf_counter() - t0
        t1 = time.perf_counter()
        found = core.identify(r.x)
        t_id = time.perf_counter() - t1
        print(f"{name}: {args.edges} edges, {r.nit} iterations ({t_relax:.1f} s, energy "
              f"{r.history['energy'][0]:.1f} -> {r.fun:.1f}), diagram {found.crossings} "
              f"crossings, identified {list(found.names)}, "
              f"{'ok' if name in found.names else 'WRONG'}, {t_id:.3f} s", flush=True)
    print(f"load average at the end: {os.getloadavg()}")


if __name__ == "__main__":
    main()
