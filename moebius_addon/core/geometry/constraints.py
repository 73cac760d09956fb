"""Constraints and their sparse Jacobian (docs/design.md, "Constraints"; the paper's "Discrete
constraints").

    Φ(P) = ( log l_I − log l0_I  for every edge I ,  (Σ_I l_I m_I − b0) / L²  per component )

The barycenter rows are divided by ``L²`` (``L`` the total target length) so that every row is
dimensionless and one tolerance on ``|Φ|`` means the same for every size of curve. Row ``I`` of
the Jacobian touches vertices ``i`` and ``i+1`` only; ``C`` is never formed as a matrix: it is
applied as ``C @ u`` and ``Cᵀ @ λ``, each by one numba loop over the edges (numpy's gathers
and ``reduceat`` cost 50–70 µs per call at 500 vertices, and a run makes about 60 per
iteration).

With pinned vertices (:mod:`.pins`) the rows change: an edge whose two ends are pinned has no
row (its length cannot change), and a component with a pin has no barycenter rows (the pins
hold it). ``edge_rows`` and ``bary_rows`` map edges and components to their rows (−1: none);
without pins they are the rows above, and every kernel computes the same numbers in the same
order as before pins existed.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numba as nb
import numpy as np

from ..metrics._tridiagonal import cyclic_tridiagonal_solve
from .layout import Layout


@dataclass
class Constraints:
    """Targets of the constraint map for one run."""

    layout: Layout
    lengths0: np.ndarray  # (N,) target edge lengths
    barycenter0: np.ndarray  # (K, 3) target Σ l_I m_I per component
    edge_lengths: bool = True
    barycenter: bool = True
    pinned: np.ndarray | None = None  # sorted stacked indices of pinned vertices (.pins)
    log_lengths0: np.ndarray = field(init=False, repr=False)
    scale: float = field(init=False)  # L², L the total target length
    edge_rows: np.ndarray = field(init=False, repr=False)  # (N,) row of edge I, or −1
    bary_rows: np.ndarray = field(init=False, repr=False)  # (K,) first barycenter row, or −1
    edge_index: np.ndarray = field(init=False, repr=False)  # edges that have a row, in order
    bary_components: np.ndarray = field(init=False, repr=False)  # components that have rows

    def __post_init__(self):
        self.log_lengths0 = np.log(self.lengths0)
        self.scale = float(self.lengths0.sum()) ** 2
        lay = self.layout
        has_edge = np.full(lay.n, self.edge_lengths)
        if lay.has_open:
            has_edge &= lay.real  # an open component's dummy edge (._layout) has no row
        has_bary = np.full(lay.k, self.barycenter)
        if self.pinned is not None:
            pin = np.zeros(lay.n, bool)
            pin[self.pinned] = True
            has_edge &= ~(pin & pin[lay.nxt])  # both ends pinned: the length is fixed
            has_bary[np.unique(lay.comp[self.pinned])] = False  # the pins hold the component
        self.edge_index = np.flatnonzero(has_edge).astype(np.int64)
        self.bary_components = np.flatnonzero(has_bary).astype(np.int64)
        self.edge_rows = np.full(lay.n, -1, np.int64)
        self.edge_rows[self.edge_index] = np.arange(self.edge_index.size)
        self.bary_rows = np.full(lay.k, -1, np.int64)
        self.bary_rows[self.bary_components] = (
            self.edge_index.size + 3 * np.arange(self.bary_components.size))

    @property
    def n_edge_rows(self) -> int:
        return int(self.edge_index.size)

    @property
    def n_bary_rows(self) -> int:
        return 3 * int(self.bary_components.size)

    @property
    def size(self) -> int:
        return self.n_edge_rows + self.n_bary_rows

    @property
    def free(self) -> np.ndarray | None:
        """Indices of the vertices that may move, or None when nothing is pinned."""
        if self.pinned is None:
            return None
        keep = np.ones(self.layout.n, bool)
        keep[self.pinned] = False
        return np.flatnonzero(keep)


@nb.njit(cache=True)
def _constraint_values(X, nxt, comp, k, log_l0, erow, ne):
    """Edge rows ``log l_I − log l0_I`` (row ``erow[I]``, none where −1; ``ne`` rows) and
    ``Σ_I l_I m_I`` per component."""
    n = X.shape[0]
    rows = np.empty(ne)
    wb = np.zeros((k, 3))
    for i in range(n):
        j = nxt[i]
        e0 = X[j, 0] - X[i, 0]
        e1 = X[j, 1] - X[i, 1]
        e2 = X[j, 2] - X[i, 2]
        ln = np.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
        r = erow[i]
        if r >= 0:
            rows[r] = np.log(ln) - log_l0[i]
        c = comp[i]
        for d in range(3):
            wb[c, d] += 0.5 * ln * (X[i, d] + X[j, d])
    return rows, wb


def weighted_barycenters(X: np.ndarray, layout: Layout) -> np.ndarray:
    """``Σ_I l_I m_I`` per component, shape (K, 3)."""
    return _constraint_values(X, layout.nxt, layout.comp, layout.k, np.zeros(0),
                              np.full(layout.n, -1, np.int64), 0)[1]


def residual(X: np.ndarray, con: Constraints) -> np.ndarray:
    """Φ(X) as one vector: edge rows then 3 barycenter rows per component (those that have
    rows, see :class:`Constraints`)."""
    layout = con.layout
    rows, wb = _constraint_values(X, layout.nxt, layout.comp, layout.k, con.log_lengths0,
                                  con.edge_rows, con.n_edge_rows)
    if not con.n_bary_rows:
        return rows
    bary = (wb - con.barycenter0) / con.scale
    if con.bary_components.size < layout.k:
        bary = bary[con.bary_components]
    return np.concatenate([rows, bary.ravel()])


@nb.njit(cache=True)
def _matvec(U, nxt, comp, k, T, ln, b, M, scale, erow, brow, size):
    n = U.shape[0]
    out = np.empty(size)
    acc = np.zeros((k, 3))
    for i in range(n):
        j = nxt[i]
        proj = (T[i, 0] * (U[j, 0] - U[i, 0]) + T[i, 1] * (U[j, 1] - U[i, 1])
                + T[i, 2] * (U[j, 2] - U[i, 2]))  # l_I <t_I, (Du)_I>
        if erow[i] >= 0:
            out[erow[i]] = proj / ln[i]
        c = comp[i]
        if brow[c] >= 0:
            for d in range(3):
                acc[c, d] += b[i] * U[i, d] + M[i, d] * proj
    for c in range(k):
        if brow[c] >= 0:
            for d in range(3):
                out[brow[c] + d] = acc[c, d] / scale
    return out


@nb.njit(cache=True)
def _rmatvec(lam, nxt, comp, T, ln, b, M, scale, erow, brow, U):
    n = T.shape[0]
    U[:] = 0.0
    for i in range(n):
        # coefficient of t_I in edge I's contribution
        s = lam[erow[i]] / ln[i] if erow[i] >= 0 else 0.0
        r = brow[comp[i]]
        if r >= 0:
            for d in range(3):
                mu = lam[r + d] / scale
                U[i, d] += b[i] * mu
                s += M[i, d] * mu
        j = nxt[i]
        for d in range(3):
            v = s * T[i, d]
            U[i, d] -= v
            U[j, d] += v


@dataclass
class Jacobian:
    """``C = DΦ(X)`` in factored form: unit tangents, lengths, midpoints, vertex weights."""

    con: Constraints
    T: np.ndarray  # (N, 3) unit tangents
    ln: np.ndarray  # (N,) edge lengths
    M: np.ndarray  # (N, 3) midpoints
    b: np.ndarray  # (N,) (l_{p−1} + l_p) / 2

    def matvec(self, U: np.ndarray) -> np.ndarray:
        """``C @ u`` for a field ``U`` of shape (N, 3)."""
        con = self.con
        lay = con.layout
        return _matvec(np.ascontiguousarray(U, dtype=np.float64), lay.nxt, lay.comp, lay.k,
                       self.T, self.ln, self.b, self.M, con.scale, con.edge_rows,
                       con.bary_rows, con.size)

    def rmatvec(self, lam: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """``Cᵀ @ λ`` as a field of shape (N, 3), in ``out`` (C-contiguous float64) if given."""
        con = self.con
        lay = con.layout
        out = np.empty((lay.n, 3)) if out is None else out
        _rmatvec(np.ascontiguousarray(lam, dtype=np.float64), lay.nxt, lay.comp, self.T,
                 self.ln, self.b, self.M, con.scale, con.edge_rows, con.bary_rows, out)
        return out

    def edge_fields(self) -> tuple[np.ndarray, np.ndarray]:
        """Unit tangents and ``1/l`` of every edge (those with a row: ``con.edge_index``) for
        the structured Schur complement of the edge rows."""
        lay = self.con.layout
        if not lay.has_open:
            return self.T, 1.0 / self.ln
        inv = np.zeros_like(self.ln)  # 0 at the dummy edges (no row, ._layout)
        inv[lay.real] = 1.0 / self.ln[lay.real]
        return self.T, inv

    def barycenter_fields(self) -> np.ndarray:
        """The barycenter rows of ``C`` as fields: array (3K', N, 3), K' the components that
        have them (all K without pins)."""
        con = self.con
        nb = con.n_bary_rows
        F = np.zeros((nb, con.layout.n, 3))
        for row in range(nb):
            lam = np.zeros(con.size)
            lam[con.n_edge_rows + row] = 1.0
            F[row] = self.rmatvec(lam)
        return F


def jacobian(X: np.ndarray, con: Constraints) -> Jacobian:
    layout = con.layout
    E = X[layout.nxt] - X
    ln = np.sqrt(np.einsum("ij,ij->i", E, E))
    if layout.has_open:  # the dummy edges of open components: tangent 0, not 0/0
        T = np.zeros_like(E)
        real = layout.real
        T[real] = E[real] / ln[real, None]
    else:
        T = E / ln[:, None]
    return Jacobian(
        con,
        T,
        ln,
        0.5 * (X + X[layout.nxt]),
        0.5 * (ln[layout.prv] + ln),
    )


def make_constraints(
    X: np.ndarray,
    layout: Layout,
    lengths0: np.ndarray,
    edge_lengths: bool = True,
    barycenter: bool = True,
    pinned: np.ndarray | None = None,
) -> Constraints:
    """The constraints of a run at its start ``X``; ``pinned``: checked stacked indices
    (:func:`.pins.check_pins`) or None."""
    return Constraints(
        layout, np.asarray(lengths0, float), weighted_barycenters(X, layout), edge_lengths,
        barycenter, pinned,
    )


@nb.njit(cache=True)
def _edge_gram(T, ln, nxt, starts):
    """``C_e C_eᵀ`` of the edge rows as a cyclic tridiagonal matrix per component: diagonal
    ``2 / l_I²``, and ``−<t_I, t_J> / (l_I l_J)`` for the edges ``J = nxt I`` sharing vertex
    ``nxt I``."""
    n = T.shape[0]
    diag = np.empty(n)
    off = np.empty(n)
    for i in range(n):
        j = nxt[i]
        diag[i] = 2.0 / (ln[i] * ln[i])
        off[i] = -(T[i, 0] * T[j, 0] + T[i, 1] * T[j, 1] + T[i, 2] * T[j, 2]) / (ln[i] * ln[j])
    return diag, off


@nb.njit(cache=True)
def _bordered_solve(cw, diag, off, TiB, schur, starts):
    """``(CCᵀ)⁻¹ cw`` with ``CCᵀ = [[T, B], [Bᵀ, D]]`` per component (T cyclic tridiagonal,
    ``TiB = T⁻¹B`` and ``schur = (D − BᵀT⁻¹B)⁻¹`` precomputed): the barycenter part by the
    Schur complement, then the edge part."""
    k = starts.shape[0] - 1
    n = starts[k]
    out = np.empty(cw.shape[0])
    for c in range(k):
        s0, s1 = starts[c], starts[c + 1]
        t = cyclic_tridiagonal_solve(diag[s0:s1], off[s0:s1], cw[s0:s1].copy())
        rhs = np.empty(3)
        for d in range(3):
            acc = cw[n + 3 * c + d]
            for i in range(s0, s1):
                acc -= TiB[c, d, i] * cw[i]
            rhs[d] = acc
        for d in range(3):
            z = 0.0
            for e in range(3):
                z += schur[c, d, e] * rhs[e]
            out[n + 3 * c + d] = z
        for i in range(s0, s1):
            y = t[i - s0]
            for d in range(3):
                y -= out[n + 3 * c + d] * TiB[c, d, i]
            out[i] = y
    return out


class TangentProjector:
    """The Euclidean orthogonal projection ``Π = I − Cᵀ(CCᵀ)⁻¹C`` onto the tangent space of the
    constraints (``C u = 0``), in O(N): ``CCᵀ`` is cyclic tridiagonal per component in the
    edge rows (edges sharing a vertex), bordered by the three barycenter rows of each component
    (a 3 × 3 Schur complement per component). Needs both kinds of rows, and no pins."""

    def __init__(self, jac: Jacobian):
        con = jac.con
        if not (con.edge_lengths and con.barycenter) or con.pinned is not None:
            raise ValueError("the tangent projector needs the edge-length and barycenter rows "
                             "and no pinned vertices")
        lay = con.layout
        self.jac, self.layout = jac, lay
        self.diag, self.off = _edge_gram(jac.T, jac.ln, lay.nxt, lay.starts)
        F = jac.barycenter_fields()  # (3k, N, 3): the barycenter rows as fields
        n, k = lay.n, lay.k
        # B = C_e C_bᵀ (N × 3k, block-diagonal by component), D = C_b C_bᵀ (3k × 3k)
        self.TiB = np.zeros((k, 3, n))
        self.schur = np.empty((k, 3, 3))
        for c in range(k):
            s = slice(lay.starts[c], lay.starts[c + 1])
            B = np.stack([jac.matvec(F[3 * c + d])[:n][s] for d in range(3)])
            for d in range(3):
                self.TiB[c, d, s] = self._tri(c, B[d])
            D = np.array([[np.sum(F[3 * c + d] * F[3 * c + e]) for e in range(3)]
                          for d in range(3)])
            self.schur[c] = np.linalg.inv(D - B @ self.TiB[c, :, s].T)

    def _tri(self, c: int, r: np.ndarray) -> np.ndarray:
        s = slice(self.layout.starts[c], self.layout.starts[c + 1])
        return cyclic_tridiagonal_solve(self.diag[s], self.off[s], np.ascontiguousarray(r))

    def multipliers(self, W: np.ndarray) -> np.ndarray:
        """``(CCᵀ)⁻¹ C W`` for a field ``W`` (N, 3)."""
        return _bordered_solve(self.jac.matvec(W), self.diag, self.off, self.TiB, self.schur,
                               self.layout.starts)

    def __call__(self, W: np.ndarray) -> np.ndarray:
        """``Π W``: ``W`` (N, 3) moved orthogonally onto ``C u = 0``."""
        return W - self.jac.rmatvec(self.multipliers(W))
