"""Design study for the cost-ratio target of the core: how well would a *sparse*
preconditioner built from the geometric near field of the hs Gram matrix work, in place of the
dense factorization of every iterate? Prints measurements; not a test. Uses scipy (dense
eigenvalues, null spaces, a sparse LU for the fill) — fine for a study, not for the add-on.

    python bench/preconditioner_study.py                 # FHW 600: start and iterate 80
    python bench/preconditioner_study.py --n 1648 --at 0 --no-constrained
    python bench/preconditioner_study.py --n 3000 --at 0 --costs-only

``A_hs = 2 Dᵀ(diag(W1) − W)D + 2 Mᵀ(diag(V1) − V)M + b bᵀ`` (metrics.py). A preconditioner
``P`` keeps the pairs (I, J) of ``W`` and ``V`` in one of these sets and drops the rest:

* ``index band b``: cyclic index distance at most b (what a banded solver could use);
* ``space r``: midpoints closer than r mean edge lengths (the geometric near field: strands
  that come close in space but are far apart along the curve are kept);
* ``+ coarse k``: that near field plus an exact coarse-space correction (balancing two-level
  preconditioner) on hat functions centred at every k-th vertex, ``(ZᵀAZ)⁻¹`` dense — the first
  level of a multigrid along the curve; constrained: the hats projected onto the tangent
  space.

Dropping pairs removes positive semidefinite terms, so ``P ≤ A`` and every eigenvalue of
``P⁻¹A`` is ≥ 1. Reported: nonzeros per row of ``P``, the condition number of ``P⁻¹A`` and the
preconditioned CG iterations to a relative residual of 1e-10 (the flow's solver tolerance)
for the x coordinate of the energy gradient; "constrained" does the same on the tangent space
of the constraints (null space of ``C``), where the flow's saddle-point solves live; ``fill``
is nnz(L+U)/N of a sparse LU of ``P`` with scipy's default (COLAMD) ordering. ``costs``
times the pieces of one two-level solve against the flow's dense factorization.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import scipy.linalg as sl
import scipy.sparse as sp
import scipy.sparse.linalg as spl
from core_bench import best_of  # bench/ is on sys.path when run as a script
from paper import machine

from moebius_addon.core.energies.moebius_dense import energy_gradient_x
from moebius_addon.core.geometry.constraints import jacobian
from moebius_addon.core.metrics.gram import gram_x
from moebius_addon.core.metrics.saddle import Factorization, field_product
from moebius_addon.core.runs.methods import Relaxation
from moebius_addon.core.topology import knots

TOL = 1e-10


def weights(X, nxt):
    """Dense W, V of metrics.py's formula (one component), D, M, pair distances in mean edge
    lengths, cyclic index distances and the edge lengths."""
    n = len(X)
    ln = np.linalg.norm(X[nxt] - X, axis=1)
    mid = 0.5 * (X + X[nxt])
    arc = np.cumsum(ln) - 0.5 * ln
    total = ln.sum()
    i = np.arange(n)
    gap = np.abs(i[:, None] - i[None, :])
    gap = np.minimum(gap, n - gap)
    fwd = np.abs(arc[:, None] - arc[None, :])
    rho = np.minimum(fwd, total - fwd)
    r2 = ((mid[:, None, :] - mid[None, :, :]) ** 2).sum(-1)
    disjoint = gap >= 2
    with np.errstate(divide="ignore", invalid="ignore"):
        W = np.where(disjoint, np.outer(ln, ln) / r2, 0.0)
        V = np.where(disjoint, np.outer(ln, ln) * (1 / r2 - 1 / rho**2) / r2, 0.0)
    D = np.zeros((n, n))
    M = np.zeros((n, n))
    D[i, i], D[i, nxt] = -1 / ln, 1 / ln
    M[i, i], M[i, nxt] = 0.5, 0.5
    return W, V, D, M, gap, np.sqrt(r2) / (total / n), ln


def laplacian(K):
    return np.diag(K.sum(1)) - K


def pcg(apply_A, apply_P, b, maxit=2000):
    """Preconditioned CG iterations until |r| ≤ TOL |b|."""
    x = np.zeros_like(b)
    r = b.copy()
    z = apply_P(r)
    p = z.copy()
    rz = r @ z
    nb = np.linalg.norm(b)
    for k in range(maxit):
        Ap = apply_A(p)
        a = rz / (p @ Ap)
        x += a * p
        r -= a * Ap
        if np.linalg.norm(r) <= TOL * nb:
            return k + 1
        z = apply_P(r)
        rz, rz_old = r @ z, rz
        p = z + (rz / rz_old) * p
    return maxit


def hats(n, k):
    """Piecewise-linear functions along the closed polygon, centred at every k-th vertex."""
    m = n // k
    centres = np.arange(m) * n / m
    i = np.arange(n)[:, None]
    d = np.abs(i - centres[None, :])
    d = np.minimum(d, n - d) / (n / m)
    return np.maximum(0.0, 1.0 - d)


def two_level(A, P, Z):
    """Balancing preconditioner ``Q + (I − QA) P⁻¹ (I − AQ)``, ``Q = Z (ZᵀAZ)⁻¹ Zᵀ`` (dense)."""
    Q = Z @ np.linalg.solve(Z.T @ A @ Z, Z.T)
    R = np.eye(len(A)) - Q @ A
    return Q + R @ sl.cho_solve(sl.cho_factor(P), R.T)


def best_ms(f, repeat=5):
    return 1e3 * best_of(f, repeat)


def costs(A, Psparse, H, g, run):
    """Timings (ms) of the pieces a two-level PCG would need per iterate, against the current
    dense factorization: the sparse factorization (SuperLU, as a stand-in for a good sparse
    direct solver), one sparse solve for the three coordinates, the coarse matrix ZᵀAZ, one
    dense product A·U (the kernel the flow uses) and the flow's float32 Factorization."""
    n = len(A)
    # + a tiny multiple of I: the near field alone does not see translations (the flow's
    # barycenter term would, as a rank-1 update)
    csc = sp.csc_matrix(Psparse + 1e-6 * np.diag(Psparse).mean() * np.eye(n))
    lu = spl.splu(csc)
    coarse = np.ascontiguousarray(H.T)
    jac = jacobian(run.X, run.con)
    # the constraint preconditioner [[P ⊗ I₃, Cᵀ], [C, 0]] with the edge-length rows of C
    # (the three dense barycenter rows would go by a 3 × 3 Schur complement)
    ne = run.con.size - 3 * run.layout.k
    C = np.column_stack([jac.matvec(e.reshape(n, 3))[:ne] for e in np.eye(3 * n)])
    Cs = sp.csr_matrix(np.where(np.abs(C) > 0, C, 0.0))
    K = sp.bmat([[sp.kron(csc, sp.eye(3)), Cs.T], [Cs, None]], format="csc")
    klu = spl.splu(K)
    rhs = np.concatenate([g.ravel(), np.zeros(ne)])
    res = np.linalg.norm(K @ klu.solve(rhs) - rhs) / np.linalg.norm(rhs)
    assert res < 1e-8, f"saddle solve residual {res:.1e}"
    return {
        "sparse factor": best_ms(lambda: spl.splu(csc)),
        "sparse solve (3 rhs)": best_ms(lambda: lu.solve(g)),
        "sparse saddle factor": best_ms(lambda: spl.splu(K), 3),
        "sparse saddle solve": best_ms(lambda: klu.solve(rhs)),
        "coarse ZᵀAZ": best_ms(lambda: coarse @ (A @ H)),
        "dense A·U": best_ms(lambda: field_product(A, g)),
        "dense factorization (flow)": best_ms(lambda: Factorization(A, jac, np.float32), 2),
    }


def study(n, at, constrained, costs_only=False):
    run = Relaxation(knots.freedman_unknot(n), max_iter=10**6)
    for _ in range(at):
        run.step()
    X, lay = run.X, run.layout
    print(f"\nFHW N={n}, iterate {run.nit}, E={run.E:.4f}", flush=True)
    A = gram_x("hs", X, lay)
    W, V, D, M, gap, dist, ln = weights(X, lay.nxt)
    rest = A - 2 * D.T @ laplacian(W) @ D - 2 * M.T @ laplacian(V) @ M  # = b bᵀ
    bb = 0.5 * (ln[lay.prv] + ln) * np.sqrt(n) / ln.sum() ** 2
    err = np.abs(rest - np.outer(bb, bb)).max() / np.abs(A).max()
    print(f"  formula check: |A − (W, V terms) − b bᵀ| / |A| = {err:.1e}")
    _, g = energy_gradient_x(X, lay)
    b = g[:, 0]
    keep = dist <= 6
    P6 = 2 * D.T @ laplacian(W * keep) @ D + 2 * M.T @ laplacian(V * keep) @ M
    timing = costs(A, P6, hats(n, 8), g, run)
    print("  costs (space 6 + coarse 8), ms: "
          + ", ".join(f"{k} {v:.2f}" for k, v in timing.items()), flush=True)
    if costs_only:
        return
    print(f"  unpreconditioned CG: {pcg(lambda v: A @ v, lambda v: v, b)} iterations; "
          f"Jacobi: {pcg(lambda v: A @ v, lambda v: v / np.diag(A), b)}", flush=True)
    variants = [(f"index band {k}", gap <= k, True) for k in (16, 64)]
    variants += [(f"space {r}", dist <= r, True) for r in (6, 12, 20)]
    variants += [("space 12, no V term", dist <= 12, False)]
    if constrained:
        jac = jacobian(X, run.con)
        C = np.column_stack([jac.matvec(e.reshape(n, 3)) for e in np.eye(3 * n)])
        t = time.perf_counter()
        Z = sl.null_space(C)
        Zc = [Z[c::3] for c in range(3)]  # G = A ⊗ I₃ on interleaved x, y, z
        GZ = sum(z.T @ A @ z for z in Zc)
        bz = Z.T @ g.ravel()
        print(f"  constrained: tangent space of dimension {Z.shape[1]} "
              f"({time.perf_counter() - t:.0f} s to set up)", flush=True)
    for name, keep, with_v in variants:
        P = rest + 2 * D.T @ laplacian(W * keep) @ D
        if with_v:
            P += 2 * M.T @ laplacian(V * keep) @ M
        ev = sl.eigh(A, P, eigvals_only=True)
        cf = sl.cho_factor(P)
        its = pcg(lambda v: A @ v, lambda v, c=cf: sl.cho_solve(c, v), b)
        lu = spl.splu(sp.csc_matrix(P - rest))  # the sparse part; b bᵀ goes by a rank-1 update
        fill = (lu.L.nnz + lu.U.nnz) / n
        line = (f"  {name:>20s}: nnz/row {keep.sum(1).mean():5.0f}, fill {fill:6.0f}/row, "
                f"κ(P⁻¹A) {ev.max() / ev.min():9.3g}, CG {its:4d}")
        if constrained:
            PZ = sum(z.T @ P @ z for z in Zc)
            evz = sl.eigh(GZ, PZ, eigvals_only=True)
            cz = sl.cho_factor(PZ)
            itz = pcg(lambda v: GZ @ v, lambda v, c=cz: sl.cho_solve(c, v), bz)
            line += f" | constrained κ {evz.max() / evz.min():9.3g}, CG {itz:4d}"
        print(line, flush=True)
    for r, k in ((6, 8), (6, 16), (12, 16)):
        keep = dist <= r
        P = rest + 2 * D.T @ laplacian(W * keep) @ D + 2 * M.T @ laplacian(V * keep) @ M
        H = hats(n, k)
        Minv = two_level(A, P, H)
        ev = np.linalg.eigvals(Minv @ A).real
        its = pcg(lambda v: A @ v, lambda v, m=Minv: m @ v, b)
        line = (f"  {f'space {r} + coarse {k}':>20s}: coarse size {n // k:4d}, "
                f"κ(M⁻¹A) {ev.max() / ev.min():9.3g}, CG {its:4d}")
        if constrained:
            # coarse space: the hat functions (each coordinate) projected onto the tangent space
            Hz = np.linalg.qr(np.hstack([z.T @ H for z in Zc]))[0]
            Mz = two_level(GZ, sum(z.T @ P @ z for z in Zc), Hz)
            evz = np.linalg.eigvals(Mz @ GZ).real
            itz = pcg(lambda v: GZ @ v, lambda v, m=Mz: m @ v, bz)
            line += f" | constrained κ {evz.max() / evz.min():9.3g}, CG {itz:4d}"
        print(line, flush=True)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n", type=int, default=600)
    ap.add_argument("--at", type=int, nargs="+", default=[0, 80],
                    help="flow iterates to study (0: the start)")
    ap.add_argument("--no-constrained", action="store_true")
    ap.add_argument("--costs-only", action="store_true", help="timings only, no eigenvalues")
    args = ap.parse_args()
    print("machine:", machine())
    for at in args.at:
        study(args.n, at, not args.no_constrained, args.costs_only)


if __name__ == "__main__":
    main()
