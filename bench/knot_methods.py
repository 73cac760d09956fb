"""The feasible methods on every knot of the table: which one reaches the knot's relaxed shape.

    python bench/knot_methods.py                  # all 36 entries, 200 iterations (about 8 min)
    python bench/knot_methods.py --names 4_1 7_3 --max-iter 600
    python bench/knot_methods.py --equal-time    # explicit given the implicit run's seconds
    python bench/knot_methods.py --equal-time --tangled-links --max-iter 5000 --tol 1e-4

For each knot at its default edge count: iterations, seconds, final energy above the lowest
of the three methods, and whether the run converged (``success``: gradient below ``tol`` or
energy change below ``ftol``) within the iteration limit. Prints measurements; not a test.
"""

from __future__ import annotations

import argparse
import time

from moebius_addon import core

METHODS = ("projected_gradient", "projected_gradient_implicit", "trust_region")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--names", nargs="*", default=None)
    ap.add_argument("--max-iter", type=int, default=200)
    ap.add_argument("--equal-time", action="store_true",
                    help="per knot: the implicit method, then the explicit one with the same "
                         "seconds and no iteration limit")
    ap.add_argument("--tangled-links", action="store_true",
                    help="with --equal-time: the links of bench/untangle.py, their tangled "
                         "starts (names from there unless --names)")
    ap.add_argument("--tol", type=float, default=1e-6)
    args = ap.parse_args()
    if args.tangled_links:
        import untangle

        tasks = {t["name"]: t for t in untangle.tasks() if t["name"] in untangle.LINKS}
        starts = [(n, untangle.start_of(tasks[n])) for n in (args.names or untangle.LINKS)]
        return equal_time(starts, args.max_iter, args.tol)
    names = args.names or core.knots.names()
    if args.equal_time:
        return equal_time([(n, core.knots.named(n)) for n in names], args.max_iter, args.tol)
    for m in METHODS:  # compile every kernel before timing
        core.relax(core.knots.named("3_1"), method=m, max_iter=3)
    print(f"{'knot':5s} {'N':>4s} | " + " | ".join(f"{m[:24]:>24s}" for m in METHODS))
    totals = {m: [0.0, 0, 0] for m in METHODS}  # seconds, converged, lowest energy
    for name in names:
        P = core.knots.named(name)
        rows = []
        for m in METHODS:
            t = time.perf_counter()
            r = core.relax(P, method=m, max_iter=args.max_iter)
            rows.append((m, r.nit, time.perf_counter() - t, float(r.fun), r.success))
        best = min(row[3] for row in rows)
        cells = []
        for m, nit, sec, energy, ok in rows:
            lowest = energy - best <= 1e-3
            totals[m][0] += sec
            totals[m][1] += ok
            totals[m][2] += lowest
            flag = "conv" if ok else "    "
            cells.append(f"{nit:4d} it {sec:6.2f} s +{energy - best:7.4f} {flag}")
        print(f"{name:5s} {len(P):4d} | " + " | ".join(cells), flush=True)
    print(f"{len(names)} knots, at most {args.max_iter} iterations each:")
    for m, (sec, ok, low) in totals.items():
        print(f"  {m:28s} {sec:7.1f} s in all, converged on {ok}, lowest energy "
              f"(within 1e-3) on {low}")


def equal_time(starts, max_iter, tol):
    """Whether the explicit method, given the seconds the implicit one took on a curve (its
    ``max_iter`` iterations or convergence), reaches as low an energy; ``starts`` are
    (name, polygon or link) pairs."""
    for m in METHODS[:2]:
        core.relax(core.knots.named("3_1"), method=m, max_iter=3)
    print(f"{'curve':9s} {'N':>4s} | {'implicit':>34s} | {'explicit, same seconds':>34s} | "
          "diff")
    lower = 0
    for name, P in starts:
        n = sum(len(p) for p in P) if isinstance(P, list) else len(P)
        t = time.perf_counter()
        imp = core.relax(P, method="projected_gradient_implicit", max_iter=max_iter, tol=tol)
        sec = time.perf_counter() - t
        t = time.perf_counter()
        exp = core.relax(P, method="projected_gradient", max_iter=100 * max_iter, tol=tol,
                         max_seconds=sec)
        sec_e = time.perf_counter() - t
        diff = float(exp.fun) - float(imp.fun)
        lower += diff > 1e-3
        print(f"{name:9s} {n:4d} | {imp.nit:4d} it {sec:7.2f} s E={float(imp.fun):10.4f}"
              f"{'*' if imp.success else ' '} | {exp.nit:4d} it {sec_e:7.2f} s "
              f"E={float(exp.fun):10.4f}{'*' if exp.success else ' '} | {diff:+8.4f}",
              flush=True)
    print(f"{len(starts)} curves: the implicit method ended lower (by more than 1e-3) than the "
          f"explicit one in the same time on {lower} (* converged)")


if __name__ == "__main__":
    main()
