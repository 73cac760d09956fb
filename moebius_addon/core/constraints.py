"""Constraints and their sparse Jacobian (DESIGN.md, "Constraints"; the paper's "Discrete
constraints").

    Φ(P) = ( log l_I − log l0_I  for every edge I ,  (Σ_I l_I m_I − b0) / L²  per component )

The barycenter rows are divided by ``L²`` (``L`` the total target length) so that every row is
dimensionless and one tolerance on ``|Φ|`` means the same for every size of curve. Row ``I`` of
the Jacobian touches vertices ``i`` and ``i+1`` only; ``C`` is never formed as a matrix: it is
applied as ``C @ u`` and ``Cᵀ @ λ``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ._layout import Layout


@dataclass
class Constraints:
    """Targets of the constraint map for one run."""

    layout: Layout
    lengths0: np.ndarray  # (N,) target edge lengths
    barycenter0: np.ndarray  # (K, 3) target Σ l_I m_I per component
    edge_lengths: bool = True
    barycenter: bool = True

    @property
    def scale(self) -> float:
        return float(self.lengths0.sum()) ** 2

    @property
    def size(self) -> int:
        return (self.layout.n if self.edge_lengths else 0) + (
            3 * self.layout.k if self.barycenter else 0
        )


def weighted_barycenters(X: np.ndarray, layout: Layout) -> np.ndarray:
    """``Σ_I l_I m_I`` per component, shape (K, 3)."""
    E = X[layout.nxt] - X
    ln = np.sqrt(np.einsum("ij,ij->i", E, E))
    lm = 0.5 * ln[:, None] * (X + X[layout.nxt])
    return np.add.reduceat(lm, layout.starts[:-1], axis=0)


def residual(X: np.ndarray, con: Constraints) -> np.ndarray:
    """Φ(X) as one vector: edge rows then 3 barycenter rows per component."""
    layout = con.layout
    parts = []
    if con.edge_lengths:
        E = X[layout.nxt] - X
        ln = np.sqrt(np.einsum("ij,ij->i", E, E))
        parts.append(np.log(ln) - np.log(con.lengths0))
    if con.barycenter:
        parts.append(((weighted_barycenters(X, layout) - con.barycenter0) / con.scale).ravel())
    return np.concatenate(parts) if parts else np.zeros(0)


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
        lay = self.con.layout
        dU = U[lay.nxt] - U
        proj = np.einsum("ij,ij->i", self.T, dU)  # l_I <t_I, (Du)_I>
        out = []
        if self.con.edge_lengths:
            out.append(proj / self.ln)
        if self.con.barycenter:
            rows = self.b[:, None] * U + self.M * proj[:, None]
            out.append((np.add.reduceat(rows, lay.starts[:-1], axis=0) / self.con.scale).ravel())
        return np.concatenate(out) if out else np.zeros(0)

    def rmatvec(self, lam: np.ndarray) -> np.ndarray:
        """``Cᵀ @ λ`` as a field of shape (N, 3)."""
        lay = self.con.layout
        n = lay.n
        s = np.zeros(n)  # coefficient of t_I in edge I's contribution
        U = np.zeros((n, 3))
        k = 0
        if self.con.edge_lengths:
            s += lam[:n] / self.ln
            k = n
        if self.con.barycenter:
            mu = lam[k : k + 3 * lay.k].reshape(lay.k, 3) / self.con.scale
            mu_v = mu[lay.comp]  # per vertex / edge of its component
            U += self.b[:, None] * mu_v
            s += np.einsum("ij,ij->i", self.M, mu_v)
        V = s[:, None] * self.T
        U -= V
        U[lay.nxt] += V
        return U

    def edge_fields(self) -> tuple[np.ndarray, np.ndarray]:
        """Unit tangents and ``1/l`` for the structured Schur complement of the edge rows."""
        return self.T, 1.0 / self.ln

    def barycenter_fields(self) -> np.ndarray:
        """The barycenter rows of ``C`` as fields: array (3K, N, 3)."""
        lay = self.con.layout
        k = lay.k
        F = np.zeros((3 * k, lay.n, 3))
        for row in range(3 * k):
            lam = np.zeros(self.con.size)
            lam[self.con.size - 3 * k + row] = 1.0
            F[row] = self.rmatvec(lam)
        return F


def jacobian(X: np.ndarray, con: Constraints) -> Jacobian:
    layout = con.layout
    E = X[layout.nxt] - X
    ln = np.sqrt(np.einsum("ij,ij->i", E, E))
    return Jacobian(
        con,
        E / ln[:, None],
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
) -> Constraints:
    return Constraints(
        layout, np.asarray(lengths0, float), weighted_barycenters(X, layout), edge_lengths,
        barycenter,
    )
