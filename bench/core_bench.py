"""Benchmark of the numerical core (issue: core engine). Prints measurements; not a test.

    python bench/core_bench.py                 # everything (about 15-30 min on 2 cores)
    python bench/core_bench.py --only ratio    # one part: fhw, helix, knot72, ratio, sizes
    python bench/core_bench.py --quick         # smaller sizes, a few minutes

Results also go to ``out/bench_core.json`` (``--json PATH``).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numba
import numpy as np
from paper import machine  # bench/ is on sys.path when run as a script

from moebius_addon import core
from moebius_addon.core.energies.moebius_dense import energy_gradient_x, energy_x
from moebius_addon.core.geometry.collision import contact_time_x
from moebius_addon.core.geometry.constraints import jacobian
from moebius_addon.core.metrics.gram import gram_x
from moebius_addon.core.metrics.saddle import Factorization
from moebius_addon.core.topology import knots


def best_of(f, repeat=5):
    f()
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        f()
        times.append(time.perf_counter() - t)
    return min(times)


def to_round(P, name, target=4.01, max_iter=400, **kw):
    t = time.perf_counter()
    r = core.relax(P, max_iter=max_iter, energy_target=target, **kw)
    dt = time.perf_counter() - t
    row = {
        "curve": name,
        "edges": len(P),
        "iterations": r.nit,
        "seconds": round(dt, 2),
        "final_energy": r.fun,
        "message": r.message,
        "seconds_per_iteration": round(dt / max(r.nit, 1), 4),
        "factorizations": r.stats["factorizations"],
    }
    print(
        f"  {name:>22s} N={len(P):5d}: {r.nit:4d} iterations, {dt:7.1f} s "
        f"({1e3 * dt / max(r.nit, 1):.0f} ms/it), E={r.fun:.5f}  [{r.message}]",
        flush=True,
    )
    return row, r


def bench_fhw(n):
    P = knots.freedman_unknot(n)
    row, _ = to_round(P, "Freedman-He-Wang unknot")
    return row


def bench_helix(n):
    P = knots.helix_unknot(n)
    row, _ = to_round(P, "helix unknot")
    return row


def bench_knot72(n, iters):
    P = knots.named("7_2", n)
    t = time.perf_counter()
    r = core.relax(P, max_iter=iters, tol=0.0, ftol=0.0)
    dt = time.perf_counter() - t
    print(f"  7_2 N={n}: {r.nit} iterations in {dt:.1f} s ({1e3 * dt / r.nit:.0f} ms/it), "
          f"E {r.history['energy'][0]:.3f} -> {r.fun:.3f}  [{r.message}]", flush=True)
    return {"edges": n, "iterations": r.nit, "seconds": round(dt, 2), "energy_start":
            r.history["energy"][0], "energy_end": r.fun}


def bench_ratio(n, iters=8):
    """Cost of a full iteration over one energy+gradient evaluation, with the pieces."""
    P = knots.freedman_unknot(n)
    run = core.Relaxation(P, max_iter=10**6)
    for _ in range(2):  # warm up every kernel (compilation, caches)
        run.step()
    t = time.perf_counter()
    k0 = run.nit
    r0 = run.rejected
    for _ in range(iters):
        if not run.step():
            break
    per_iter = (time.perf_counter() - t) / (run.nit - k0)
    rejected = (run.rejected - r0) / (run.nit - k0)
    X, lay = run.X, run.layout
    A = gram_x("hs", X, lay)
    jac = jacobian(X, run.con)
    dtype = run.engine.solver.dtype
    parts = {
        "energy_gradient": best_of(lambda: energy_gradient_x(X, lay)),
        "energy": best_of(lambda: energy_x(X, lay)),
        "gram_hs": best_of(lambda: gram_x("hs", X, lay), 3),
        "factorization": best_of(lambda: Factorization(A, jac, dtype), 2),
        "contact_bound": best_of(lambda: contact_time_x(X, run.u, lay, 3 * run.tau, run.eps)),
    }
    fac = Factorization(A, jac, dtype)
    parts["preconditioner_apply"] = best_of(lambda: fac.solve(run.g, np.zeros(run.con.size)))
    ratio = per_iter / parts["energy_gradient"]
    print(f"  N={n:5d}: iteration {1e3 * per_iter:8.1f} ms = {ratio:5.1f} x energy+gradient "
          f"({1e3 * parts['energy_gradient']:.2f} ms), {rejected:.1f} rejected trials/it; "
          + ", ".join(f"{k} {1e3 * v:.1f} ms" for k, v in parts.items() if k != "energy_gradient"),
          flush=True)
    return {"edges": n, "seconds_per_iteration": per_iter, "ratio": ratio,
            "parts_seconds": parts, "precision": np.dtype(dtype).name,
            "rejected_trials_per_iteration": rejected,
            "krylov_per_iteration": float(np.mean(run.engine.solver.krylov_its[-iters:]))}


def bench_sizes(sizes):
    rows = []
    for n in sizes:
        rows.append(bench_fhw(n))
    return rows


def bench_too_coarse(n):
    P = core.resample(knots.freedman_unknot(1184), n)
    try:
        core.check_polygon(P)
        msg = "accepted (unexpected)"
    except ValueError as e:
        msg = str(e)
    print(f"  N={n}: {msg}", flush=True)
    return {"edges": n, "message": msg, "contact_ratio": core.contact_ratio(P)}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--only", choices=["fhw", "helix", "knot72", "ratio", "sizes"])
    ap.add_argument("--json", default="out/bench_core.json")
    args = ap.parse_args()
    q = args.quick
    out = {"machine": machine(), "quick": q}
    print("machine:", out["machine"], flush=True)
    todo = [args.only] if args.only else ["ratio", "fhw", "helix", "knot72", "sizes"]
    for part in todo:
        print(f"[{part}]", flush=True)
        if part == "fhw":
            out["fhw"] = bench_fhw(600 if q else 1648)
        elif part == "helix":
            out["helix"] = bench_helix(700 if q else 1940)
        elif part == "knot72":
            out["knot72"] = bench_knot72(1000 if q else 3000, 20 if q else 100)
        elif part == "ratio":
            out["ratio"] = [bench_ratio(n) for n in ((500, 1000) if q else (500, 1648, 3000))]
        elif part == "sizes":
            out["too_coarse"] = bench_too_coarse(300)
            out["sizes"] = bench_sizes((600, 1200) if q else (600, 1200, 2400))
    out["machine"]["threading_layer"] = numba.threading_layer()
    print("threading layer:", out["machine"]["threading_layer"])
    path = Path(args.json)
    path.parent.mkdir(parents=True, exist_ok=True)
    old = json.loads(path.read_text()) if path.exists() and args.only else {}
    old.update(out)
    path.write_text(json.dumps(old, indent=1, default=float))
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
