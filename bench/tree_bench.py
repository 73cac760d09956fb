"""Benchmark of the tree engine. Prints measurements; not a test.

    python bench/tree_bench.py                      # sizes 1 000 .. 100 000 (and errors)
    python bench/tree_bench.py --sizes 1000 5000    # some sizes only
    python bench/tree_bench.py --million            # only one E+g at 10^6 edges, with the
                                                    # peak memory of that process alone
    python bench/tree_bench.py --flow 600 1648      # only the flow: FHW to E <= 4.01, exact
                                                    # engine against the tree (iterations, s)
    python bench/tree_bench.py --banded 100000      # only the banded metrics (h1, h2) on the
                                                    # tree path: solver and 5 iterations of
                                                    # the flow, peak memory of this process

Energy+gradient exact vs tree (exact up to 20 000 edges), the frame (hierarchy build and the
far/near split) and the box refit, the contact step and the closest pairs (exact; all pairs up
to 20 000 edges, and through the hierarchy), relative errors against the exact sum as a
function of theta, and peak memory. Results also go to ``out/bench_tree.json`` (``--json PATH``).
"""

from __future__ import annotations

import argparse
import json
import resource
import time
from pathlib import Path

import numpy as np
from core_bench import best_of  # bench/ is on sys.path when run as a script
from paper import machine

from moebius_addon import core
from moebius_addon.core.energies.moebius_dense import energy_gradient_x
from moebius_addon.core.geometry.collision import closest_pairs, contact_time_x
from moebius_addon.core.geometry.layout import as_layout
from moebius_addon.core.tree import bvh
from moebius_addon.core.tree import moebius as barnes_hut

EXACT_UP_TO = 20000
THETAS = (0.0625, 0.125, 0.175, 0.2, 0.25, 0.5)
CACHE = Path("out/bench_tree_curves")


def curve(name: str, n: int) -> np.ndarray | list:
    """The benchmark curves, resampled once and kept in out/ (resampling 100 000 edges takes
    tens of seconds today)."""
    CACHE.mkdir(parents=True, exist_ok=True)
    path = CACHE / f"{name}_{n}.npy"
    if path.exists():
        data = np.load(path)
        return list(data) if name == "link3" else data
    if name == "fhw":
        P = core.knots.freedman_unknot(n)
    elif name == "7_2":
        P = core.resample(core.knots.named("7_2"), n)
    elif name == "noneq":  # the 7_2 with every vertex moved by 0.2 edge lengths
        Q = curve("7_2", n)
        rng = np.random.default_rng(7)
        P = Q + 0.2 * np.linalg.norm(Q[1] - Q[0]) * rng.standard_normal(Q.shape)
    elif name == "link3":  # a chain of three unit rings 1.2 apart, n // 3 edges each
        t = np.linspace(0, 2 * np.pi, 400, endpoint=False)
        ring = np.c_[np.cos(t), np.sin(t), 0 * t]
        P = core.resample([ring, ring[:, [0, 2, 1]] + [1.2, 0, 0], ring + [2.4, 0, 0]],
                          [n // 3] * 3)
    else:
        raise ValueError(name)
    np.save(path, np.asarray(P))
    return P


def errors(P, thetas=THETAS) -> list[dict]:
    X, layout = as_layout(P)
    E0, G0 = energy_gradient_x(X, layout)
    rows = []
    for theta in thetas:
        E1, G1 = barnes_hut.Frame(X, layout, theta).energy_gradient(X)
        rows.append({"theta": theta, "energy": abs(E1 - E0) / E0,
                     "gradient": float(np.linalg.norm(G1 - G0) / np.linalg.norm(G0))})
    return rows


def timings(P, exact: bool, theta: float) -> dict:
    X, layout = as_layout(P)
    n = layout.n
    row: dict = {"edges": n}
    frame = barnes_hut.Frame(X, layout, theta)
    row["far_pairs"], row["near_pairs"] = frame.far_pairs, frame.near_pairs
    row["tree_eg"] = best_of(lambda: barnes_hut.Frame(X, layout, theta).energy_gradient(X), 7)
    row["tree_e"] = best_of(lambda: barnes_hut.Frame(X, layout, theta).energy(X), 7)
    row["frame"] = best_of(lambda: barnes_hut.Frame(X, layout, theta), 7)
    row["build"] = best_of(lambda: bvh.build(X, layout), 7)
    tree = bvh.build(X, layout)
    row["refit"] = best_of(lambda: bvh.segment_boxes(tree, X, layout), 3)
    if exact:
        row["exact_eg"] = best_of(lambda: energy_gradient_x(X, layout), 2)
        row["speedup"] = row["exact_eg"] / row["tree_eg"]
    # the contact step as the flow calls it: along the gradient, scaled so that the fastest
    # vertex moves 0.1 edge lengths at tau = 1; once with a contact before tau_max, once without
    _, G = frame.energy_gradient(X)
    h = float(np.linalg.norm(X[layout.nxt] - X, axis=1).mean())
    U = G * (0.1 * h / np.abs(G).max())
    eps = 1e-3 * h
    searches = ("pairs", "tree") if exact else ("tree",)
    for search in searches:
        for key, tau_max in (("none", 1.0), ("hit", 1e4)):
            row[f"contact_{key}_{search}"] = best_of(
                lambda t=tau_max, s=search: contact_time_x(X, U, layout, t, eps, search=s), 3)
        row[f"closest_{search}"] = best_of(
            lambda s=search: closest_pairs(X, layout, 4, search=s), 2 if search == "pairs" else 3)
    return row


def million(theta: float) -> None:
    n = 1000000
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    P = np.c_[np.sin(t) + 2 * np.sin(2 * t), np.cos(t) - 2 * np.cos(2 * t), -np.sin(3 * t)]
    X, layout = as_layout(P)
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    barnes_hut.Frame(X[:1000], as_layout(P[:1000])[1], theta).energy_gradient(X[:1000])
    t0 = time.perf_counter()
    barnes_hut.Frame(X, layout, theta).energy_gradient(X)
    seconds = time.perf_counter() - t0
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"10^6 edges (the trefoil curve), theta={theta}: E+g {seconds:.2f} s (frame included, "
          f"compiled before); peak resident memory {peak:.0f} MB (before: {before:.0f} MB)")


def flow(sizes: list[int], theta: float) -> list[dict]:
    """The FHW unknot to E <= 4.01 with the exact engine and with the tree, one run each."""
    rows = []
    for n in sizes:
        P = core.knots.freedman_unknot(n)
        for engine in ("exact", "tree"):
            t0 = time.perf_counter()
            r = core.relax(P, max_iter=400, energy_target=4.01, engine=engine, theta=theta)
            row = {"edges": n, "engine": engine, "theta": theta if engine == "tree" else None,
                   "iterations": r.nit, "seconds": time.perf_counter() - t0,
                   "energy": float(r.fun), "message": r.message}
            rows.append(row)
            print(f"  FHW N={n:5d} {engine:5s}: {row['iterations']} iterations, "
                  f"{row['seconds']:.1f} s, E {row['energy']:.5f} ({r.message})", flush=True)
    return rows


def banded_runs(sizes: list[int], iterations: int = 5,
                metric_names: tuple[str, ...] = ("h1", "h2")) -> list[dict]:
    """The O(N) saddle solver of the banded metrics (core/banded.py) and the flow with it."""
    from moebius_addon.core.geometry.constraints import jacobian, make_constraints
    from moebius_addon.core.geometry.layout import as_unit_layout
    from moebius_addon.core.metrics import banded
    from moebius_addon.core.metrics import gram as metrics

    rows = []
    rng = np.random.default_rng(0)
    for n in sizes:
        P = curve("7_2", n)
        X, layout, _ = as_unit_layout(P)
        X = X / np.linalg.norm(X[layout.nxt] - X, axis=1).sum()
        ln = np.linalg.norm(X[layout.nxt] - X, axis=1)
        con = make_constraints(X, layout, ln)
        jac = jacobian(X, con)
        for metric in metric_names:
            parts = metrics.banded_parts(metric, X, layout)
            row = {"edges": n, "metric": metric,
                   "factor": best_of(lambda p=parts, j=jac: banded.BandedSaddle(p, j), 2)}
            solver = banded.BandedSaddle(parts, jac)
            g = rng.standard_normal((n, 3))
            r = np.zeros(con.size)
            row["solve"] = best_of(lambda s=solver, g=g, r=r: s.solve(g, r), 3)
            u, _ = solver.solve(g, r)
            row["constraint_residual"] = float(np.abs(jac.matvec(u)).max())
            t0 = time.perf_counter()
            res = core.relax(P, metric=metric, max_iter=iterations, engine="tree")
            row["relax_seconds"] = time.perf_counter() - t0
            row["iteration_seconds"] = list(np.diff(res.history["seconds"]))
            row["energies"] = res.history["energy"]
            row["relax_constraint_residual"] = max(res.history["constraint_residual"])
            row["peak_rss_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
            rows.append(row)
            its = row["iteration_seconds"]
            print(f"  7_2 N={n:6d} {metric}: factor {row['factor']:.3f} s, solve "
                  f"{row['solve']:.3f} s (|C u| {row['constraint_residual']:.1e}); relax "
                  f"{iterations} iterations {row['relax_seconds']:.1f} s in all, per "
                  f"iteration {' '.join(f'{t:.2f}' for t in its)} s (median "
                  f"{np.median(its):.2f}), E {row['energies'][0]:.2f} -> "
                  f"{row['energies'][-1]:.2f}, constraints <= "
                  f"{row['relax_constraint_residual']:.1e}; peak memory so far "
                  f"{row['peak_rss_mb']:.0f} MB", flush=True)
    return rows


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--sizes", type=int, nargs="*", default=[1000, 2000, 5000, 10000, 20000,
                                                              100000])
    ap.add_argument("--error-sizes", type=int, nargs="*", default=[5000, 20000])
    ap.add_argument("--theta", type=float, default=barnes_hut.THETA)
    ap.add_argument("--million", action="store_true")
    ap.add_argument("--flow", type=int, nargs="*", default=None,
                    help="only the flow comparison at these edge counts")
    ap.add_argument("--banded", type=int, nargs="*", default=None,
                    help="only the banded metrics on the tree path at these edge counts")
    ap.add_argument("--iterations", type=int, default=5,
                    help="iterations of the flow in --banded")
    ap.add_argument("--metrics", nargs="*", default=["h1", "h2"], help="metrics of --banded")
    ap.add_argument("--json", default="out/bench_tree.json")
    args = ap.parse_args()
    out: dict = {"machine": machine(), "theta": args.theta, "leaf_size": bvh.LEAF_SIZE}
    print(out["machine"], flush=True)
    if args.million:
        million(args.theta)
        return
    if args.banded is not None:
        print("\nBanded metrics on the tree path (O(N) saddle solves), 7_2:", flush=True)
        out["banded"] = banded_runs(args.banded or [20000, 100000], args.iterations,
                                    args.metrics)
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps(out, indent=1))
        return
    if args.flow is not None:
        print(f"\nFHW to E <= 4.01, exact against tree (theta={args.theta}):", flush=True)
        out["flow"] = flow(args.flow or [600, 1184, 1648], args.theta)
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps(out, indent=1))
        return

    print("\nresample to 100 000 edges (<= 2 s), seconds:", flush=True)
    out["resample"] = {}
    for name in ("3_1", "7_2"):
        P = core.knots.named(name)
        t0 = time.perf_counter()
        core.resample(P, 100000)
        out["resample"][name] = time.perf_counter() - t0
        print(f"  {name}: {out['resample'][name]:.2f}", flush=True)
    t0 = time.perf_counter()
    core.resample(core.knots.named("3_1"), 1000000)
    out["resample"]["3_1 at 10^6"] = time.perf_counter() - t0
    print(f"  3_1 to 10^6 edges: {out['resample']['3_1 at 10^6']:.2f}", flush=True)

    print(f"\nEnergy+gradient (7_2, theta={args.theta}), seconds (tree: best of 7, exact: of 2):",
          flush=True)
    out["timings"] = []
    for n in args.sizes:
        row = timings(curve("7_2", n), n <= EXACT_UP_TO, args.theta)
        out["timings"].append(row)
        exact = (f"exact {row['exact_eg']:.4f}  ratio {row['speedup']:.1f}x"
                 if "exact_eg" in row else "exact -")
        print(f"  N={n:7d}: tree E+g {row['tree_eg']:.4f} (E {row['tree_e']:.4f}, frame "
              f"{row['frame']:.4f}, build {row['build']:.4f}, refit {row['refit']:.5f})  "
              f"{exact}  far/near pairs {row['far_pairs']}/{row['near_pairs']}", flush=True)
        for search in ("pairs", "tree"):
            if f"closest_{search}" in row:
                print(f"           contact step ({search}) {row[f'contact_none_{search}']:.4f} "
                      f"(no contact) / {row[f'contact_hit_{search}']:.4f} (contact); closest "
                      f"pairs {row[f'closest_{search}']:.4f}", flush=True)

    print("\nRelative errors against the exact sum (energy, gradient 2-norm):", flush=True)
    out["errors"] = []
    for n in args.error_sizes:
        for name in ("fhw", "7_2", "link3", "noneq"):
            for r in errors(curve(name, n)):
                out["errors"].append({"curve": name, "edges": n, **r})
                print(f"  {name:6s} N={n:6d} theta={r['theta']:<7g} energy {r['energy']:.2e}  "
                      f"gradient {r['gradient']:.2e}", flush=True)

    out["peak_rss_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"\npeak resident memory of this process: {out['peak_rss_mb']:.0f} MB")
    Path(args.json).parent.mkdir(parents=True, exist_ok=True)
    Path(args.json).write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
