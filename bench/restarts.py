"""Restarts (``restarts=`` of ``core.relax``) on relaxed knots of the energy table: does a
nudged restart find a lower energy, and what does it cost? Prints measurements; not a test.

Each knot's relaxed polygon at the table's ``n2`` edges (``docs/data/energy_table_curves.npz``,
resampled to equal edges in double precision) is relaxed again by the table's method and
tolerance (``projected_gradient_implicit``, ``tol=1e-4``), first without restarts (the
baseline), then with ``--restarts`` nudged restarts for each of ``--seeds`` seeds::

    .venv/bin/python bench/restarts.py                       # 8_19 = T(3,4), 10_124 = T(3,5)
    .venv/bin/python bench/restarts.py --names 3_1 5_1 --restarts 2 --seeds 0
"""

from __future__ import annotations

import argparse
import csv
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from moebius_addon import core  # noqa: E402

CURVES = ROOT / "docs" / "data" / "energy_table_curves.npz"
TABLE = ROOT / "docs" / "data" / "energy_table.csv"
TORUS = {"3_1": (2, 3), "5_1": (2, 5), "7_1": (2, 7), "8_19": (3, 4), "10_124": (3, 5)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--names", nargs="*", default=["8_19", "10_124"])
    ap.add_argument("--restarts", type=int, default=3)
    ap.add_argument("--seeds", nargs="*", type=int, default=[0, 1])
    ap.add_argument("--scale", type=float, default=None, help="restart_scale (edge lengths)")
    ap.add_argument("--max-iter", type=int, default=3000)
    ap.add_argument("--torus", action="store_true",
                    help="start from the symmetric torus_knot(p, q) curve at n2 edges instead "
                         "of the table's relaxed one (8_19 = T(3,4), 10_124 = T(3,5))")
    args = ap.parse_args()
    with open(TABLE) as f:
        rows = {r["name"]: r for r in csv.DictReader(f)}
    packed = np.load(CURVES)
    extra = {} if args.scale is None else {"restart_scale": args.scale}
    for name in args.names:
        P = packed[name].astype(np.float64)
        P = core.resample(P, len(P))
        if args.torus:
            p, q = TORUS[name]
            P = core.knots.torus_knot(p, q, len(P))
        opts = {"method": "projected_gradient_implicit", "tol": 1e-4, "max_iter": args.max_iter}
        t = time.process_time()
        base = core.relax(P, **opts)
        cpu = time.process_time() - t
        print(f"{name}: table n2 {rows[name]['n2']} E {float(rows[name]['energy2']):.6f}; "
              f"again without restarts {base.fun:.6f} ({base.nit} iterations, {cpu:.1f} s CPU)",
              flush=True)
        for seed in args.seeds:
            t = time.process_time()
            r = core.relax(P, restarts=args.restarts, seed=seed, **opts, **extra)
            cpu = time.process_time() - t
            print(f"  seed {seed}: {r.fun:.6f} ({100 * (r.fun / base.fun - 1):+.4f} %), "
                  f"{r.nit} iterations kept, {cpu:.1f} s CPU in all", flush=True)
            for x in r.stats["restarts"]:
                print(f"    restart {x['restart']}: E {x.get('energy', float('nan')):.6f} "
                      f"after {x.get('iterations', 0)} iterations, "
                      f"{'kept' if x['kept'] else 'dropped'}", flush=True)


if __name__ == "__main__":
    main()
