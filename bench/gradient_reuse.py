"""Before and after the tree engine's trials with their gradient (``engine.GRADIENT_REUSE``),
alternated in one process. Prints measurements.

    python bench/gradient_reuse.py [--rounds 2] [--iters 6] [--cases cables,torus,fhw]
    python bench/gradient_reuse.py --accuracy      # a kept split against a fresh one
    python bench/gradient_reuse.py --nearest       # the start check's nearest pair

"before" is the line search as it was: a trial's energy alone tested against Armijo before its
back-projection finished (``TreeEngine.early_energy_test``), then the accepted polygon's energy
and gradient with a split built there. "after": from ``engine.EARLY_TEST_BELOW`` vertices on the
trial finished first, its energy and gradient in one pass with the split of the last frame
while no vertex moved more than ``GRADIENT_REUSE`` mean edge lengths from it, kept when the
trial is accepted (below, the early test as before, then the gradient with the kept split).

Cases: ``cables`` (bench/cables_tree.py: 100 open cables × 200 edges between two plates, ends
pinned, ``h1``), ``torus`` (bench/scenes.py's cables scene: the same with a torus obstacle of
2 048 triangles, ``hs``), ``fhw`` (the Freedman–He–Wang unknot at 1 648 edges, closed, ``hs``,
relaxed to E ≤ 4.01 or 400 iterations on the tree). Per case and round each setting runs once;
seconds per iteration are the median after the first (compilation and the start's checks left
out); the load average is printed with each.

``--accuracy``: the energy and gradient with the split built at ``X`` (kept) and with one built
at ``Y`` (fresh), both against the exact sums at ``Y = X + d``, ``d`` a smooth field or a random
one (every vertex its own way) scaled to a largest displacement of 2–16 mean edge lengths; FHW
at 5 000 edges and the 100 cables. ``--nearest``: seconds of the start check's nearest
edge–triangle pair of the torus scene, all pairs and through the triangles' hierarchy
(alternated, best of 3), and whether both found the same pair.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from cables_tree import plates_scene  # noqa: E402
from scenes import cables_torus  # noqa: E402

from moebius_addon import core  # noqa: E402
from moebius_addon.core.runs import engine  # noqa: E402

SETTINGS = {"before": (0.0, np.inf), "after": (engine.GRADIENT_REUSE, engine.EARLY_TEST_BELOW)}


def use(setting: str) -> None:
    engine.GRADIENT_REUSE, engine.EARLY_TEST_BELOW = SETTINGS[setting]


def timed(**kw) -> tuple[float, int, float]:
    """(median seconds per iteration after the first, iterations, final energy)."""
    stamps = []
    res = core.relax(engine="tree", callback=lambda s: stamps.append(time.perf_counter()), **kw)
    return float(np.median(np.diff(stamps))), res.nit, float(res.fun)


def accuracy() -> None:
    from moebius_addon.core.energies.choice import MOEBIUS
    from moebius_addon.core.geometry.layout import as_layout
    from moebius_addon.core.tree import moebius as barnes_hut

    rng = np.random.default_rng(1)
    sc = cables_torus()
    cases = {"FHW 5000": as_layout(core.knots.freedman_unknot(5000)),
             "100 cables": as_layout(sc.parts, closed=sc.closed)}
    for name, (X, lay) in cases.items():
        ln = np.linalg.norm(X[lay.nxt] - X, axis=1)
        h = float(np.mean(ln[lay.real] if lay.has_open else ln))
        kept = barnes_hut.Frame(X, lay)
        W, b = rng.standard_normal((3, 3)), rng.standard_normal(3)
        smooth = np.sin(3.0 * X @ W + b)
        for move in (2.0, 4.0, 8.0, 16.0):
            for kind, d in (("smooth", smooth), ("random", rng.standard_normal(X.shape))):
                Y = X + d * (move * h / np.max(np.linalg.norm(d, axis=1)))
                Ee, Ge = MOEBIUS.exact_gradient(Y, lay)
                errs = []
                for frame in (kept, barnes_hut.Frame(Y, lay)):
                    E, G = frame.energy_gradient(Y)
                    errs.append((abs(E - Ee) / Ee, np.linalg.norm(G - Ge) / np.linalg.norm(Ge)))
                print(f"{name:10} {kind:6} move {move:4} edges: kept E {errs[0][0]:.1e} "
                      f"g {errs[0][1]:.1e} | fresh E {errs[1][0]:.1e} g {errs[1][1]:.1e}",
                      flush=True)


def nearest() -> None:
    from moebius_addon.core.geometry import obstacles
    from moebius_addon.core.geometry.layout import as_layout

    sc = cables_torus()
    X, lay = as_layout(sc.parts, closed=sc.closed)
    field = obstacles.ObstacleField(obstacles.check_obstacles(sc.obstacles))
    best, found = {"pairs": np.inf, "tree": np.inf}, {}
    for _ in range(3):
        for search in best:
            t = time.perf_counter()
            found[search] = field.nearest(X, lay.nxt, search=search)
            best[search] = min(best[search], time.perf_counter() - t)
    print(f"nearest edge-triangle pair, {lay.n} vertices, {field.triangles} triangles: all "
          f"pairs {best['pairs']:.3f} s, hierarchy {best['tree']:.3f} s (best of 3), "
          f"{best['pairs'] / best['tree']:.1f}x; the same pair: "
          f"{found['pairs'] == found['tree']} {found['tree']}, load {os.getloadavg()[0]:.2f}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--iters", type=int, default=6)
    ap.add_argument("--cases", default="cables,torus,fhw")
    ap.add_argument("--accuracy", action="store_true")
    ap.add_argument("--nearest", action="store_true")
    args = ap.parse_args()
    if args.accuracy or args.nearest:
        if args.nearest:
            nearest()
        if args.accuracy:
            accuracy()
        return
    cases = {}
    parts = plates_scene()
    cases["cables"] = dict(P=parts, closed=False, pinned=[[0, len(p) - 1] for p in parts],
                           metric="h1", max_iter=args.iters + 1)
    sc = cables_torus()
    cases["torus"] = dict(P=sc.parts, closed=sc.closed, pinned=sc.pinned, metric="hs",
                          obstacles=sc.obstacles, max_iter=args.iters + 1, **sc.options)
    cases["fhw"] = dict(P=core.knots.freedman_unknot(1648), metric="hs", max_iter=400,
                        energy_target=4.01)
    use("after")
    core.relax(cases["fhw"]["P"], engine="tree", max_iter=2)  # compile before timing
    print(f"NUMBA_NUM_THREADS={os.environ.get('NUMBA_NUM_THREADS', 'all')}, "
          f"GRADIENT_REUSE={SETTINGS['after'][0]}")
    for name in args.cases.split(","):
        for r in range(args.rounds):
            for setting in (("before", "after") if r % 2 == 0 else ("after", "before")):
                use(setting)
                load = os.getloadavg()[0]
                t0 = time.perf_counter()
                s, nit, E = timed(**cases[name])
                print(f"{name:6} round {r} {setting:6}: {s:.3f} s/iteration (median), {nit} "
                      f"iterations in {time.perf_counter() - t0:.1f} s, energy {E:.10g}, "
                      f"load {load:.2f}", flush=True)
    use("after")


if __name__ == "__main__":
    main()
