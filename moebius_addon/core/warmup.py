"""Run the paths of a first session on small curves, so that numba compiles (or loads) their
kernels: what ``make extension`` runs to build the cache it ships with the linux-x64 zip
(mk/build_extension.py, docs/blender.md "Install"), and what ``python -m
moebius_addon.core.warmup`` runs to fill numba's cache ahead of use.

Each path does what the Blender layer does on that first contact: *Add Knot* (resample, start
check, energy), the method *Automatic* chooses (the knot determinant), a few iterates, and the
invariants compared at the end of a run.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Callable

import numpy as np

from . import hs_solve, hs_tree, knots
from ._layout import layout_from_sizes
from .engine import energy, moebius_energy
from .identify import identify
from .invariants import knot_determinant
from .polygon import check_polygon, contact_ratio, resample
from .separate import separate
from .solvers import make_run


def _relax(P, method: str, steps: int = 2, **options) -> None:
    run = make_run(method, P, metric="hs", max_iter=steps, tol=0.0, target_lengths="keep",
                   **options)
    while run.step():
        pass
    run.result()


def _knot(name: str, n: int, method: str = "projected_gradient_implicit") -> None:
    """Add Knot + Relax of a knot: *Automatic* takes the implicit method (determinant > 1);
    the explicit one for unknots."""
    P = knots.named(name, n)
    check_polygon(P)
    moebius_energy(P)
    knot_determinant(P)
    _relax(P, method)
    identify(P)


def _exact() -> None:
    _knot("3_1", 100)
    _relax(knots.named("3_1", 100), "projected_gradient")  # unknots, and as chosen
    # a start whose strands nearly touch is pushed apart first (solvers.adaptive)
    separate(resample(knots.named("3_1", 30) * [1.0, 1.0, 0.3], 30))


def _tree() -> None:
    # from engine.AUTO_TREE_FROM edges on Automatic takes the tree; from engine.ENERGY_TREE_FROM
    # (3 000) the energy shown by Add Knot and Convert is the tree's too
    _knot("3_1", 3000)
    _relax(knots.named("3_1", 3000), "projected_gradient")
    # from hs_solve.MULTILEVEL_FROM (2·10⁴) vertices the hs solve's hierarchy: its transfers
    _, _, P = hs_solve._halve(layout_from_sizes([64], False))
    P.T @ (P @ np.zeros((P.shape[1], 3)))
    # and its levels' operators, in single precision as the fine one from
    # engine.SINGLE_WEIGHTS_FROM (2·10⁵) vertices on
    X = knots.named("3_1", 400)
    hs_tree.HsOperator(X, layout_from_sizes([400], False), single=True).product(X)


def _tangent_point() -> None:
    # Energy ▸ Tangent-Point: its sums, the metric of its order (7/4 at the default exponents),
    # on the exact engine and, from engine.AUTO_TREE_FROM edges on, the tree
    for n in (100, 3000):
        P = knots.named("3_1", n)
        energy(P, energy="tangent_point")
        _relax(P, "projected_gradient_implicit", energy="tangent_point")


def _convert() -> None:
    t = np.linspace(0.0, 2.0 * np.pi, 400, endpoint=False)
    drawn = np.c_[np.sin(t) + 2 * np.sin(2 * t), np.cos(t) - 2 * np.cos(2 * t), -np.sin(3 * t)]
    P = resample(drawn, 200)
    check_polygon(P, coarseness=False)
    contact_ratio(P)


def _identify() -> None:
    identify(knots.named("8_19", 200))


def _open() -> None:
    t = np.linspace(0.0, 1.0, 80)
    P = resample(np.c_[np.cos(6 * t), np.sin(6 * t), 3 * t], 80, closed=False)
    check_polygon(P, closed=False)
    moebius_energy(P, closed=False)
    _relax(P, "projected_gradient", closed=False)


def _cables() -> None:
    # Presets ▸ Untangle Cables: open cables with both ends pinned; from engine.AUTO_TREE_FROM
    # vertices on (6 × 171 here) the tree's open-curve kernels (the arc-length field, the open
    # band solver), which a first run compiled for about a minute
    t = np.linspace(0.0, 1.0, 171)
    P = [np.c_[0.1 * (c % 3) + 0.01 * np.sin(3 * t + c), 0.1 * (c // 3) + 0.01 * np.cos(2 * t + c),
               t] for c in range(6)]
    _relax(P, "projected_gradient", closed=False, pinned=[[0, 170]] * 6)


#: The paths, in the order a first session meets them.
PATHS: dict[str, Callable[[], None]] = {
    "exact": _exact,
    "convert": _convert,
    "identify": _identify,
    "open": _open,
    "tree": _tree,
    "tangent_point": _tangent_point,
    "cables": _cables,
}


def warm(paths=tuple(PATHS), say: Callable[[str], None] | None = print) -> dict[str, float]:
    """Run ``paths`` (names of :data:`PATHS`); return the CPU seconds of each."""
    seconds = {}
    for name in paths:
        t = time.process_time()
        PATHS[name]()
        seconds[name] = time.process_time() - t
        if say is not None:
            say(f"{name}: {seconds[name]:.1f} s CPU")
    return seconds


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("paths", nargs="*", default=list(PATHS),
                    help=f"which paths (default: all of {', '.join(PATHS)})")
    args = ap.parse_args(argv)
    unknown = [p for p in args.paths if p not in PATHS]
    if unknown:
        ap.error(f"unknown path(s) {', '.join(unknown)}; choose from {', '.join(PATHS)}")
    warm(args.paths, lambda line: print(line, flush=True))
    return 0


if __name__ == "__main__":
    sys.exit(main())
