"""Krylov iterations of the hs solves against N ("a preconditioner whose Krylov count
does not grow with N or with the curve"). Prints a table, writes JSON to out/ and a plot to
docs/img/krylov_scaling.png; not a test.

    python bench/krylov_scaling.py                          # 10³, 10⁴, both preconditioners
    python bench/krylov_scaling.py --n 1000 10000 100000 --iterations 3
    python bench/krylov_scaling.py --plot out/krylov_scaling.json   # plot a saved table only

The multilevel preconditioner is measured from 1 000 vertices on (``MULTILEVEL_FROM`` 0).

Every (curve, N) runs ``core.make_run("projected_gradient", P, engine="tree", metric="hs")``
for ``--iterations`` iterations with each preconditioner of ``hs_solve.PRECONDITIONERS``, the
two alternated (``two_level``: today's banded constraint preconditioner plus, from
``COARSE_FROM`` vertices, one dense coarse level; ``multilevel``: the banded one plus the
hierarchy of :class:`hs_solve.Multilevel`), and prints per solve the Krylov iterations
(median / max) and seconds (median; the solve alone, the preconditioner's set-up is in the
iteration's seconds, printed as their median).

Curves: the Freedman unknot (``knots.freedman_unknot``, the Repulsive Curves polygon
resampled), the 10-crossing knot 10_123 as the closure of its braid, the Borromean rings
(``L6a4{0,0}``, three components, N/3 vertices each) and a tangled 7_2
(``tangle.tangled("7_2")``, kept in out/ after the first run), each resampled to N.
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import numpy as np

from moebius_addon import core
from moebius_addon.core.metrics import hs_solve
from moebius_addon.core.topology import knots, tangle

OUT = Path("out")
IMG = Path(__file__).resolve().parent.parent / "docs" / "img" / "krylov_scaling.png"
CURVES = ("fhw", "10_123", "borromean", "tangled")


def curve(name: str, n: int):
    """A benchmark curve with ``n`` vertices in all."""
    if name == "fhw":
        return knots.freedman_unknot(n)
    if name == "10_123":
        return core.resample(knots.named("10_123"), n)
    if name == "borromean":
        return core.resample(knots.named("L6a4{0,0}"), [n // 3] * 3)
    OUT.mkdir(exist_ok=True)
    path = OUT / "krylov_tangled_7_2.npy"
    if not path.exists():  # about two minutes (the closure is identified at every count)
        np.save(path, np.asarray(tangle.tangled("7_2", seed=0)))
    return core.resample(np.load(path), n)


def measure(P, preconditioner: str, iterations: int) -> dict:
    """Krylov iterations and seconds of every hs solve of the first ``iterations``."""
    its, secs = [], []
    solve = hs_solve.HsSaddle.solve

    def timed(self, g, r, rtol=None):
        t = time.perf_counter()
        before = len(self.iterations)
        out = solve(self, g, r, rtol)
        secs.append(time.perf_counter() - t)
        its.extend(self.iterations[before:])
        return out

    old = hs_solve.PRECONDITIONER, hs_solve.MULTILEVEL_FROM
    hs_solve.PRECONDITIONER, hs_solve.MULTILEVEL_FROM = preconditioner, 0
    hs_solve.HsSaddle.solve = timed
    try:
        run = core.make_run("projected_gradient", P, "hs", max_iter=iterations, tol=0.0,
                            engine="tree")
        while not run.done:
            run.step()
        step_secs = list(run.history["seconds"]) if isinstance(run.history, dict) else []
    finally:
        hs_solve.HsSaddle.solve = solve
        hs_solve.PRECONDITIONER, hs_solve.MULTILEVEL_FROM = old
    return {"its": its, "secs": secs, "iteration_secs": step_secs}


def row(name, n, pre, m) -> str:
    its, secs = np.array(m["its"]), np.array(m["secs"])
    it_s = np.diff(np.r_[0.0, m["iteration_secs"]]) if m["iteration_secs"] else [np.nan]
    return (f"{name:10s} {n:8d} {pre:11s} {len(its):4d} {np.median(its):7.1f} {its.max():5d}"
            f" {np.median(secs):9.3f} {np.median(it_s):9.2f}")


def plot(results: list[dict], path: Path = IMG) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.0))
    for name, color in zip(CURVES, ("C0", "C1", "C2", "C3"), strict=True):
        for pre, style in (("two_level", "--"), ("multilevel", "-")):
            pts = sorted((r["n"], np.median(r["its"]), max(r["its"])) for r in results
                         if r["curve"] == name and r["preconditioner"] == pre)
            if pts:
                n, med, top = zip(*pts, strict=True)
                ax.plot(n, med, style, color=color, marker="o", label=f"{name}, {pre}")
                ax.plot(n, top, style, color=color, marker="^", alpha=0.4)
    ax.axhline(30, color="grey", lw=0.8)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("vertices N")
    ax.set_ylabel("Krylov iterations per solve (o median, ^ max)")
    ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    IMG.parent.mkdir(exist_ok=True)
    fig.savefig(path, dpi=110)
    print(f"wrote {path}")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--n", type=int, nargs="+", default=[1000, 10000])
    ap.add_argument("--curves", nargs="+", default=list(CURVES))
    ap.add_argument("--iterations", type=int, default=3)
    ap.add_argument("--pre", nargs="+", default=["two_level", "multilevel"])
    ap.add_argument("--out", default="out/krylov_scaling.json")
    ap.add_argument("--plot", nargs="+", metavar="JSON",
                    help="plot saved JSON tables (rows of later files replace earlier ones') "
                         "to docs/img/krylov_scaling.png and stop")
    args = ap.parse_args()
    if args.plot:
        rows = {}
        for path in args.plot:
            for r in json.loads(Path(path).read_text()):
                rows[(r["curve"], r["n"], r["preconditioner"])] = r
        plot(list(rows.values()))
        return
    print(f"load {os.getloadavg()}, {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}")
    print(f"{'curve':10s} {'N':>8s} {'precond':11s} {'#':>4s} {'median':>7s} {'max':>5s}"
          f" {'s/solve':>9s} {'s/iter':>9s}")
    results = []
    OUT.mkdir(exist_ok=True)
    for n in args.n:
        for name in args.curves:
            P = curve(name, n)
            for pre in args.pre:
                m = measure(P, pre, args.iterations)
                results.append({"curve": name, "n": n, "preconditioner": pre, **m})
                print(row(name, n, pre, m), flush=True)
                Path(args.out).write_text(json.dumps(results))
    print(f"load {os.getloadavg()}")
    plot(results, Path(args.out).with_suffix(".png"))  # docs' plot: --plot


if __name__ == "__main__":
    main()
