"""The saddle-point system of the projected gradient (docs/design.md, step 2) and the pseudoinverse
of the back-projection (step 4).

    [[G, Cᵀ], [C, 0]] [u; λ] = [g; r],   G = A ⊗ I₃ (A is N × N, dense, SPD)

Exact solve by the Schur complement: ``A⁻¹`` from a Cholesky factor, then
``S = C G⁻¹ Cᵀ``. The edge rows of ``C`` are ``diag(t_k) D`` for each coordinate ``k``, so the
edge block of ``S`` is ``(D A⁻¹ Dᵀ) ∘ (T Tᵀ)``: O(N²) once ``A⁻¹`` is known, instead of the
3(N+3) triangular solves of a generic ``G⁻¹ Cᵀ``. Cubic cost: LAPACK potrf + potri for ``A⁻¹``
(N³ flops) and potrf for ``S`` (N³/3); ``S⁻¹`` is applied by triangular solves.

``SaddlePointSolver`` reuses that factorization across iterations as a preconditioner for GMRES
on the current system (the metric and the constraints change little from one iterate to the
next), and refactors when a solve costs more than the average since the last factorization
(including it). numpy only: no scipy at run time. LAPACK comes from numpy's own OpenBLAS
(``_lapack``); where that cannot be reached, the inverse falls back to numpy's Cholesky and a
blocked triangular inverse on BLAS-3 products.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from ..geometry.constraints import Jacobian
from . import _lapack


def _numpy_triangular_inverse(L: np.ndarray) -> np.ndarray:
    """Inverse of a lower-triangular matrix by blocked recursion on BLAS-3 products."""
    n = L.shape[0]
    if n <= 128:
        return np.tril(np.linalg.inv(L))
    h = n // 2
    X11 = _numpy_triangular_inverse(L[:h, :h])
    X22 = _numpy_triangular_inverse(L[h:, h:])
    out = np.zeros_like(L)
    out[:h, :h] = X11
    out[h:, h:] = X22
    out[h:, :h] = -(X22 @ (L[h:, :h] @ X11))
    return out


def spd_inverse(A: np.ndarray, overwrite: bool = False) -> np.ndarray:
    """Inverse of a symmetric positive definite matrix via Cholesky (raises LinAlgError).

    LAPACK ``potrf`` + ``potri`` (N³ flops) where numpy's own LAPACK can be reached, else
    Cholesky, a blocked triangular inverse and ``LᵀL`` (2 N³ flops). ``overwrite=True`` lets
    LAPACK invert a C-ordered ``A`` in place (the fallback always returns a new array)."""
    out = _lapack.spd_inverse(A, overwrite=overwrite)
    if out is not None:
        return out
    Li = _numpy_triangular_inverse(np.linalg.cholesky(A))
    return Li.T @ Li  # numpy routes XᵀX to BLAS syrk


_ROWS = 4  # rows per pass of _product3 (its body is written out for 4): each u[j] serves 12 FMAs


@nb.njit(cache=True, parallel=True, fastmath={"reassoc", "contract", "nsz", "arcp"})
def _product3(M, Ut, out):
    """``out = M @ Utᵀ`` for a (N, N) matrix of any float dtype and three float64 vectors
    ``Ut`` (3, N), with float64 sums: one pass over ``M``, four rows at a time. Every row is
    summed by one thread in a fixed order, so results do not depend on the thread count."""
    n = M.shape[0]
    m = M.shape[1]
    u0 = Ut[0]
    u1 = Ut[1]
    u2 = Ut[2]
    for p in nb.prange((n + _ROWS - 1) // _ROWS):
        i0 = _ROWS * p
        if i0 + _ROWS <= n:
            r0 = M[i0]
            r1 = M[i0 + 1]
            r2 = M[i0 + 2]
            r3 = M[i0 + 3]
            a0 = a1 = a2 = b0 = b1 = b2 = c0 = c1 = c2 = d0 = d1 = d2 = 0.0
            for j in range(m):
                x0 = u0[j]
                x1 = u1[j]
                x2 = u2[j]
                s = np.float64(r0[j])
                a0 += s * x0
                a1 += s * x1
                a2 += s * x2
                s = np.float64(r1[j])
                b0 += s * x0
                b1 += s * x1
                b2 += s * x2
                s = np.float64(r2[j])
                c0 += s * x0
                c1 += s * x1
                c2 += s * x2
                s = np.float64(r3[j])
                d0 += s * x0
                d1 += s * x1
                d2 += s * x2
            out[i0, 0], out[i0, 1], out[i0, 2] = a0, a1, a2
            out[i0 + 1, 0], out[i0 + 1, 1], out[i0 + 1, 2] = b0, b1, b2
            out[i0 + 2, 0], out[i0 + 2, 1], out[i0 + 2, 2] = c0, c1, c2
            out[i0 + 3, 0], out[i0 + 3, 1], out[i0 + 3, 2] = d0, d1, d2
        else:
            for i in range(i0, n):
                r0 = M[i]
                a0 = a1 = a2 = 0.0
                for j in range(m):
                    s = np.float64(r0[j])
                    a0 += s * u0[j]
                    a1 += s * u1[j]
                    a2 += s * u2[j]
                out[i, 0], out[i, 1], out[i, 2] = a0, a1, a2


def field_product(M: np.ndarray, U: np.ndarray) -> np.ndarray:
    """``M @ U`` in float64 for a (N, N) matrix ``M`` (float64 or float32) and a field (N, 3):
    one pass over ``M`` with float64 sums. BLAS reads ``M`` three times (gemv per coordinate:
    6.9 ms at 3000 vertices, float64) or sums in single precision (sgemm: 3.1 ms, errors of
    1e-4); this kernel: 2.5 ms (float64) and 1.0 ms (float32) at 3000, exact sums."""
    out = np.empty((M.shape[0], 3))
    _product3(M, np.ascontiguousarray(U.T, dtype=np.float64), out)
    return out


@nb.njit(cache=True, parallel=True)
def _block_inverses(F, b):
    """Inverses (float64) of the lower triangles of the diagonal b × b blocks of F, row by row
    (b³/6 multiply–adds per block; np.linalg.inv of each block cost 6.6 ms per iterate at
    1648 vertices)."""
    n = F.shape[0]
    nblocks = (n + b - 1) // b
    out = np.zeros((nblocks, b, b))
    for k in nb.prange(nblocks):
        b0 = k * b
        m = min(n, b0 + b) - b0
        X = out[k]
        for i in range(m):  # row i: X[i, :i] = −L[i, :i] X[:i, :i] / L[i, i]
            for j in range(i):
                lij = F[b0 + i, b0 + j]
                for c in range(j + 1):
                    X[i, c] -= lij * X[j, c]
            d = 1.0 / F[b0 + i, b0 + i]
            for c in range(i):
                X[i, c] *= d
            X[i, i] = d
    return out


@nb.njit(cache=True, fastmath={"reassoc", "contract", "nsz", "arcp"})
def _substitution(F, v):
    """``(L Lᵀ)⁻¹ v`` with L the lower triangle of F (any float dtype), float64 sums: row dots
    forward, row updates backward, so both passes read F row by row."""
    n = F.shape[0]
    y = v.copy()
    for i in range(n):
        row = F[i]
        a = 0.0
        for j in range(i):
            a += np.float64(row[j]) * y[j]
        y[i] = (y[i] - a) / np.float64(row[i])
    for i in range(n - 1, -1, -1):
        row = F[i]
        x = y[i] / np.float64(row[i])
        y[i] = x
        for j in range(i):
            y[j] -= np.float64(row[j]) * x
    return y


class CholeskySolve:
    """``S⁻¹ v`` from the Cholesky factor ``L`` of ``S`` (the lower triangle of ``F``; the
    strict upper triangle is ignored).

    Below ``SEQUENTIAL_BELOW`` rows: plain substitution in one numba loop (float64 sums).
    Above: blocked substitution, gemv on the off-diagonal panels and precomputed inverses of
    the diagonal blocks. (LAPACK's potrs is latency bound: 1.03 against 0.28 ms for the
    blocked form at 1651 rows, 10.1 against 1.5 ms at 3003, single precision, matrix alone in
    memory.) Inside the FHW flow, ms per solve, blocked (128-row blocks) / plain: 0.13 / 0.043
    at 500 vertices, 0.18–0.22 / 0.09–0.11 at 800, 0.42–0.44 / 0.32–0.44 at 1200, 0.67–0.73 /
    0.85–0.96 at 1648. Blocks of 256 rows instead of 128 (fewer small BLAS calls): alone
    0.45 → 0.33 ms at 1651 rows, 2.25 → 1.81 ms at 3003; in the flow at 1648 0.83–0.95 →
    0.72–0.77 ms, at 3000 2.8–3.2 → 2.5–3.1 ms.
    """

    BLOCK = 256
    SEQUENTIAL_BELOW = 1000

    def __init__(self, F: np.ndarray):
        n = F.shape[0]
        self.F = F
        self.sequential = n < self.SEQUENTIAL_BELOW
        if self.sequential:
            return
        self.blocks = [(b0, min(n, b0 + self.BLOCK)) for b0 in range(0, n, self.BLOCK)]
        # explicit inverses lose κ(L_bb) digits: keep them (small) in double precision
        inv = _block_inverses(F, self.BLOCK)
        self.dinv = [inv[k, : b1 - b0, : b1 - b0] for k, (b0, b1) in enumerate(self.blocks)]

    def __call__(self, v: np.ndarray) -> np.ndarray:
        F = self.F
        if self.sequential:
            return _substitution(F, np.asarray(v, dtype=np.float64))
        n = F.shape[0]
        y = np.array(v, dtype=np.float64)
        for (b0, b1), D in zip(self.blocks, self.dinv, strict=True):  # L y = v
            r = y[b0:b1] - F[b0:b1, :b0] @ y[:b0].astype(F.dtype) if b0 else y[b0:b1]
            y[b0:b1] = D @ r
        for (b0, b1), D in zip(reversed(self.blocks), reversed(self.dinv), strict=True):  # Lᵀ x = y
            r = y[b0:b1] - F[b1:, b0:b1].T @ y[b1:].astype(F.dtype) if b1 < n else y[b0:b1]
            y[b0:b1] = D.T @ r
        return y


@nb.njit(cache=True, parallel=True)
def _edge_schur(Ainv, nxt, inv_l, T, S):
    """``S[I, J] = (D A⁻¹ Dᵀ)_IJ <t_I, t_J>`` for the edge rows, with
    ``(Du)_I = (u[nxt I] − u[I]) / l_I``: one pass over ``A⁻¹``, no N × N temporaries."""
    n = nxt.shape[0]
    for i in nb.prange(n):
        i1 = nxt[i]
        for j in range(n):
            j1 = nxt[j]
            y = (Ainv[i1, j1] - Ainv[i1, j] - Ainv[i, j1] + Ainv[i, j]) * inv_l[i] * inv_l[j]
            S[i, j] = y * (T[i, 0] * T[j, 0] + T[i, 1] * T[j, 1] + T[i, 2] * T[j, 2])


@nb.njit(cache=True, parallel=True)
def _edge_schur_rows(Ainv, nxt, edges, inv_l, T, S):
    """:func:`_edge_schur` for the rows of the edges ``edges`` only (with pins: an edge
    between two pins has no row). Separate, because the index gather makes the loop about
    three times slower (4.1 against 1.4 ms at 1648 edges, single precision)."""
    m = edges.shape[0]
    for a in nb.prange(m):
        i = edges[a]
        i1 = nxt[i]
        for b in range(m):
            j = edges[b]
            j1 = nxt[j]
            y = (Ainv[i1, j1] - Ainv[i1, j] - Ainv[i, j1] + Ainv[i, j]) * inv_l[i] * inv_l[j]
            S[a, b] = y * (T[i, 0] * T[j, 0] + T[i, 1] * T[j, 1] + T[i, 2] * T[j, 2])


class Factorization:
    """Solver of the saddle-point system at one iterate (A, C fixed).

    ``dtype=np.float32`` factors in single precision (BLAS-3 at twice the speed, half the
    memory traffic): then :meth:`solve` is accurate to about ``κ(A)·1e-7`` only and serves as
    the preconditioner of a float64 Krylov solve. ``κ(A)`` of the hs metric is ~1e5 at 1648
    edges once the constant mode is scaled (see metrics.py), well inside single precision.

    Pinned vertices (``jac.con.pinned``) are eliminated: ``A⁻¹`` is replaced by the inverse of
    the free vertices' block ``A_ff`` with zero rows and columns at the pins, i.e. ``G⁻¹`` by
    ``E (E ᵀG E)⁻¹ Eᵀ`` (``E`` the free coordinates). Every solve and every back-projection
    step is then exactly zero at the pins: the same ``u`` as with pin rows ``u_p = 0`` in the
    saddle-point system, whose ``C`` is restricted to the free coordinates.
    """

    def __init__(self, A: np.ndarray, jac: Jacobian, dtype=np.float64,
                 recycle: Factorization | None = None):
        self.jac = jac
        self.dtype = np.dtype(dtype)
        self.exact = self.dtype == np.float64
        lay = jac.con.layout
        m = jac.con.size
        # ``recycle``: a factorization that is no longer needed lends its arrays (fresh ones
        # of this size are page-faulted in anew: 27 ms per 72 MB at 3000 vertices)
        old = recycle if recycle is not None and recycle.dtype == self.dtype else None
        M = old.Ainv if old is not None and old.Ainv.shape == A.shape else None
        free = jac.con.free
        if free is not None:
            self.Ainv = self._free_inverse(A, free, M)
        else:
            if M is None:
                M = np.array(A, dtype=self.dtype, order="C")
            else:
                np.copyto(M, A, casting="same_kind")
            self.Ainv = spd_inverse(M, overwrite=True)
        S = None
        if old is not None and old.sinv is not None and old.sinv.F.shape == (m, m):
            S = old.sinv.F
        if S is None:
            S = np.empty((m, m), dtype=self.dtype)
        nb = jac.con.n_bary_rows
        ne = m - nb
        if ne:
            T, inv_l = jac.edge_fields()
            inv_l, T = inv_l.astype(self.dtype), T.astype(self.dtype)
            if ne == lay.n:
                _edge_schur(self.Ainv, lay.nxt, inv_l, T, S)
            else:
                _edge_schur_rows(self.Ainv, lay.nxt, jac.con.edge_index, inv_l, T, S)
        if nb:
            F = jac.barycenter_fields()  # (nb, N, 3)
            cols = np.stack([jac.matvec(self.ginv(F[r])) for r in range(nb)], axis=1)
            S[:, ne:] = cols
            S[ne:, :] = cols.T
        # S⁻¹ is applied by two triangular solves with its Cholesky factor (N³/3 flops)
        self.sinv = None
        if m:
            LS = _lapack.cholesky(S, overwrite=True)
            self.sinv = CholeskySolve(LS if LS is not None else np.linalg.cholesky(S))

    def _free_inverse(self, A: np.ndarray, free: np.ndarray, out: np.ndarray | None):
        """``A_ff⁻¹`` of the free vertices' block, embedded with zeros at the pins (in
        ``out`` when given)."""
        block = np.array(A[np.ix_(free, free)], dtype=self.dtype, order="C")
        inv = spd_inverse(block, overwrite=True)
        if out is None:
            out = np.zeros(A.shape, dtype=self.dtype)
        else:
            out.fill(0)
        out[np.ix_(free, free)] = inv
        return out

    def ginv(self, U: np.ndarray) -> np.ndarray:
        """``G⁻¹ U`` for a field (N, 3) (``A⁻¹`` on every coordinate, float64 sums; zero at
        pinned vertices)."""
        return field_product(self.Ainv, U)

    def solve(self, g: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``[u; λ]`` with ``G u + Cᵀ λ = g``, ``C u = r``."""
        z = self.ginv(g)
        if self.sinv is None:  # no constraint rows at all
            return z, np.zeros(0)
        lam = self.sinv(self.jac.matvec(z) - r)
        return z - self.ginv(self.jac.rmatvec(lam)), lam

    def pseudo_inverse(self, phi: np.ndarray) -> np.ndarray:
        """``G⁻¹Cᵀ(CG⁻¹Cᵀ)⁻¹ φ``: :meth:`solve` with ``g = 0``, one product with ``A⁻¹``."""
        if self.sinv is None:
            return np.zeros((self.jac.con.layout.n, 3))
        return self.ginv(self.jac.rmatvec(self.sinv(phi)))


class SaddlePointSolver:
    """Solves the saddle-point systems of successive iterates.

    Parameters
    ----------
    rtol : float
        Relative residual of the GMRES solves with a reused factorization.
    reuse : bool
        False factors every iterate (the textbook method); True reuses the last factorization
        as a preconditioner while that pays.
    dtype : numpy dtype
        Precision of the factorization. float32 halves its cost; every solve is then refined
        to ``rtol`` by GMRES with the float64 operator, so results stay double precision.
    factor_cost : float
        Cost of one factorization in units of one preconditioned Krylov iteration. The rule
        is deterministic (counts, not clocks), so runs are reproducible: refactor once the last
        iterate's solves cost more than the average per iterate since the last factorization,
        that factorization included (the optimal restart rule for costs that only grow).
    """

    def __init__(self, rtol: float = 1e-10, reuse: bool = True, max_krylov: int = 30,
                 factor_cost: float = 50.0, dtype=np.float64):
        self.rtol = rtol
        self.reuse = reuse
        self.dtype = dtype
        self.max_krylov = max_krylov
        self.factor_cost = factor_cost
        self.fac: Factorization | None = None
        self.A: np.ndarray | None = None
        self.jac: Jacobian | None = None
        self.fresh = False  # factorization belongs to the current (A, jac)
        self.spent = 0.0  # Krylov-iteration units since the last factorization
        self.iterates = 0  # iterates served since the last factorization
        self.last = 0.0  # units spent on the last iterate
        self.n_factor = 0
        self.krylov_its: list[int] = []

    def update(self, A: np.ndarray, jac: Jacobian) -> None:
        """Move to a new iterate's metric and constraints."""
        self.A = A
        self.jac = jac
        self.fresh = False
        if (
            self.fac is None
            or not self.reuse
            or (self.iterates and self.last > (self.factor_cost + self.spent) / self.iterates)
        ):
            self.refactor()
        self.iterates += 1
        self.last = 0.0

    def refactor(self) -> None:
        old, self.fac = self.fac, None  # its arrays are reused: it must not be used again
        try:
            self.fac = Factorization(self.A, self.jac, self.dtype, recycle=old)
        except np.linalg.LinAlgError:
            if self.dtype == np.float64:
                raise
            # single precision lost definiteness (h2 at many vertices has κ(A) beyond 1e7):
            # factor in double precision from now on
            self.dtype = np.float64
            self.fac = Factorization(self.A, self.jac, self.dtype)
        self.fresh = True
        self.spent = 0.0
        self.iterates = 0
        self.n_factor += 1

    def _charge(self, units: float) -> None:
        self.spent += units
        self.last += units

    def _apply_K(self, U: np.ndarray, lam: np.ndarray):
        GU = field_product(self.A, U) + self.jac.rmatvec(lam)
        pinned = self.jac.con.pinned
        if pinned is not None:
            # pinned coordinates are eliminated: the system acts on the free ones only (the
            # Krylov vectors are zero there, see _gmres)
            GU[pinned] = 0.0
        return GU, self.jac.matvec(U)

    def solve(self, g: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Solve ``[[G, Cᵀ], [C, 0]] [u; λ] = [g; r]`` at the current iterate."""
        if self.fresh and self.fac.exact:
            self.krylov_its.append(0)
            self._charge(1.0)
            return self.fac.solve(g, r)
        out, its, ok = self._gmres(g, r)
        self.krylov_its.append(its)
        self._charge(its)
        if not ok:
            self.refactor()
            out = self.fac.solve(g, r)
        return out

    def pseudo_inverse(self, phi: np.ndarray) -> np.ndarray:
        """``G⁻¹Cᵀ(CG⁻¹Cᵀ)⁻¹ φ`` with the stored factorization (modified Newton, step 4)."""
        self._charge(0.5)
        return self.fac.pseudo_inverse(phi)

    def _gmres(self, g, r):
        """Right-preconditioned GMRES on the saddle-point system, preconditioner = stored
        factorization. Returns ((u, λ), iterations, converged)."""
        n = g.shape[0]
        m = r.shape[0]
        pinned = self.jac.con.pinned
        if pinned is not None:  # the equations of pinned coordinates are not part of it
            g = g.copy()
            g[pinned] = 0.0

        def pack(U, lam):
            return np.concatenate([U.ravel(), lam])

        def unpack(x):
            return x[: 3 * n].reshape(n, 3), x[3 * n :]

        b = pack(g, r)
        bnorm = np.linalg.norm(b)
        if bnorm == 0.0:
            return (np.zeros((n, 3)), np.zeros(m)), 0, True
        x0 = pack(*self.fac.solve(g, r))
        res = b - pack(*self._apply_K(*unpack(x0)))
        beta = np.linalg.norm(res)
        tol = self.rtol * bnorm
        if beta <= tol:
            return unpack(x0), 1, True
        k_max = self.max_krylov
        V = np.zeros((k_max + 1, b.size))
        Z = np.zeros((k_max, b.size))
        H = np.zeros((k_max + 1, k_max))
        V[0] = res / beta
        y = np.zeros(0)
        for k in range(k_max):
            Z[k] = pack(*self.fac.solve(*unpack(V[k])))
            w = pack(*self._apply_K(*unpack(Z[k])))
            for j in range(k + 1):  # modified Gram–Schmidt, twice for stability
                h = V[j] @ w
                H[j, k] += h
                w -= h * V[j]
            for j in range(k + 1):
                h = V[j] @ w
                H[j, k] += h
                w -= h * V[j]
            H[k + 1, k] = np.linalg.norm(w)
            if H[k + 1, k] > 0:
                V[k + 1] = w / H[k + 1, k]
            e1 = np.zeros(k + 2)
            e1[0] = beta
            y, *_ = np.linalg.lstsq(H[: k + 2, : k + 1], e1, rcond=None)
            resid = np.linalg.norm(H[: k + 2, : k + 1] @ y - e1)
            if resid <= tol or H[k + 1, k] == 0:
                x = x0 + y @ Z[: k + 1]
                return unpack(x), k + 2, True
        return unpack(x0 + y @ Z[:k_max]), k_max + 1, False
