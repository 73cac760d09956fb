"""The public ``core.energy_gradient`` on the tree against the exact engine, and against the
two passes it made before (a value sum, then the gradient's, on one frame). Prints
measurements; not a test.

    .venv/bin/python bench/public_eg.py [--edges 20000] [--rounds 5]

Each round times the three, alternated, in this process; the best of the rounds is reported.
The curve: the shipped Freedman–He–Wang unknot resampled to ``--edges`` (or ``--knot``).
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np
from paper import machine  # bench/ is on sys.path when run as a script

from moebius_addon import core
from moebius_addon.core.geometry.layout import as_checked_layout
from moebius_addon.core.runs import engine


def two_passes(P) -> tuple[float, np.ndarray]:
    """What ``energy_gradient(P, engine="tree")`` did before: one frame, the value sum and
    then the energy-and-gradient sum."""
    choice = core.check_energy("moebius")
    X, layout, k = as_checked_layout(P)
    frame = engine._frame(X, layout, "tree", None, choice, k)
    e = frame.energy(X)
    return e, frame.energy_gradient(X)[1]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--edges", type=int, default=20000)
    ap.add_argument("--knot", default="freedman")
    ap.add_argument("--rounds", type=int, default=5)
    args = ap.parse_args()
    base = core.knots.freedman_unknot() if args.knot == "freedman" else core.knots.named(args.knot)
    P = core.resample(base, args.edges)
    calls = {
        "tree, one pass": lambda: core.energy_gradient(P, engine="tree"),
        "tree, two passes (before)": lambda: two_passes(P),
        "exact": lambda: core.energy_gradient(P, engine="exact"),
    }
    for f in calls.values():  # compile (or load) first
        f()
    best = {name: np.inf for name in calls}
    for _ in range(args.rounds):
        for name, f in calls.items():
            t = time.perf_counter()
            f()
            best[name] = min(best[name], time.perf_counter() - t)
    print(f"{machine()}; load {os.getloadavg()[0]:.1f}")
    print(f"{args.knot} resampled to {args.edges} edges, best of {args.rounds} alternated rounds")
    for name, t in best.items():
        print(f"  {name:28s} {t:8.4f} s   exact / this {best['exact'] / t:6.1f}x")


if __name__ == "__main__":
    main()
