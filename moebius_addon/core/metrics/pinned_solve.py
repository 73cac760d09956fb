"""Saddle-point solves with pinned vertices for the tree engine's O(N) solvers, by bordering
the solver of the same system without pins.

The system with pins (:mod:`.pins`) differs from the one without in a few rows: the pin rows
``u_p = 0`` (three per pinned vertex) are added, and the rows of edges between two pins and
the barycenter rows of pinned components are dropped (their multipliers are zero). With
``K₀`` the system without pins and ``Q`` the selector of the pinned coordinates of ``u`` and
the dropped rows' multipliers, the solution with pins is

    w = w₀ + K₀⁻¹ Qᵀ y,    (Q K₀⁻¹ Qᵀ) y = −Q w₀,    w₀ = K₀⁻¹ b₀

(``y`` holds the pin rows' multipliers and the values the dropped rows take). It needs one
solve of ``K₀`` per bordering column at every iterate (batched), so it serves a few pins
(``TREE_MAX_PINS``); the pinned coordinates of the result are then set to exactly zero (they
are zero up to the solve's rounding). This is the same ``u`` as eliminating the pinned
coordinates (:class:`.linalg.Factorization`), in the solver's own metric.
"""

from __future__ import annotations

import numpy as np

from ..geometry.constraints import Constraints, Jacobian

#: Most pinned vertices (with ``pin_tangents``: their neighbours included) for which the tree
#: engine borders its O(N) solvers; beyond, it solves densely like the exact engine. Every
#: pin costs three solves of the system without pins at every iterate.
TREE_MAX_PINS = 50


def tree_borders(n_pinned: int) -> bool:
    """Whether the tree engine solves a run with ``n_pinned`` pinned vertices in O(N)."""
    return 0 < n_pinned <= TREE_MAX_PINS


def unpinned_jacobian(jac: Jacobian) -> Jacobian:
    """The Jacobian of the same polygon with every row (no pins): the same fields."""
    con = jac.con
    full = Constraints(con.layout, con.lengths0, con.barycenter0, True, True)
    return Jacobian(full, jac.T, jac.ln, jac.M, jac.b)


# Bordering columns solved per batch (memory: this many (N, 3) fields at a time).
_BATCH = 32


class BorderedPins:
    """Solver of the saddle-point system with pins from ``base``, a solver of the system
    without pins at the same polygon (:class:`.banded.BandedSaddle`: ``_solve``,
    ``solve_many``, ``metric_product``); ``jac`` is the Jacobian with pins. Solves take and
    return the pinned system's rows (the order of ``constraints.residual``). Memory O(N):
    only the capacitance matrix ``Q K₀⁻¹ Qᵀ`` is kept, and every solve is two solves of
    ``K₀`` (the second with the bordered right-hand side)."""

    def __init__(self, base, jac: Jacobian):
        con = jac.con
        lay = con.layout
        n, k = lay.n, lay.k
        self.base, self.jac = base, jac
        self.pinned = con.pinned
        self.m0 = n + 3 * k  # rows without pins: every edge, then three per component
        bary = (n + 3 * con.bary_components[:, None] + np.arange(3)).ravel()
        self.kept = np.concatenate([con.edge_index, bary]).astype(np.int64)
        keep = np.zeros(self.m0, bool)
        keep[self.kept] = True
        self.dropped = np.flatnonzero(~keep)
        p = self.pinned.size
        self.n_border = nb = 3 * p + self.dropped.size
        cols = []
        for s0 in range(0, nb, _BATCH):
            G, R = self._border(np.eye(nb)[s0:s0 + _BATCH])
            cols.append(self._select(*base.solve_many(G, R)))
        # Q K₀⁻¹ Qᵀ, inverted once: a LAPACK solve per call cost 3 ms at 30 rows (FHW at
        # 1 000 edges, 10 pins; threads contending after the parallel kernels), the product
        # microseconds
        self.cap_inv = np.linalg.inv(np.concatenate(cols).T)

    def release(self) -> None:
        """Let go of all but the band's memory (:meth:`BandedSaddle.release`), which the next
        iterate's solver takes over. Unusable afterwards."""
        self.base.release()
        self.__dict__ = {"base": self.base}

    def _border(self, Y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``Qᵀ y`` for the rows ``y`` of ``Y`` (m, n_border): fields and rows without pins."""
        m = Y.shape[0]
        p = self.pinned.size
        G = np.zeros((m, self.jac.con.layout.n, 3))
        G[:, self.pinned] = Y[:, :3 * p].reshape(m, p, 3)
        R = np.zeros((m, self.m0))
        R[:, self.dropped] = Y[:, 3 * p:]
        return G, R

    def _select(self, U: np.ndarray, L: np.ndarray) -> np.ndarray:
        """``Q w`` for solutions given as fields ``U`` (m, N, 3) and multipliers ``L``."""
        m = U.shape[0]
        return np.concatenate([U[:, self.pinned].reshape(m, -1), L[:, self.dropped]], axis=1)

    def _solve(self, g: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(u, λ)`` of the system with pins, ``u`` exactly zero at the pins."""
        r0 = np.zeros(self.m0)
        r0[self.kept] = r
        u, lam = self.base._solve(g, r0)  # g None: zero
        y = self.cap_inv @ -self._select(u[None], lam[None])[0]
        G, R = self._border(y[None])
        u, lam = self.base._solve((G[0] + 0.0) if g is None else g + G[0], r0 + R[0])
        u[self.pinned] = 0.0
        return u, lam[self.kept]

    def solve(self, g: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`_solve` with one step of iterative refinement (as ``BandedSaddle.solve``);
        the pinned coordinates' equations are not part of the system."""
        u, lam = self._solve(g, r)
        rg = g - self.metric_product(u) - self.jac.rmatvec(lam)
        rg[self.pinned] = 0.0
        du, dlam = self._solve(rg, r - self.jac.matvec(u))
        return u + du, lam + dlam

    def pseudo_inverse(self, phi: np.ndarray) -> np.ndarray:
        """``G⁻¹Cᵀ(CG⁻¹Cᵀ)⁻¹ φ`` with pins (one back-projection step), zero at the pins."""
        return self._solve(np.zeros((self.jac.con.layout.n, 3)), phi)[0]

    def metric_product(self, V: np.ndarray) -> np.ndarray:
        return self.base.metric_product(V)
