"""Study: which preconditioner for the hs saddle-point solves without a dense factorization
(issue "Tree engine, part 2"). Prints measurements; not a test.

    python bench/hs_precond_study.py                       # FHW 600 and 1648, start and it. 60
    python bench/hs_precond_study.py --n 4000 --at 0 --curve 7_2

The projected gradient solves ``[[G, Cᵀ], [C, 0]] [u; λ] = [g; 0]`` (``G = A ⊗ I₃``, here the
exact dense hs matrix). Projected preconditioned CG (core/hs_tree.py's ``HsSaddle``, its
residual update included) keeps every iterate on ``C u = 0`` when its preconditioner is a
*constraint preconditioner* ``[[H ⊗ I₃, Cᵀ], [C, 0]]``; the candidates for ``H``:

* ``h1``: the h1 metric (banded: core/banded.py solves it in O(N)), scaled to ``A``'s trace;
* ``shipped``: ``h1`` plus, on the diagonal, the lower-order weights of folded pairs
  (``HsOperator.preconditioner_parts``);
* ``all V lumped``: the same with every pair's lower-order weight on the diagonal;
* ``L⁻¹BL⁻¹``: not a constraint preconditioner of that form but ``Z = L_c⁻¹ B L_c⁻¹`` with
  ``L_c⁻¹`` the constrained h1 solve and ``B`` the W^{1/2,2} operator ``2(diag(W1) − W)`` on
  vertex values (weights ``b_p b_q / |x_p − x_q|²``), dense: the fractional preconditioner of
  Repulsive Surfaces / Repulsor, ``(−Δ)^{−3/2} = (−Δ)^{−1}(−Δ)^{1/2}(−Δ)^{−1}``.

Printed: CG iterations to a relative preconditioned residual of 1e-2 and 1e-4 for the energy
gradient and for a random right-hand side.
"""

from __future__ import annotations

import argparse

import numpy as np

from moebius_addon.core import resample
from moebius_addon.core.geometry.constraints import jacobian
from moebius_addon.core.metrics import hs_solve
from moebius_addon.core.metrics.banded import BandedSaddle
from moebius_addon.core.metrics.gram import banded_parts_of_lengths, gram_x
from moebius_addon.core.metrics.saddle import field_product
from moebius_addon.core.runs.methods import Relaxation
from moebius_addon.core.topology import knots
from moebius_addon.core.tree import hs_metric as hs_tree


class _Dense:
    """What HsSaddle needs of an operator: ``product``, with the dense matrix."""

    def __init__(self, A, layout, weights):
        self.A, self.layout, self.weights = A, layout, weights

    def preconditioner_parts(self):
        return self.weights.preconditioner_parts()

    def product(self, U):
        return field_product(self.A, U)


class _Sandwich:
    """``Z = L_c⁻¹ B L_c⁻¹`` behind the interface HsSaddle uses of its band solver."""

    def __init__(self, K, B):
        self.K, self.B = K, B

    def _solve(self, R, r):
        y = self.K._solve(R, r)[0]
        z, mu = self.K._solve(self.B @ y, r)
        return z, mu


def w_half_vertices(X, lay):
    """``2(diag(W1) − W)`` on vertex values, ``w_pq = b_p b_q / |x_p − x_q|²`` (b: dual
    lengths), every pair of distinct vertices."""
    ln = np.linalg.norm(X[lay.nxt] - X, axis=1)
    b = 0.5 * (ln + ln[lay.prv])
    r2 = ((X[:, None, :] - X[None, :, :]) ** 2).sum(-1)
    np.fill_diagonal(r2, np.inf)
    W = np.outer(b, b) / r2
    return 2 * (np.diag(W.sum(1)) - W)


def study(curve: str, n: int, at: int) -> None:
    P = knots.freedman_unknot(n) if curve == "fhw" else resample(knots.named(curve), n)
    run = Relaxation(P, max_iter=10**6, engine="exact")
    for _ in range(at):
        run.step()
    X, lay = run.X, run.layout
    jac = jacobian(X, run.con)
    A = gram_x("hs", X, lay)
    ln = np.linalg.norm(X[lay.nxt] - X, axis=1)
    exact_weights = hs_tree.HsOperator(X, lay, "hs", theta=1e-9)  # every pair near: exact
    rows, cols, vals, beta = exact_weights.preconditioner_parts()
    nb = len(vals) - 4 * lay.n
    h1r, h1c, h1v = rows[:nb], cols[:nb], vals[:nb]
    i, j = np.arange(lay.n), lay.nxt
    half_all = 0.5 * exact_weights.v1
    candidates = {
        "h1": (h1r, h1c, h1v, beta),
        "shipped": (rows, cols, vals, beta),
        "all V lumped": (np.concatenate([h1r, i, i, j, j]), np.concatenate([h1c, i, j, i, j]),
                         np.concatenate([h1v] + [half_all] * 4), beta),
    }
    rng = np.random.default_rng(1)
    rhs = {"gradient": run.g, "random": rng.standard_normal(run.g.shape)}
    zero = np.zeros(run.con.size)
    line = [f"{curve} N={n} iterate {run.nit} (E {run.E:.2f}):"]
    op = _Dense(A, lay, exact_weights)
    for name, parts in candidates.items():
        solver = hs_solve.HsSaddle(op, jac, max_iter=1000)
        solver.K = BandedSaddle(parts, jac)
        counts = []
        for rtol in (1e-2, 1e-4):
            for g in rhs.values():
                solver.solve(g, zero, rtol=rtol)
                counts.append(solver.iterations[-1])
        line.append(f"{name} {counts}")
    rl, cl, vl, _ = banded_parts_of_lengths("h1", ln, lay)
    solver = hs_solve.HsSaddle(op, jac, max_iter=1000)
    solver.K = _Sandwich(BandedSaddle((rl, cl, vl, beta), jac), w_half_vertices(X, lay))
    counts = []
    for rtol in (1e-2, 1e-4):
        for g in rhs.values():
            solver.solve(g, zero, rtol=rtol)
            counts.append(solver.iterations[-1])
    line.append(f"L⁻¹BL⁻¹ {counts}")
    print("; ".join(line), flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, nargs="+", default=[600, 1648])
    ap.add_argument("--at", type=int, nargs="+", default=[0, 60])
    ap.add_argument("--curve", default="fhw")
    args = ap.parse_args()
    print("CG iterations [gradient 1e-2, random 1e-2, gradient 1e-4, random 1e-4]")
    for n in args.n:
        for at in args.at:
            study(args.curve, n, at)


if __name__ == "__main__":
    main()
