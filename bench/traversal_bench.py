"""The tree engine's dual traversals of an earlier revision against this checkout's, timed
alternately in one process. Prints measurements; not a test.

    python bench/traversal_bench.py                    # against cd59f62, FHW 20 000 and 100 000
    python bench/traversal_bench.py --base REV --sizes 20000 --rounds 9

The earlier revision's package is extracted with ``git archive`` into ``out/bench_base/REV``
under the name ``moebius_addon_base`` (its kernels cached there), so both are imported side by
side. In every round each path is timed once with each revision, the order of the two swapped
from one round to the next; printed are the median and the least of the rounds, and the ratio
of the medians (this checkout / the earlier one). The paths:

* ``frame``: the Möbius energy's frame (hierarchy, far/near split) at the polygon;
* ``moebius E+g``: the frame and the energy and gradient with it (``Frame(X).energy_gradient``);
* ``tangent-point E+g``: the same for the tangent-point energy;
* ``hs build``: the hs operator (hierarchy of arcs, its split, the weights); ``hs product``:
  one product with it;
* ``contact``: the first contact along a step (the flow's step bound: along the gradient,
  scaled to move the fastest vertex 0.1 edge lengths at τ = 1; up to τ = 10⁴, with a
  contact); ``no contact``: up to τ = 1 at once (``staged=False`` in revisions that searched
  shorter horizons first), none found;
* ``closest``: the closest pairs of vertices and of edges.
"""

from __future__ import annotations

import argparse
import importlib
import inspect
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def base_package(rev: str) -> str:
    """Extract the package at ``rev`` as ``moebius_addon_base`` (once) and put it on the path."""
    sha = subprocess.run(["git", "rev-parse", "--short", rev], cwd=ROOT, check=True,
                         capture_output=True, text=True).stdout.strip()
    where = ROOT / "out" / "bench_base" / sha
    if not (where / "moebius_addon_base").is_dir():
        where.mkdir(parents=True, exist_ok=True)
        archive = subprocess.run(["git", "archive", sha, "moebius_addon"], cwd=ROOT, check=True,
                                 capture_output=True).stdout
        subprocess.run(["tar", "-x", "-C", str(where)], input=archive, check=True)
        (where / "moebius_addon").rename(where / "moebius_addon_base")
    sys.path.insert(0, str(where))
    return sha


def paths(pkg: str, X: np.ndarray) -> dict:
    """The timed calls of the package named ``pkg`` at the polygon ``X``."""
    moebius = importlib.import_module(f"{pkg}.core.tree.moebius")
    tangent = importlib.import_module(f"{pkg}.core.tree.tangent_point")
    hs = importlib.import_module(f"{pkg}.core.tree.hs_metric")
    contact = importlib.import_module(f"{pkg}.core.tree.contact")
    layout = importlib.import_module(f"{pkg}.core.geometry.layout")
    X, lay = layout.as_layout(X)
    _, G = moebius.Frame(X, lay).energy_gradient(X)
    h = float(np.linalg.norm(X[lay.nxt] - X, axis=1).mean())
    U = G * (0.1 * h / np.abs(G).max())
    eps = 0.5 * h
    op = hs.HsOperator(X, lay)
    # revisions before one search per call searched shorter horizons first unless told
    once = ({"staged": False}
            if "staged" in inspect.signature(contact.contact_time_tree).parameters else {})
    V = np.sin(np.arange(X.size, dtype=float)).reshape(X.shape)
    return {
        "frame": lambda: moebius.Frame(X, lay),
        "moebius E+g": lambda: moebius.Frame(X, lay).energy_gradient(X),
        "tangent-point E+g": lambda: tangent.tp_tree_energy_gradient(X, lay),
        "hs build": lambda: hs.HsOperator(X, lay),
        "hs product": lambda: op.product(V),
        "contact": lambda: contact.contact_time_tree(X, U, lay, 1e4, eps),
        "no contact": lambda: contact.contact_time_tree(X, U, lay, 1.0, eps, **once),
        "closest": lambda: contact.closest_pairs_tree(X, lay),
    }


def seconds(f) -> float:
    t = time.perf_counter()
    f()
    return time.perf_counter() - t


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--base", default="cd59f62", help="the earlier revision")
    parser.add_argument("--sizes", type=int, nargs="+", default=[20000, 100000])
    parser.add_argument("--rounds", type=int, default=7)
    args = parser.parse_args()
    sha = base_package(args.base)
    import numba

    from moebius_addon.core.topology.knots import freedman_unknot

    load = os.getloadavg()
    print(f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, numba "
          f"{numba.__version__}, {numba.get_num_threads()} threads, load {load[0]:.1f}; "
          f"base {sha} against this checkout; {args.rounds} rounds, alternated", flush=True)
    for n in args.sizes:
        P = freedman_unknot(n)
        calls = {"base": paths("moebius_addon_base", P), "new": paths("moebius_addon", P)}
        for impl in calls.values():  # compiled or loaded before anything is timed
            for f in impl.values():
                f()
        times = {k: {"base": [], "new": []} for k in calls["new"]}
        for r in range(args.rounds):
            order = ("base", "new") if r % 2 == 0 else ("new", "base")
            for key in times:
                for which in order:
                    times[key][which].append(seconds(calls[which][key]))
        print(f"\nFHW, {n} edges (ms: median / least of {args.rounds})", flush=True)
        for key, t in times.items():
            b, w = np.median(t["base"]), np.median(t["new"])
            print(f"  {key:18s} base {1e3 * b:8.2f} / {1e3 * min(t['base']):8.2f}   "
                  f"new {1e3 * w:8.2f} / {1e3 * min(t['new']):8.2f}   new/base {w / b:.3f}",
                  flush=True)
    print(f"\nload at the end {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
