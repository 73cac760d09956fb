"""Study: preconditioners for the hs saddle-point solves without any dense factorization
(issue "Tree engine, part 2"). Dense matrices and scipy here (a study, not add-on code).

The projected gradient solves ``[[G, Cᵀ], [C, 0]] [u; λ] = [g; 0]`` (G = A ⊗ I₃); on the
tangent space ker C that is ``A_red x = b`` with ``A_red = Nᵀ G N`` (N an orthonormal basis of
ker C). A *constrained* preconditioner ``Z`` maps a residual into ker C. Candidates:

* ``band h1`` / ``band h2``: ``Z = L_c⁻¹``, the constrained solve with the banded metric
  (what core/banded.py does in O(N)).
* ``L⁻¹BL⁻¹``: ``Z = L_c⁻¹ B L_c⁻¹`` with ``L`` the h1 stiffness (+ mass) and ``B`` an order-one
  operator, the W^{1/2,2} form of the same kernel on vertex values
  ``2 Mᵀ(diag(W1) − W)M`` (+ mass): A is of order 3 (eigenvalues ~k³ on a circle), L of order 2,
  B of order 1, so ``L⁻¹BL⁻¹`` is of order −3 (the fractional-operator preconditioner of
  Repulsive Surfaces, Yu–Brakensiek–Schumacher–Crane 2021: (−Δ)^−s = (−Δ)^−1 (−Δ)^(2−s) (−Δ)^−1).

Prints κ(Z_red A_red) (generalized eigenvalues) and PCG iterations to 1e-4 / 1e-10.

    python bench/hs_precond_study.py --n 600 1648 --at 0 80
"""

from __future__ import annotations

import argparse

import numpy as np
import scipy.linalg as sl

from moebius_addon.core import knots, resample
from moebius_addon.core.constraints import jacobian
from moebius_addon.core.energy import energy_gradient_x
from moebius_addon.core.metrics import _mass, _stiffness, gram_x
from moebius_addon.core.solvers import Relaxation


def dense_C(jac, n):
    return np.column_stack([jac.matvec(e.reshape(n, 3)) for e in np.eye(3 * n)])


def w_laplacian_values(X, lay, power=2):
    """``2 Mᵀ(diag(W1) − W)M`` with ``w_IJ = l_I l_J / |m_I − m_J|^power`` over disjoint
    pairs (all components), M the edge average."""
    n = len(X)
    nxt = lay.nxt
    ln = np.linalg.norm(X[nxt] - X, axis=1)
    mid = 0.5 * (X + X[nxt])
    r2 = ((mid[:, None, :] - mid[None, :, :]) ** 2).sum(-1)
    comp = lay.comp
    i = np.arange(n)
    pos = i - lay.starts[comp]
    size = lay.starts[comp + 1] - lay.starts[comp]
    same = comp[:, None] == comp[None, :]
    gap = np.abs(pos[:, None] - pos[None, :])
    gap = np.minimum(gap, size[:, None] - gap)
    disjoint = ~same | (gap >= 2)
    with np.errstate(divide="ignore"):
        W = np.where(disjoint, np.outer(ln, ln) / r2 ** (power / 2), 0.0)
    M = np.zeros((n, n))
    M[i, i] = 0.5
    M[i, nxt] += 0.5
    Lw = np.diag(W.sum(1)) - W
    return 2 * M.T @ Lw @ M


def w_laplacian_vertices(X, lay, skip=1):
    """``2(diag(W1) − W)`` on vertex values, ``w_pq = b_p b_q / |x_p − x_q|²`` for vertices
    at least ``skip`` apart along their component (all pairs between components), b the dual
    lengths."""
    n = len(X)
    nxt = lay.nxt
    ln = np.linalg.norm(X[nxt] - X, axis=1)
    bw = 0.5 * (ln + ln[lay.prv])
    r2 = ((X[:, None, :] - X[None, :, :]) ** 2).sum(-1)
    comp = lay.comp
    i = np.arange(n)
    pos = i - lay.starts[comp]
    size = lay.starts[comp + 1] - lay.starts[comp]
    same = comp[:, None] == comp[None, :]
    gap = np.abs(pos[:, None] - pos[None, :])
    gap = np.minimum(gap, size[:, None] - gap)
    keep = ~same | (gap >= skip)
    with np.errstate(divide="ignore"):
        W = np.where(keep, np.outer(bw, bw) / r2, 0.0)
    return 2 * (np.diag(W.sum(1)) - W)


def reduced(Mat, Nb):
    """``Nᵀ (Mat ⊗ I₃) N`` for interleaved coordinates."""
    return sum(Nb[c::3].T @ Mat @ Nb[c::3] for c in range(3))


def pcg(A, Zred, b, tol, maxit=3000):
    x = np.zeros_like(b)
    r = b.copy()
    z = Zred @ r
    p = z.copy()
    rz = r @ z
    nb = np.linalg.norm(b)
    for k in range(maxit):
        Ap = A @ p
        a = rz / (p @ Ap)
        x += a * p
        r -= a * Ap
        if np.linalg.norm(r) <= tol * nb:
            return k + 1
        z = Zred @ r
        rz, old = r @ z, rz
        p = z + rz / old * p
    return maxit


CONSTRAINED = True


def study(name, P, at, variants):
    run = Relaxation(P, max_iter=10**6)
    for _ in range(at):
        run.step()
    X, lay = run.X, run.layout
    n = lay.n
    A = gram_x("hs", X, lay)
    jac = jacobian(X, run.con)
    C = dense_C(jac, n)
    Nb = sl.null_space(C) if CONSTRAINED else np.eye(3 * n)
    Ar = reduced(A, Nb)
    _, g = energy_gradient_x(X, lay)
    b = Nb.T @ g.ravel()
    total = 1.0
    stiff = _stiffness(np.linalg.norm(X[lay.nxt] - X, axis=1), lay)
    mass = _mass(np.linalg.norm(X[lay.nxt] - X, axis=1), lay)
    Bw = (w_laplacian_values(X, lay), w_laplacian_vertices(X, lay))
    print(f"\n{name} N={n} iterate {run.nit} E={run.E:.4f}  dim ker C = {Nb.shape[1]}",
          flush=True)
    its0 = pcg(Ar, np.eye(len(Ar)), b, 1e-4)
    print(f"  none: CG {its0} its to 1e-4")
    for label, L, B in variants(stiff, mass, Bw, total):
        Lr = reduced(L, Nb)
        Li = np.linalg.inv(Lr)
        if B is None:
            Zr = Li
        else:
            Zr = Li @ reduced(B, Nb) @ Li
        Zr = 0.5 * (Zr + Zr.T)
        R = np.linalg.cholesky(Zr)
        ev = np.linalg.eigvalsh(R.T @ Ar @ R)
        print(f"  {label:34s} κ {ev[-1] / ev[0]:9.3g}  CG {pcg(Ar, Zr, b, 1e-4):4d} (1e-4) "
              f"{pcg(Ar, Zr, b, 1e-10):4d} (1e-10)", flush=True)


def variants(stiff, mass, Bw, total):
    h1 = stiff + mass
    yield "band h1 (stiffness + mass)", h1, None
    Be, Bv = Bw
    for a in (1.0, 10.0, 100.0):
        yield f"L⁻¹BL⁻¹, L = stiff + {a:g} mass, B = W½v", stiff + a * mass, Bv + mass
    yield "L⁻¹BL⁻¹, L = stiff + 10 mass, B = W½e + W½v", stiff + 10 * mass, Be + Bv + mass


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--n", type=int, nargs="+", default=[600])
    ap.add_argument("--at", type=int, nargs="+", default=[0])
    ap.add_argument("--curves", nargs="+", default=["fhw"])
    ap.add_argument("--free", action="store_true", help="no constraints (all of R^3N)")
    args = ap.parse_args()
    global CONSTRAINED
    CONSTRAINED = not args.free
    for curve in args.curves:
        for n in args.n:
            if curve == "fhw":
                P = knots.freedman_unknot(n)
            else:
                P = resample(knots.named(curve), n)
            for at in args.at:
                study(curve, P, at, variants)


if __name__ == "__main__":
    main()
