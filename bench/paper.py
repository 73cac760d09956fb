"""The paper's optimizer comparison (Reiter & Schumacher, Figs. 3 and 4): every method
of ``core.runs.methods`` with every metric on the Freedman–He–Wang unknot, a fixed wall-time budget
per run, plus iterations-to-round (E ≤ 4.01) against the edge count for the explicit projected
gradient with hs, h1 and l2.

    python bench/paper.py --quick            # N = 600, 12 s per run, helix scaling: < 10 min
    python bench/paper.py                    # N = 1200, 90 s per run, FHW at 600/1200/2400
    python bench/paper.py --csv out/p.csv --n 800 --budget 30 --methods lbfgs,ncg

Writes (``--out``, default ``out/paper``): ``paper.csv`` (``--csv``; one row per run: method,
metric, iterations, seconds, final_energy, …), ``paper_traces.csv`` (every iterate of every run),
``paper_scaling.csv``, ``paper_alpha.csv`` (penalty weight sweep), ``paper_meta.json`` (machine,
command) and the plots ``energy_vs_time.png``, ``energy_vs_iteration.png``, ``scaling.png``.
Timings depend on the machine and on whatever else runs on it.
"""

from __future__ import annotations

import argparse
import csv
import gc
import json
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

from moebius_addon.core import relax, resample
from moebius_addon.core.metrics.gram import METRICS
from moebius_addon.core.runs.methods import FEASIBLE, INFEASIBLE, METHODS
from moebius_addon.core.topology import knots

# Factorization precision of the feasible methods: the penalty methods factor in double
# precision, so the comparison does too (``--precision auto`` for the core's default).
PRECISION = "double"
ROUND = 4.01  # "round": the paper's circle is reached at about this energy
COLORS = {"l2": "tab:blue", "h1": "tab:orange", "h2": "tab:purple", "hs_pure": "tab:red",
          "hs": "tab:green"}  # green for the geometric W^{3/2,2}, as in the paper
LABELS = {"l2": "$L^2$", "h1": "$W^{1,2}$", "h2": "$W^{2,2}$", "hs_pure": "pure $W^{3/2,2}$",
          "hs": "geometric $W^{3/2,2}$"}
DASHES = {"projected_gradient": "-", "projected_gradient_implicit": "--", "trust_region": ":",
          "ncg": "-", "lbfgs": "--", "nesterov": "-."}


def machine() -> dict:
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as f:
            cpu = next(line.split(":", 1)[1].strip() for line in f if line.startswith("model name"))
    except (OSError, StopIteration):
        pass
    import numba

    return {
        "cpu": cpu,
        "cores": os.cpu_count(),
        "load_average_at_start": os.getloadavg(),
        "python": platform.python_version(),
        "numpy": np.__version__,
        "numba": numba.__version__,
        "numba_threads": numba.get_num_threads(),
    }


def warm_up() -> None:
    """Compile (or load from the numba cache) every kernel before anything is timed."""
    t = np.linspace(0, 2 * np.pi, 200, endpoint=False)
    P = resample(np.c_[np.sin(t) + 2 * np.sin(2 * t), np.cos(t) - 2 * np.cos(2 * t),
                       -np.sin(3 * t)], 60)
    for method in METHODS:
        for metric in METRICS:
            relax(P, metric=metric, max_iter=2, method=method)


def first_reaching(hist: dict, target: float):
    for k, e in enumerate(hist["energy"]):
        if e <= target:
            return k, hist["seconds"][k]
    return None, None


def one_run(P, method, metric, budget, **options) -> tuple[dict, dict]:
    gc.collect()
    if method in FEASIBLE:  # the penalty weight means nothing with hard constraints
        options = {"precision": PRECISION, **{k: v for k, v in options.items() if k != "penalty"}}
    else:
        options = {k: v for k, v in options.items() if k != "precision"}
    max_iter = options.pop("max_iter", 100000)  # --options '{"max_iter": 2}' caps every run
    t = time.perf_counter()
    try:
        r = relax(P, metric=metric, max_iter=max_iter, method=method, max_seconds=budget,
                  **options)
    except Exception as e:  # a failing combination is a result too
        r = None
        error = f"error: {type(e).__name__}: {e}"
    wall = time.perf_counter() - t
    if r is None:
        h = {"energy": [], "seconds": [], "constraint_residual": [float("nan")],
             "grad_norm": []}
        row = {"method": method, "family": "feasible" if method in FEASIBLE else "infeasible",
               "metric": metric, "n": len(P), "budget_s": budget, "iterations": 0,
               "seconds": round(wall, 3), "final_energy": float("nan"),
               "iterations_to_4.01": "", "seconds_to_4.01": "",
               "max_constraint_violation": float("nan"), "rejected_steps": "",
               "success": False, "message": error}
        return row, h
    h = r.history
    k, s = first_reaching(h, ROUND)
    row = {
        "method": method,
        "family": "feasible" if method in FEASIBLE else "infeasible",
        "metric": metric,
        "n": len(P),
        "budget_s": budget,
        "iterations": r.nit,
        "seconds": round(wall, 3),
        "final_energy": r.fun,
        "iterations_to_4.01": "" if k is None else k,
        "seconds_to_4.01": "" if s is None else round(s, 3),
        "max_constraint_violation": max(h["constraint_residual"]),
        "rejected_steps": r.stats.get("rejected_steps", ""),
        "success": r.success,
        "message": r.message,
    }
    return row, h


def write_csv(path: Path, rows: list[dict]) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)


def comparison(args, out: Path) -> tuple[list[dict], dict]:
    P = knots.freedman_unknot(args.n)
    rows, traces = [], {}
    trace_rows = []
    for method in args.methods:
        for metric in args.metrics:
            row, h = one_run(P, method, metric, args.budget, **args.options)
            rows.append(row)
            traces[method, metric] = h
            for k in range(len(h["energy"])):
                trace_rows.append({
                    "method": method, "metric": metric, "iteration": k,
                    "seconds": round(h["seconds"][k], 4), "energy": h["energy"][k],
                    "grad_norm": h["grad_norm"][k],
                    "constraint_residual": h["constraint_residual"][k],
                })
            print(f"{method:28s} {metric:8s} it={row['iterations']:5d} "
                  f"E={row['final_energy']:10.5f} t={row['seconds']:6.1f}s "
                  f"to4.01={row['iterations_to_4.01']!s:>4} {row['message'][:50]}", flush=True)
            write_csv(args.csv, rows)  # keep what is done if interrupted
    write_csv(args.traces, trace_rows)
    return rows, traces


def alpha_sweep(args) -> list[dict]:
    P = knots.freedman_unknot(args.n)
    rows = []
    for alpha in args.alphas:
        row, h = one_run(P, "lbfgs", "hs", args.budget, penalty=alpha)
        row = {"alpha": alpha, **row,
               "final_max_log_stretch": h["constraint_residual"][-1]}
        rows.append(row)
        print(f"alpha={alpha:g}: lbfgs hs it={row['iterations']} E={row['final_energy']:.5f} "
              f"max|log stretch|={row['max_constraint_violation']:.3g} (final "
              f"{row['final_max_log_stretch']:.3g})", flush=True)
    return rows


def scaling(args) -> list[dict]:
    make = knots.freedman_unknot if args.scaling_curve == "fhw" else knots.helix_unknot
    rows = []
    for n in args.scaling_n:
        P = make(n)
        for metric in ("hs", "h1", "l2"):
            gc.collect()
            t = time.perf_counter()
            r = relax(P, metric=metric, max_iter=args.scaling_cap, energy_target=ROUND,
                      max_seconds=args.scaling_seconds, precision=PRECISION)
            rows.append({
                "curve": args.scaling_curve, "n": n, "metric": metric,
                "iterations_to_4.01": r.nit if r.fun <= ROUND else "",
                "iterations_run": r.nit, "final_energy": r.fun,
                "seconds": round(time.perf_counter() - t, 2), "message": r.message,
            })
            print(f"scaling {args.scaling_curve} n={n:5d} {metric:3s} it={r.nit:4d} "
                  f"E={r.fun:10.4f} {rows[-1]['seconds']:7.1f}s {r.message[:50]}", flush=True)
    return rows


def _legend(ax, methods, metrics):
    from matplotlib.lines import Line2D

    handles = [Line2D([], [], color=COLORS[m], lw=2, label=LABELS[m]) for m in metrics]
    handles += [Line2D([], [], color="k", ls=DASHES[m], lw=1.4, label=m) for m in methods]
    ax.legend(handles=handles, fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.14),
              ncol=4, frameon=False)


def plot_comparison(traces: dict, args, out: Path) -> list[Path]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    excess = [np.asarray(h["energy"]) - 4.0 for h in traces.values() if h["energy"]]
    # below 1e-3 (E ≤ 4.001) every curve is round: the plot stops there
    lo = max(min(float(e.min()) for e in excess) / 2.0, 1e-3)
    hi = max(float(e.max()) for e in excess) * 1.5
    paths = []
    for xkey, fname, xlabel in (("seconds", "energy_vs_time.png", "wall time [s]"),
                                ("iteration", "energy_vs_iteration.png", "iteration")):
        fig, axes = plt.subplots(1, 2, figsize=(12, 5.4), sharey=True)
        for ax, family, title in ((axes[0], FEASIBLE, "feasible (constraints kept)"),
                                  (axes[1], INFEASIBLE, "infeasible (stretch penalty)")):
            for (method, metric), h in traces.items():
                if method not in family or not h["energy"]:
                    continue
                y = np.maximum(np.asarray(h["energy"]) - 4.0, 0.5 * lo)
                x = h["seconds"] if xkey == "seconds" else np.arange(1, len(y) + 1)
                ax.plot(x, y, DASHES[method], color=COLORS[metric], lw=1.3)
            ax.set_yscale("log")
            if xkey == "iteration":
                ax.set_xscale("log")
            ax.set_ylim(lo, hi)
            if lo < ROUND - 4.0:
                ax.axhline(ROUND - 4.0, color="0.6", lw=0.8)
            ax.set_title(title)
            ax.set_xlabel(xlabel if xkey == "seconds" else "iteration + 1")
            ax.grid(True, which="major", alpha=0.3)
            _legend(ax, [m for m in family if m in args.methods], args.metrics)
        axes[0].set_ylabel("Möbius energy − 4")
        fig.suptitle(f"FHW unknot, {args.n} edges, {args.budget:g} s per run"
                     + (f" (grey line: E = {ROUND})" if lo < ROUND - 4.0 else ""), fontsize=10)
        fig.tight_layout()
        path = out / fname
        fig.savefig(path, dpi=args.dpi)
        plt.close(fig)
        paths.append(path)
    return paths


def plot_scaling(rows: list[dict], args, out: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    marks = {"hs": "o", "h1": "s", "l2": "^"}
    shift = {"hs": 1.0, "h1": 0.96, "l2": 1.04}  # keeps capped runs apart
    for metric in ("hs", "h1", "l2"):
        rs = [r for r in rows if r["metric"] == metric]
        ns = [r["n"] * shift[metric] for r in rs]
        its = [r["iterations_run"] for r in rs]
        reached = [r["iterations_to_4.01"] != "" for r in rs]
        c = COLORS[metric]
        axes[0].plot(ns, its, "-", color=c, label=LABELS[metric])
        for n, it, ok in zip(ns, its, reached, strict=True):
            axes[0].plot(n, it, marks[metric], color=c, mfc=c if ok else "white")
        axes[1].plot(ns, [max(r["final_energy"] - 4.0, 1e-12) for r in rs], "-" + marks[metric],
                     color=c, label=LABELS[metric])
    for ax in axes:
        ax.set_xscale("log", base=2)
        ax.set_xticks(args.scaling_n, [str(n) for n in args.scaling_n])
        ax.minorticks_off()
        ax.set_xlabel("edges")
        ax.legend(fontsize=8)
    axes[0].set_ylim(0, None)
    axes[0].set_ylabel(f"iterations to E ≤ {ROUND} (open: not reached)")
    axes[1].set_yscale("log")
    axes[1].set_ylabel("E − 4 at the end of the run")
    name = "FHW unknot" if args.scaling_curve == "fhw" else "helix unknot"
    fig.suptitle(f"explicit projected gradient, {name}; at most {args.scaling_cap} iterations "
                 f"or {args.scaling_seconds:g} s", fontsize=10)
    fig.tight_layout()
    path = out / "scaling.png"
    fig.savefig(path, dpi=args.dpi)
    plt.close(fig)
    return path


def _read_csv(path: Path) -> list[dict]:
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def replot(args) -> int:
    meta = json.loads((args.out / "paper_meta.json").read_text())
    args.n, args.budget = meta["n"], meta["budget_s"]
    sc = meta["scaling"]
    args.scaling_curve, args.scaling_n = sc["curve"], sc["n"]
    args.scaling_cap, args.scaling_seconds = sc["cap"], sc["seconds"]
    if args.traces.exists():
        traces: dict = {}
        for r in _read_csv(args.traces):
            h = traces.setdefault((r["method"], r["metric"]), {"energy": [], "seconds": []})
            h["energy"].append(float(r["energy"]))
            h["seconds"].append(float(r["seconds"]))
        args.methods = [m for m in METHODS if any(k[0] == m for k in traces)]
        args.metrics = [m for m in METRICS if any(k[1] == m for k in traces)]
        for path in plot_comparison(traces, args, args.out):
            print("wrote", path)
    scaling_csv = args.out / "paper_scaling.csv"
    if scaling_csv.exists():
        rows = _read_csv(scaling_csv)
        for r in rows:
            r["n"] = int(r["n"])
            r["iterations_run"] = int(r["iterations_run"])
            r["final_energy"] = float(r["final_energy"])
        print("wrote", plot_scaling(rows, args, args.out))
    return 0


def parse(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--quick", action="store_true",
                   help="N=600, 12 s per run, helix scaling at 150/300/600 (< 10 min)")
    p.add_argument("--out", type=Path, default=Path("out/paper"))
    p.add_argument("--csv", type=Path, help="results table (default OUT/paper.csv)")
    p.add_argument("--traces", type=Path, help="every iterate (default: CSV name + _traces)")
    p.add_argument("--n", type=int, help="edges of the FHW unknot (1200; quick 600)")
    p.add_argument("--budget", type=float, help="wall-time budget per run in s (90; quick 12)")
    p.add_argument("--methods", default=",".join(METHODS))
    p.add_argument("--metrics", default=",".join(METRICS))
    p.add_argument("--alpha", type=float, help="penalty weight of the infeasible methods")
    p.add_argument("--alphas", default="1e3,1e5", help="extra penalty weights for lbfgs+hs")
    p.add_argument("--options", default="{}",
                   help='JSON of further options for every run, e.g. \'{"cg_iter": 100}\'')
    p.add_argument("--scaling-n", help="edge counts (600,1200,2400; quick 150,300,600)")
    p.add_argument("--scaling-curve", choices=("fhw", "helix"))
    p.add_argument("--scaling-cap", type=int, help="iterations at most (300)")
    p.add_argument("--scaling-seconds", type=float, help="seconds at most (1200; quick 25)")
    p.add_argument("--skip", default="", help="parts to leave out: comparison,alpha,scaling")
    p.add_argument("--precision", choices=("double", "single", "auto"), default="double",
                   help="factorization precision of the feasible methods (default double)")
    p.add_argument("--replot", action="store_true",
                   help="only redraw the plots from the CSV files of an earlier run in --out")
    p.add_argument("--dpi", type=int, default=110)
    args = p.parse_args(argv)
    q = args.quick
    args.n = args.n or (600 if q else 1200)
    args.budget = args.budget or (12.0 if q else 90.0)
    args.methods = [m for m in args.methods.split(",") if m]
    args.metrics = [m for m in args.metrics.split(",") if m]
    for m in args.methods:
        if m not in METHODS:
            p.error(f"unknown method {m!r}; choose from {', '.join(METHODS)}")
    for m in args.metrics:
        if m not in METRICS:
            p.error(f"unknown metric {m!r}; choose from {', '.join(METRICS)}")
    args.options = json.loads(args.options)
    if args.alpha is not None:
        args.options["penalty"] = args.alpha
    args.alphas = [float(a) for a in args.alphas.split(",") if a]
    args.scaling_n = [int(n) for n in (args.scaling_n or ("150,300,600" if q else
                                                            "600,1200,2400")).split(",")]
    args.scaling_curve = args.scaling_curve or ("helix" if q else "fhw")
    args.scaling_cap = args.scaling_cap or 300
    args.scaling_seconds = args.scaling_seconds or (25.0 if q else 1200.0)
    args.skip = set(filter(None, args.skip.split(",")))
    args.csv = args.csv or args.out / "paper.csv"
    args.traces = args.traces or args.csv.with_name(args.csv.stem + "_traces.csv")
    return args


def main(argv=None) -> int:
    global PRECISION
    args = parse(argv)
    PRECISION = args.precision
    out = args.out
    out.mkdir(parents=True, exist_ok=True)
    meta = {"command": " ".join(["python", "bench/paper.py", *(argv or sys.argv[1:])]),
            "machine": machine(), "n": args.n, "budget_s": args.budget,
            "precision": args.precision, "options": args.options,
            "scaling": {"curve": args.scaling_curve, "n": args.scaling_n,
                        "cap": args.scaling_cap, "seconds": args.scaling_seconds}}
    if args.replot:
        return replot(args)
    print(json.dumps(meta["machine"]), flush=True)
    (out / "paper_meta.json").write_text(json.dumps(meta, indent=1))  # --replot mid-run
    t0 = time.perf_counter()
    warm_up()
    if "comparison" not in args.skip:
        rows, traces = comparison(args, out)
        for path in plot_comparison(traces, args, out):
            print("wrote", path)
        print("wrote", args.csv, "and", args.traces)
    if "alpha" not in args.skip and args.alphas:
        write_csv(out / "paper_alpha.csv", alpha_sweep(args))
    if "scaling" not in args.skip:
        srows = scaling(args)
        write_csv(out / "paper_scaling.csv", srows)
        print("wrote", plot_scaling(srows, args, out))
    meta["total_seconds"] = round(time.perf_counter() - t0, 1)
    meta["load_average_at_end"] = os.getloadavg()
    (out / "paper_meta.json").write_text(json.dumps(meta, indent=1))
    print(f"total {meta['total_seconds']} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
