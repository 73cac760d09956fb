"""Seconds per iteration against the edge count, exact and tree engines, on a log-log plot.

    python bench/scaling_plot.py                         # about 2 min on the 2-core machine
    python bench/scaling_plot.py --sizes 500 1000 --iterations 3 --out out/scaling

For each configuration and size: 7_2 resampled to N edges, ``core.relax`` for a few
iterations, the median of the seconds between iterates (the first iterate, which pays for the
set-up, is left out when there are more). Prints one line per run, writes ``scaling.json`` and
``scaling.png`` (with N log N and N^3 guide lines through the first point of the tree and the
exact runs). Prints measurements; not a test.
"""

from __future__ import annotations

import argparse
import json
import resource
import time
from pathlib import Path

import numpy as np

from moebius_addon import core

# (engine, metric, largest N): the exact engine is dense (O(N^3) per iteration, 32 bytes per
# vertex pair), the tree engine holds nothing dense (hs: Krylov solves; h2: a band solver)
CONFIGS = (("exact", "hs", 5000), ("exact", "h2", 5000), ("tree", "hs", 100_000),
           ("tree", "h2", 100_000))


def run(n: int, engine: str, metric: str, iterations: int) -> dict:
    P = core.resample(core.knots.named("7_2"), n)
    t0 = time.perf_counter()
    res = core.relax(P, metric=metric, engine=engine, max_iter=iterations, tol=0.0)
    total = time.perf_counter() - t0
    steps = np.diff(res.history["seconds"])
    per = float(np.median(steps[1:] if len(steps) > 1 else steps))
    return {"edges": n, "engine": engine, "metric": metric, "iterations": int(res.nit),
            "seconds_per_iteration": per, "seconds": total,
            "energy": [float(res.history["energy"][0]), float(res.fun)],
            "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}


def plot(rows: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 5))
    for engine, metric, _ in CONFIGS:
        pts = sorted((r["edges"], r["seconds_per_iteration"]) for r in rows
                     if r["engine"] == engine and r["metric"] == metric)
        if pts:
            n, s = np.array(pts).T
            ax.loglog(n, s, "o-" if engine == "tree" else "s--",
                      label=f"{engine}, {metric}")
    n_all = np.array(sorted({r["edges"] for r in rows}), dtype=float)
    for engine, power, style in (("tree", None, ":"), ("exact", 3, "-.")):
        first = min((r for r in rows if r["engine"] == engine), default=None,
                    key=lambda r: (r["edges"], r["seconds_per_iteration"]))
        if first is None:
            continue
        n0, s0 = first["edges"], first["seconds_per_iteration"]
        n = n_all[n_all >= n0]
        if power is None:
            guide, label = s0 * n * np.log(n) / (n0 * np.log(n0)), "N log N"
        else:
            n = n[n <= 4 * max(r["edges"] for r in rows if r["engine"] == engine)]
            guide, label = s0 * (n / n0) ** power, "N³"
        ax.loglog(n, guide, style, color="grey", label=label)
    ax.set_xlabel("edges N")
    ax.set_ylabel("seconds per iteration (median)")
    ax.set_title("7_2, seconds per iteration (2-core VM)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="*",
                    default=[500, 1000, 2000, 5000, 10_000, 20_000, 50_000, 100_000])
    ap.add_argument("--iterations", type=int, default=4)
    ap.add_argument("--out", type=Path, default=Path("out/scaling"))
    args = ap.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    for engine, metric, _ in CONFIGS:  # compile every kernel first
        core.relax(core.knots.named("3_1"), metric=metric, engine=engine, max_iter=2)
    rows = []
    for n in args.sizes:
        for engine, metric, largest in CONFIGS:
            if n > largest:
                continue
            row = run(n, engine, metric, args.iterations)
            rows.append(row)
            print(f"N={n:6d} {engine:5s} {metric:3s}: {row['seconds_per_iteration']:8.3f} s per "
                  f"iteration ({row['iterations']} iterations, {row['seconds']:.1f} s in all; "
                  f"E {row['energy'][0]:.2f} -> {row['energy'][1]:.2f}; peak memory so far "
                  f"{row['peak_rss_mb']:.0f} MB)", flush=True)
            (args.out / "scaling.json").write_text(json.dumps(rows, indent=1))
    plot(rows, args.out / "scaling.png")
    print(f"wrote {args.out / 'scaling.json'} and {args.out / 'scaling.png'}")


if __name__ == "__main__":
    main()
