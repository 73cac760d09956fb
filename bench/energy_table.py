"""The Möbius-energy table: every prime knot up to 10 crossings (250 with the unknot) relaxed to
convergence at two resolutions, the energy extrapolated in the edge count.

For each knot: ``core.knots.named(name)`` at its default edge count ``n1`` is relaxed by the
implicit projected gradient (``projected_gradient_implicit``: it converges on knots where the
explicit method stalls, docs/lab/flows-and-methods.md, "Knots of the table") until the metric
gradient norm falls below ``--tol`` (or ``--max-iter`` iterations, or ``--max-seconds``); the
relaxed polygon is then resampled to ``n2 = 2 n1`` edges and relaxed again from there. The
discretization error of the energy of a relaxed polygon falls as ``n^-p``; with ``p`` from
``--order`` (measured on the trefoil by ``--order-study``) Richardson extrapolation gives
``E_∞ = E(n2) + (E(n2) − E(n1)) / (2^p − 1)``. The relaxed curve is identified
(``core.identify``) to check it is still the knot it started as.

The knots run as one ``core.runs.batch`` job (one task per knot, ``stages=(1, 2)``, largest first;
``--workers``/``--threads`` a local Dask cluster, ``--scheduler`` a running one, ``--workers 0``
this process; docs/api.md "Batch runs"), resumable in ``out/energy_table/batch``. Finished
knots become rows of ``docs/data/energy_table.csv`` (name, crossings, n1, E1, iterations,
seconds, status, n2, E2, iterations, seconds, status, extrapolated, identified), their relaxed
polygons at ``n2`` ``out/energy_table/<name>_<n2>.obj``. Knots already in the CSV are skipped,
so the run can be stopped and started again. ``--pack`` gathers the relaxed polygons at ``n2``
edges of every row into ``docs/data/energy_table_curves.npz`` (one float32 array per knot,
centred and scaled to unit edge length; ``--check-pack`` recomputes their energies against the CSV);
``--reidentify`` names every relaxed curve again with the current ``core.identify``::

    .venv/bin/python bench/energy_table.py                     # all 250, hours
    .venv/bin/python bench/energy_table.py --names 3_1 4_1     # some
    .venv/bin/python bench/energy_table.py --min-crossings 11 --max-crossings 11 --limit 20 \
        --csv docs/data/energy_table_11.csv --workers 2          # a slice of 11 crossings
    .venv/bin/python bench/energy_table.py --order-study 3_1   # E(n) at n, 2n, 4n
    .venv/bin/python bench/energy_table.py --pack              # the curves, for the docs
"""

from __future__ import annotations

import argparse
import csv
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from moebius_addon import core  # noqa: E402
from moebius_addon.core.runs import batch  # noqa: E402
from moebius_addon.core.topology import knots  # noqa: E402

CSV = ROOT / "docs" / "data" / "energy_table.csv"
CURVES = ROOT / "docs" / "data" / "energy_table_curves.npz"
OBJ = ROOT / "out" / "energy_table"
BATCH = OBJ / "batch"
FIELDS = ["name", "crossings", "n1", "energy1", "iterations1", "seconds1", "status1", "n2",
          "energy2", "iterations2", "seconds2", "status2", "extrapolated", "identified"]
METHOD = "projected_gradient_implicit"


def relax(P, args):
    t0 = time.perf_counter()
    r = core.relax(P, method=METHOD, max_iter=args.max_iter, tol=args.tol,
                   max_seconds=args.max_seconds)
    return r, time.perf_counter() - t0


def table_names(max_crossings: int, min_crossings: int = 0) -> list[str]:
    return [n for n in knots.names("knot")
            if min_crossings <= knots.info(n)["crossings"] <= max_crossings]


def table_tasks(names: list[str], args) -> list[batch.Task]:
    """One batch task per knot: its table default ``n1`` edges (the unknot 100), relaxed, then
    resampled to ``2 n1`` and relaxed again (``stages=(1, 2)``), identified at the end."""
    return [batch.Task(name, "knot", name, batch.default_edges(name), (1.0, 2.0),
                       method=METHOD, tol=args.tol, max_iter=args.max_iter,
                       max_seconds=args.max_seconds, identify=True) for name in names]


def table_row(r: dict, order: float) -> dict:
    """The table's row from a batch row (results.csv of ``core.runs.batch``)."""
    e1, e2 = float(r["energy1"]), float(r["energy2"])
    extrapolated = e2 + (e2 - e1) / (2.0 ** order - 1.0)
    return {"name": r["name"], "crossings": knots.info(r["name"])["crossings"], "n1": r["n1"],
            "energy1": f"{e1:.6f}", "iterations1": r["iterations1"],
            "seconds1": f"{float(r['seconds1']):.1f}", "status1": r["status1"], "n2": r["n2"],
            "energy2": f"{e2:.6f}", "iterations2": r["iterations2"],
            "seconds2": f"{float(r['seconds2']):.1f}", "status2": r["status2"],
            "extrapolated": f"{extrapolated:.4f}", "identified": r["identified"]}


def order_study(name: str, args) -> None:
    """Energies of the relaxed knot at n, 2n, 4n (each relaxed from the last, resampled) and
    the order p the three give: (E(n) − E(2n)) / (E(2n) − E(4n)) = 2^p."""
    P = knots.named(name)
    energies = []
    for k in range(3):
        r, s = relax(P, args)
        energies.append(float(r.fun))
        print(f"{name} at {len(P)} edges: E = {r.fun:.6f} ({r.nit} iterations, {s:.1f} s, "
              f"{r.status.name}); load {os.getloadavg()[0]:.2f}", flush=True)
        if k < 2:
            P = core.resample(r.x, 2 * len(P))
    d1, d2 = energies[0] - energies[1], energies[1] - energies[2]
    if d1 > 0 and d2 > 0:
        p = np.log2(d1 / d2)
        print(f"order p = log2({d1:.6f} / {d2:.6f}) = {p:.3f}; extrapolated "
              f"{energies[2] + d2 / (2 ** p - 1):.4f}")


def read_rows(path: Path = CSV) -> list[dict]:
    with path.open() as f:
        return list(csv.DictReader(f))


def pack(rows: list[dict], path: Path = CURVES) -> None:
    """The relaxed polygons at ``n2`` edges of ``rows`` into one npz: float32, centred at the
    barycenter and scaled to edge length 1 (the energy is scale invariant), keyed by name.
    Curves already in the file and not in ``out/energy_table`` are kept."""
    curves = dict(np.load(path)) if path.exists() else {}
    for r in rows:
        obj = OBJ / f"{r['name']}_{r['n2']}.obj"
        if not obj.exists():
            if r["name"] not in curves:
                print(f"{r['name']}: no {obj.name} and not packed before", flush=True)
            continue
        P = core.read_obj(obj)[0]
        P = P - P.mean(axis=0)
        P /= np.linalg.norm(np.roll(P, -1, axis=0) - P, axis=1).mean()
        curves[r["name"]] = P.astype(np.float32)
    names = [r["name"] for r in rows if r["name"] in curves]
    np.savez_compressed(path, **{n: curves[n] for n in names})
    print(f"{path}: {len(names)} curves, {sum(len(curves[n]) for n in names)} vertices, "
          f"{path.stat().st_size} bytes")


def check_pack(rows: list[dict], path: Path = CURVES) -> None:
    """The energy of every packed curve (float32 coordinates) against the CSV's ``energy2``."""
    curves = np.load(path)
    worst = 0.0
    for r in rows:
        if r["name"] not in curves:
            continue
        e = core.moebius_energy(curves[r["name"]].astype(np.float64), engine="exact")
        rel = abs(e - float(r["energy2"])) / float(r["energy2"])
        worst = max(worst, rel)
        if rel > 2e-5:  # float32 coordinates: a few 1e-6 expected
            print(f"{r['name']}: packed curve has E = {e:.6f}, the table {r['energy2']}")
    print(f"{len(curves.files)} packed curves; largest relative energy difference {worst:.2e}")


def reidentify(rows: list[dict], path: Path) -> None:
    """Identify every row's relaxed polygon at ``n2`` edges again with the current
    ``core.identify`` (the run's OBJ, else the packed curve) and rewrite the CSV's
    ``identified`` column."""
    packed = np.load(CURVES) if CURVES.exists() else None
    changed = 0
    for r in rows:
        obj = OBJ / f"{r['name']}_{r['n2']}.obj"
        if obj.exists():
            P = core.read_obj(obj)[0]
        elif packed is not None and r["name"] in packed.files:
            P = packed[r["name"]].astype(np.float64)
        else:
            print(f"{r['name']}: no relaxed curve to identify")
            continue
        found = " | ".join(core.identify(P).names)
        if found != r["identified"]:
            print(f"{r['name']}: {r['identified']} -> {found}")
            changed += 1
        r["identified"] = found
    with path.open("w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=FIELDS)
        w.writeheader()
        w.writerows(rows)
    print(f"{len(rows)} rows, {changed} identifications changed")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--names", nargs="*", default=None)
    ap.add_argument("--max-crossings", type=int, default=10)
    ap.add_argument("--min-crossings", type=int, default=0)
    ap.add_argument("--limit", type=int, default=None, help="at most this many knots")
    ap.add_argument("--out", type=Path, default=BATCH, help="the batch folder (resumable)")
    ap.add_argument("--workers", type=int, default=None,
                    help="Dask worker processes (0: this process; default cores // threads)")
    ap.add_argument("--threads", type=int, default=1, help="numba threads per worker")
    ap.add_argument("--scheduler", default=None, help="address of a running Dask scheduler")
    ap.add_argument("--dashboard", default=":8787")
    ap.add_argument("--tol", type=float, default=1e-4)
    ap.add_argument("--max-iter", type=int, default=1500)
    ap.add_argument("--max-seconds", type=float, default=600.0)
    ap.add_argument("--order", type=float, default=2.0)
    ap.add_argument("--order-study", metavar="NAME", default=None)
    ap.add_argument("--csv", type=Path, default=CSV)
    ap.add_argument("--pack", action="store_true", help="gather the relaxed curves (docs)")
    ap.add_argument("--check-pack", action="store_true")
    ap.add_argument("--reidentify", action="store_true",
                    help="identify the relaxed curves again (the CSV's last column)")
    args = ap.parse_args()
    if args.order_study:
        order_study(args.order_study, args)
        return
    if args.reidentify:
        reidentify(read_rows(args.csv), args.csv)
        return
    if args.pack or args.check_pack:
        rows = read_rows(args.csv)
        if args.pack:
            pack(rows)
        check_pack(rows)
        return
    names = args.names or table_names(args.max_crossings, args.min_crossings)
    done = set()
    if args.csv.exists():
        with args.csv.open() as f:
            done = {row["name"] for row in csv.DictReader(f)}
    todo = [n for n in names if n not in done]
    print(f"{len(names)} knots, {len(names) - len(todo)} done before, {len(todo)} to go"
          f"{'' if args.limit is None else f' ({args.limit} now)'}; "
          f"load {os.getloadavg()[0]:.2f}", flush=True)
    if args.limit is not None:
        todo = todo[:args.limit]
    tasks = table_tasks(todo, args)
    # the batch folder is the resumable record of each task; the table gets the finished ones
    batch.run(tasks, args.out, workers=args.workers, threads=args.threads,
              scheduler=args.scheduler, dashboard=args.dashboard or None,
              say=lambda line: print(line, flush=True))
    results = batch.read_results(args.out)
    args.csv.parent.mkdir(parents=True, exist_ok=True)
    new = not args.csv.exists()
    OBJ.mkdir(parents=True, exist_ok=True)
    added = 0
    with args.csv.open("a", newline="") as f:
        w = csv.DictWriter(f, fieldnames=FIELDS)
        if new:
            w.writeheader()
        for t in tasks:
            r = results.get(t.id)
            if r is None or r["error"] or not (args.out / "curves" / f"{t.id}.npz").exists():
                continue
            core.write_obj(OBJ / f"{r['name']}_{r['n2']}.obj", batch.load_curve(args.out, t.id),
                           name=r["name"])
            w.writerow(table_row(r, args.order))
            added += 1
    print(f"{added} rows added to {args.csv}; load {os.getloadavg()[0]:.2f}", flush=True)

if __name__ == "__main__":
    main()
