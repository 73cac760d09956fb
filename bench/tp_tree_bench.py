"""Benchmark of the tangent-point energy's tree. Prints measurements; not a test.

    python bench/tp_tree_bench.py --errors 5000 20000    # relative errors against the exact sum
    python bench/tp_tree_bench.py --timings 2400 10000 100000   # E+g: tangent-point tree
                                                    # against the Möbius tree (and exact sums)
    python bench/tp_tree_bench.py --convergence 100       # the discretization at N, 2N, 4N, 8N

Curves as in bench/tree_bench.py (7_2, FHW, a non-equilateral 7_2, a chain of three rings).
"""

from __future__ import annotations

import argparse

import numpy as np
from core_bench import best_of  # bench/ is on sys.path when run as a script
from paper import machine
from tree_bench import curve

from moebius_addon.core.energies.moebius_dense import energy_gradient_x
from moebius_addon.core.energies.tangent_point_dense import tp_energy_gradient_x, tp_energy_x
from moebius_addon.core.geometry.layout import as_layout
from moebius_addon.core.tree import moebius as barnes_hut
from moebius_addon.core.tree.tangent_point import THETA, TangentPointFrame

THETAS = (0.1, 0.15, 0.175, 0.2, 0.25, 0.3, 0.5)
EXPONENTS = ((2.0, 4.0), (2.5, 5.0), (3.0, 6.0))


def errors(sizes):
    for n in sizes:
        for name in ("7_2", "fhw", "noneq", "link3"):
            X, layout = as_layout(curve(name, n))
            for a, b in EXPONENTS:
                E0, G0 = tp_energy_gradient_x(X, layout, a, b)
                out = []
                for theta in THETAS:
                    E1, G1 = TangentPointFrame(X, layout, a, b, theta).energy_gradient(X)
                    out.append(f"{theta:g}: {abs(E1 - E0) / E0:.1e}/"
                               f"{np.linalg.norm(G1 - G0) / np.linalg.norm(G0):.1e}")
                print(f"{name:6s} {layout.n:6d} ({a:g},{b:g})  " + "  ".join(out), flush=True)


def timings(sizes, theta, repeat=3):
    for n in sizes:
        X, lay = as_layout(curve("7_2", n))
        fm = barnes_hut.Frame(X, lay)
        ft = TangentPointFrame(X, lay, theta=theta)
        t_mb = best_of(lambda X=X, lay=lay: barnes_hut.Frame(X, lay).energy_gradient(X), repeat)
        t_tp = best_of(lambda X=X, lay=lay: TangentPointFrame(X, lay, theta=theta)
                       .energy_gradient(X), repeat)
        t_mb_eval = best_of(lambda X=X, f=fm: f.energy_gradient(X + 0.0), repeat)
        t_tp_eval = best_of(lambda X=X, f=ft: f.energy_gradient(X + 0.0), repeat)
        line = (f"7_2 {n:6d}: E+g with frame: Möbius tree (theta {barnes_hut.THETA:g}) "
                f"{t_mb * 1e3:8.1f} ms, tangent-point tree (theta {theta:g}) {t_tp * 1e3:8.1f} "
                f"ms ({t_tp / t_mb:.2f}x); frame reused (refit): {t_mb_eval * 1e3:8.1f} / "
                f"{t_tp_eval * 1e3:8.1f} ms ({t_tp_eval / t_mb_eval:.2f}x)")
        if n <= 10000:
            t_me = best_of(lambda X=X, lay=lay: energy_gradient_x(X, lay), repeat)
            t_te = best_of(lambda X=X, lay=lay: tp_energy_gradient_x(X, lay), repeat)
            line += f"; exact Möbius {t_me * 1e3:.1f} ms, exact tangent-point {t_te * 1e3:.1f} ms"
        print(line, flush=True)


def convergence(n0):
    """docs/design.md's trefoil at n equal parameter steps (the smooth curve itself, not a
    resampled polygon)."""
    for a, b in EXPONENTS:
        vals = []
        for k in range(4):
            t = np.linspace(0, 2 * np.pi, n0 * 2**k, endpoint=False)
            P = np.c_[np.sin(t) + 2 * np.sin(2 * t), np.cos(t) - 2 * np.cos(2 * t), -np.sin(3 * t)]
            X, layout = as_layout(P)
            vals.append(tp_energy_x(X, layout, a, b))
        d = np.diff(vals)
        print(f"({a:g},{b:g}) E at {n0}, {2 * n0}, {4 * n0}, {8 * n0} edges: "
              + ", ".join(f"{v:.8f}" for v in vals)
              + "; differences " + ", ".join(f"{x:.2e}" for x in d)
              + "; ratios " + ", ".join(f"{d[i] / d[i + 1]:.2f}" for i in range(len(d) - 1)),
              flush=True)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--errors", type=int, nargs="*")
    ap.add_argument("--timings", type=int, nargs="*")
    ap.add_argument("--convergence", type=int)
    ap.add_argument("--theta", type=float, default=THETA)
    args = ap.parse_args()
    print(machine())
    if args.convergence:
        convergence(args.convergence)
    if args.errors:
        errors(args.errors)
    if args.timings:
        timings(args.timings, args.theta)


if __name__ == "__main__":
    main()
