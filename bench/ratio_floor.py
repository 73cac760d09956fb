"""How low can the cost ratio of one iteration go with dense matrices? Prints measurements.

    python bench/ratio_floor.py                # N = 500, 1648, 3000 (about a minute)
    python bench/ratio_floor.py --n 1648 --iters 30

For the FHW unknot at each N, a real run counts what one iteration calls (energy, contact
test, back-projection steps, Krylov iterations of the gradient solve); every piece is then
timed alone (best of several) at the run's iterate, in units of one energy+gradient
evaluation. The floors add pieces the docs/design.md iteration cannot do without, cheapest first:

* ``no linear algebra``: E+g, Gram matrix, the trial energies and contact tests counted;
* ``+ back-projection``: the counted modified Newton steps, each one application of the
  stored pseudoinverse ``G⁻¹Cᵀ(CG⁻¹Cᵀ)⁻¹`` (two passes over dense N × N arrays);
* ``+ one Cholesky of A``: LAPACK potrf of the N × N metric block in single precision, the
  least any exact dense solve of step 2 needs (the Schur complement needs more: potri for
  ``A⁻¹``, potrf of ``S``, and Krylov refinement to double precision).

The cost-ratio target of the core issue is 8.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from core_bench import best_of  # bench/ is on sys.path when run as a script

from moebius_addon.core import Relaxation
from moebius_addon.core.energies.moebius_dense import energy_gradient_x, energy_x
from moebius_addon.core.geometry.collision import contact_time_x
from moebius_addon.core.metrics import _lapack
from moebius_addon.core.metrics.gram import gram_x
from moebius_addon.core.metrics.saddle import Factorization
from moebius_addon.core.topology import knots


class Counter:
    """Wraps a method of a run's engine and counts its calls."""

    def __init__(self, engine, name):
        self.engine = engine
        self.name = name
        self.f = getattr(engine, name)
        self.calls = 0
        setattr(engine, name, self)

    def __call__(self, *args, **kw):
        self.calls += 1
        return self.f(*args, **kw)

    def restore(self):
        delattr(self.engine, self.name)  # the class's method again


def floors(n, iters):
    run = Relaxation(knots.freedman_unknot(n), max_iter=10**6)
    for _ in range(3):  # compile, warm caches, leave the start
        run.step()
    counters = [Counter(run.engine, "energy"), Counter(run.engine, "contact_time")]
    solver = run.engine.solver
    pinv_calls = 0
    pinv = solver.pseudo_inverse

    def counted_pinv(phi):
        nonlocal pinv_calls
        pinv_calls += 1
        return pinv(phi)

    solver.pseudo_inverse = counted_pinv
    k0, kry0 = run.nit, len(solver.krylov_its)
    t = time.perf_counter()
    for _ in range(iters):
        if not run.step():
            break
    per_iter = (time.perf_counter() - t) / (run.nit - k0)
    its = run.nit - k0
    for c in counters:
        c.restore()
    solver.pseudo_inverse = pinv
    n_energy, n_contact = (c.calls / its for c in counters)
    n_pinv = pinv_calls / its
    n_krylov = float(np.sum(solver.krylov_its[kry0:])) / its

    X, lay = run.X, run.layout
    A = gram_x("hs", X, lay)
    fac = Factorization(A, run.jac, solver.dtype)
    A32 = np.array(A, dtype=solver.dtype)
    work = np.empty_like(A32)

    def potrf():
        np.copyto(work, A32)
        _lapack.cholesky(work, overwrite=True)

    def copy():
        np.copyto(work, A32)

    t_eg = best_of(lambda: energy_gradient_x(X, lay), 15)
    t = {
        "gram": best_of(lambda: gram_x("hs", X, lay), 7),
        "energy": best_of(lambda: energy_x(X, lay), 15),
        "contact": best_of(lambda: contact_time_x(X, run.u, lay, 3 * run.tau, run.eps), 15),
        "pinv": best_of(lambda: fac.pseudo_inverse(run.phi), 15),
        "potrf": best_of(potrf, 5) - best_of(copy, 5),
        "factorization": best_of(lambda: Factorization(A, run.jac, solver.dtype), 2),
        "krylov": best_of(lambda: (fac.solve(run.g, np.zeros(run.con.size)),
                                   solver._apply_K(run.u, np.zeros(run.con.size))), 15),
    }
    f0 = t_eg + t["gram"] + n_energy * t["energy"] + n_contact * t["contact"]
    f1 = f0 + n_pinv * t["pinv"]
    f2 = f1 + t["potrf"]
    print(f"  N={n:5d} ({np.dtype(solver.dtype).name} factorization): iteration "
          f"{1e3 * per_iter:6.1f} ms = {per_iter / t_eg:5.1f} E+g ({1e3 * t_eg:.2f} ms); per "
          f"iteration {n_energy:.1f} energies, {n_contact:.1f} contact tests, {n_pinv:.1f} "
          f"back-projection steps, {n_krylov:.1f} Krylov iterations", flush=True)
    print("     pieces in E+g: " + ", ".join(f"{k} {v / t_eg:.2f}" for k, v in t.items()))
    print(f"     floors in E+g: no linear algebra {f0 / t_eg:.1f}, + back-projection "
          f"{f1 / t_eg:.1f}, + one Cholesky of A {f2 / t_eg:.1f}", flush=True)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, nargs="*", default=[500, 1648, 3000])
    ap.add_argument("--iters", type=int, default=15)
    args = ap.parse_args()
    for n in args.n:
        floors(n, args.iters)


if __name__ == "__main__":
    main()
