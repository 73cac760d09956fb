"""The hs metric on the tree engine: accuracy of the matrix-free
operator, Krylov iterations against N, and the flow at large N. Prints measurements and writes
JSON to out/; not a test.

    python bench/hs_tree_bench.py --accuracy          # products against the dense Gram matrix
    python bench/hs_tree_bench.py --pcg               # PCG iterations, 1 000 to 100 000 edges
    python bench/hs_tree_bench.py --flow 20000 --curve fhw --iterations 250 --target 4.01
    python bench/hs_tree_bench.py --flow 100000 --curve 7_2 --iterations 20
    python bench/hs_tree_bench.py --ratio 5000 20000 100000   # one iteration in E+g units

``--flow`` runs ``core.relax(P, engine="tree")`` (the default metric ``hs``) and prints every
iteration's seconds, the median, the energy, the constraint residual, the Krylov iterations,
the process's peak resident memory and the knot type before and after (``core.identify``);
with ``--eg`` it also times one energy+gradient evaluation of the same engine at the start
(best of 3) and prints the median iteration in those units.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import time
from pathlib import Path

import numpy as np

from moebius_addon import core
from moebius_addon.core.energies.moebius_dense import energy_gradient_x
from moebius_addon.core.geometry.constraints import jacobian, make_constraints
from moebius_addon.core.geometry.layout import as_layout
from moebius_addon.core.metrics import hs_solve
from moebius_addon.core.metrics.banded import BandedSaddle
from moebius_addon.core.metrics.gram import banded_parts_of_lengths, gram_x
from moebius_addon.core.tree import hs_metric as hs_tree

OUT = Path("out")


def machine() -> str:
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    return (f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
            f"Python {platform.python_version()}, numpy {np.__version__}, load {load:.1f}")


def curve(name: str, n: int):
    """The benchmark curves, resampled once and kept in out/."""
    OUT.mkdir(exist_ok=True)
    path = OUT / f"hs_bench_{name}_{n}.npy"
    if path.exists():
        data = np.load(path)
        return list(data) if name == "link3" else data
    if name == "fhw":
        P = core.knots.freedman_unknot(n)
    elif name == "noneq":  # the 7_2 with every vertex moved by 0.2 edge lengths
        Q = np.asarray(curve("7_2", n))
        rng = np.random.default_rng(7)
        P = Q + 0.2 * np.linalg.norm(Q[1] - Q[0]) * rng.standard_normal(Q.shape)
    elif name == "link3":  # a chain of three unit rings 1.2 apart
        t = np.linspace(0, 2 * np.pi, 400, endpoint=False)
        ring = np.c_[np.cos(t), np.sin(t), 0 * t]
        P = core.resample([ring, ring[:, [0, 2, 1]] + [1.2, 0, 0], ring + [2.4, 0, 0]],
                          [n // 3] * 3)
    else:
        P = core.resample(core.knots.named(name), n)
    np.save(path, np.asarray(P))
    return P


def unit(P):
    X, lay = as_layout(P)
    ln = np.linalg.norm(X[lay.nxt] - X, axis=1)
    return (X - X.mean(0)) / ln.sum(), lay


def best(f, repeat=3) -> float:
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        f()
        times.append(time.perf_counter() - t)
    return min(times)


def accuracy(n: int, thetas) -> list[dict]:
    rows = []
    rng = np.random.default_rng(0)
    for name in ("fhw", "7_2", "link3", "noneq"):
        X, lay = unit(curve(name, n))
        A = gram_x("hs", X, lay)
        U = rng.standard_normal((lay.n, 3))
        t = 2 * np.pi * np.arange(lay.n) / lay.n
        smooth = np.c_[np.cos(3 * t), np.sin(2 * t), np.cos(t)]
        exact = [A @ U, A @ smooth]
        for theta in thetas:
            op = hs_tree.HsOperator(X, lay, "hs", theta=theta)
            err = [float(np.linalg.norm(op.product(V) - e) / np.linalg.norm(e))
                   for V, e in zip((U, smooth), exact, strict=True)]
            row = {"curve": name, "edges": lay.n, "theta": theta, "random": err[0],
                   "smooth": err[1], "near_leaf_pairs": op.near_pairs,
                   "far_pairs": op.far_pairs, "stored_mb": op.nbytes / 1e6,
                   "product_ms": 1e3 * best(lambda op=op, U=U: op.product(U), 5)}
            rows.append(row)
            print(f"{name:6s} N={lay.n} theta {theta:5.3f}: relative error random "
                  f"{err[0]:.1e} smooth {err[1]:.1e}; near {op.near_pairs} far "
                  f"{op.far_pairs}; {row['stored_mb']:.1f} MB; product "
                  f"{row['product_ms']:.2f} ms", flush=True)
    return rows


def pcg(sizes) -> list[dict]:
    """Iterations of the gradient's solve and of a random right-hand side, with the shipped
    preconditioner (coarse level from ``hs_solve.COARSE_FROM`` vertices), without its coarse
    level, and with h1 alone (neither the coarse level nor the lumped lower-order term)."""
    rows = []
    for name in ("fhw", "7_2"):
        for n in sizes:
            X, lay = unit(curve(name, n))
            ln = np.linalg.norm(X[lay.nxt] - X, axis=1)
            con = make_constraints(X, lay, ln)
            jac = jacobian(X, con)
            op = hs_tree.HsOperator(X, lay, "hs")
            _, g = energy_gradient_x(X, lay) if n <= 20000 else core.runs.engine.TreeEngine(
                lay, "hs").energy_gradient(X)
            rnd = np.random.default_rng(1).standard_normal(g.shape)
            row = {"curve": name, "edges": n}
            for label in ("shipped", "one level", "h1 only"):
                solver = hs_solve.HsSaddle(op, jac, X=X, coarse=0 if label != "shipped" else None)
                if label == "h1 only":
                    rows_, cols, vals, _ = banded_parts_of_lengths("h1", ln, lay)
                    s = op.diagonal().sum() / vals[rows_ == cols].sum()
                    solver.K = BandedSaddle((rows_, cols, s * vals, op.beta), jac)
                for rtol in (1e-2, 1e-4):
                    for rhs, what in ((g, "gradient"), (rnd, "random")):
                        solver.solve(rhs, np.zeros(con.size), rtol=rtol)
                        row[f"{label} {what} {rtol:g}"] = solver.iterations[-1]
            rows.append(row)
            print(json.dumps(row), flush=True)
    return rows


def flow(n: int, name: str, iterations: int, target: float | None, eg: bool) -> dict:
    P = curve(name, n)
    t0 = time.perf_counter()
    marks = []
    res = core.relax(P, engine="tree", max_iter=iterations, energy_target=target,
                     callback=lambda s: marks.append((time.perf_counter(), s.energy,
                                                      s.constraint_residual)))
    total = time.perf_counter() - t0
    steps = np.diff([t0] + [m[0] for m in marks])
    its = res.stats["krylov_iterations"]
    row = {"curve": name, "edges": n, "iterations": res.nit, "seconds": total,
           "first_iteration_s": float(steps[0]) if len(steps) else None,
           "median_iteration_s": float(np.median(steps[1:])) if len(steps) > 1 else None,
           "energy": [float(res.history["energy"][0]), float(res.fun)],
           "max_constraint_residual": float(max(res.history["constraint_residual"])),
           "krylov_mean": float(np.mean(its)), "message": res.message,
           "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}
    # the knot type before and after (core.identify, after the peak memory was read)
    start, end = core.identify(P), core.identify(res.x)
    row.update(type_start=list(start.names), type_end=list(end.names),
               type_kept=start.fingerprint == end.fingerprint)
    for k, (_t, e, c) in enumerate(marks, 1):
        if k <= 3 or k % 10 == 0 or k == len(marks):
            print(f"  iterate {k:4d}: {steps[k - 1]:7.3f} s, E {e:.6f}, constraints {c:.1e}",
                  flush=True)
    if eg:
        X, lay = unit(P)
        engine = core.runs.engine.TreeEngine(lay, "hs")
        row["eg_s"] = best(lambda: engine.energy_gradient(X + 0.0))
        row["median_in_eg"] = row["median_iteration_s"] / row["eg_s"]
    print(json.dumps(row), flush=True)
    return row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--accuracy", action="store_true")
    ap.add_argument("--accuracy-n", type=int, default=5000)
    ap.add_argument("--pcg", action="store_true")
    ap.add_argument("--pcg-sizes", type=int, nargs="*", default=[1000, 5000, 20000, 100000])
    ap.add_argument("--flow", type=int)
    ap.add_argument("--curve", default="fhw")
    ap.add_argument("--iterations", type=int, default=20)
    ap.add_argument("--target", type=float)
    ap.add_argument("--eg", action="store_true")
    args = ap.parse_args()
    print(machine())
    out = {"machine": machine()}
    if args.accuracy:
        out["accuracy"] = accuracy(args.accuracy_n, (0.25, 0.35, 0.5, 0.75, 1.0))
    if args.pcg:
        out["pcg"] = pcg(args.pcg_sizes)
    if args.flow:
        out["flow"] = flow(args.flow, args.curve, args.iterations, args.target, args.eg)
    OUT.mkdir(exist_ok=True)
    path = OUT / f"hs_tree_bench_{int(time.time())}.json"
    path.write_text(json.dumps(out, indent=1))
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
