"""Saddle-point solves with the hs metric of the tree (:mod:`.hs_tree`) by a preconditioned
Krylov method.

The systems ``[[Ã ⊗ I₃, Cᵀ], [C, 0]] [u; λ] = [g; r]`` (docs/design.md, steps 2 and 4) are
solved by projected conjugate gradients (Gould, Hribar & Nocedal 2001, with their residual
update) preconditioned by

* the constraint preconditioner ``[[H ⊗ I₃, Cᵀ], [C, 0]]``, solved exactly in O(N) by
  :mod:`.banded`: ``H = s·h1 + 2 Mᵀ diag(Ṽ1_folded) M``, the h1 metric scaled to ``Ã``'s trace
  plus, on the diagonal, the lower-order weights of folded pairs (strands that come close
  again along the curve, and other components), which carry the strong coupling of strands
  close in space (without them the iterates' errors moved such strands against each other and
  the collision bound stalled the flow); without the barycenter term, which moves only the
  multipliers (:class:`.banded.BandedSaddle`, ``barycenter_term``), and with ``H``'s
  translations minimized out, its barycenter rows projected (``projected``): ``Ã``'s two
  Laplacians charge nothing for a translation (its barycenter term moves the multipliers
  only), ``H``'s mass and folded weights do;
* from ``MULTILEVEL_FROM`` vertices on, plus the coarser levels of :class:`Multilevel` (the
  curve quartered again and again, each level's own banded ``H``; additive, BPX): what the
  banded ``H`` misses most on smooth curves are the low modes, at every scale below its own.
  (``PRECONDITIONER = "two_level"``: one dense coarse level, :class:`CoarseLevel`, instead;
  its count grew with N and the curve, to the cap of 200 at 10⁶ on FHW.)

Every iterate stays on ``C u = r`` to rounding, whatever the tolerance. Measured iterations
(docs/lab/tree-engine.md, "Krylov iterations against N"): 4–15 per solve below 2·10⁴ vertices
on the banded ``H`` alone, 5–15 with the levels from 2·10⁴ to 10⁵, 9 at 10⁶ (FHW).
"""

from __future__ import annotations

import numba as nb
import numpy as np

from ..geometry.collision import closest_vertices
from ..geometry.constraints import Jacobian, TangentProjector, jacobian, make_constraints
from ..geometry.layout import Layout, layout_from_sizes
from ..geometry.polygon import CONTACT_GAP
from ..tree.hs_metric import HsOperator
from .banded import BandedSaddle, OpenBandedSaddle
from .gram import PAPER_ORDER, gram_x
from .pinned_solve import BorderedPins, unpinned_jacobian
from .saddle import Factorization

#: Relative tolerance of the gradient's Krylov solve (preconditioned residual norm).
RTOL = 1e-2
#: The coarse level of the preconditioner: about ``COARSE_PER_ROOT · √N`` vertices, at most
#: ``COARSE_MAX`` (solved densely), none below ``COARSE_FROM`` vertices (median iteration,
#: alternated, busy machine: 7_2 at 10 000 edges 217-222 ms without, 233-248 ms with it; FHW
#: at 20 000 0.46 / 0.47 s; 7_2 at 100 000 5.0 / 3.0 s).
COARSE_PER_ROOT = 8.0
COARSE_MAX = 2500
COARSE_FROM = 20000
#: Which preconditioner :class:`HsSaddle` builds: "two_level" (the banded constraint
#: preconditioner plus :class:`CoarseLevel`) or "multilevel" (plus :class:`Multilevel`).
PRECONDITIONERS = ("two_level", "multilevel")
#: "multilevel" from ``MULTILEVEL_FROM`` vertices on: with a level at every second halving it
#: took 5-15 iterations per solve where two_level took 9-38 at 2·10⁴-10⁵, 1.3-1.9x faster
#: per iteration from 5·10⁴ on and mixed at 2·10⁴ (alternated, 27 November 2026); at 10⁶
#: 9-25 on four curves where two_level hit its cap of 200 on FHW (docs/lab/tree-engine.md,
#: "Krylov iterations against N").
PRECONDITIONER = "multilevel"
#: "multilevel" from this many vertices on (below, the banded constraint preconditioner alone).
MULTILEVEL_FROM = COARSE_FROM


def check_rtol(rtol) -> float:
    """``rtol`` as a float in [1e-10, 1), else ValueError naming ``krylov_rtol``."""
    try:
        t = float(rtol)
    except (TypeError, ValueError):
        raise ValueError(f"krylov_rtol must be a number in [1e-10, 1), got {rtol!r}") from None
    if not 1e-10 <= t < 1.0:
        raise ValueError(f"krylov_rtol must be a number in [1e-10, 1), got {rtol!r}")
    return t


def coarse_size(n: int) -> int:
    """Vertices of the preconditioner's coarse level for ``n`` fine ones (0: none)."""
    if n < COARSE_FROM:
        return 0
    return int(min(COARSE_MAX, COARSE_PER_ROOT * np.sqrt(n)))


class CoarseLevel:
    """The coarse level of the preconditioner: the polygon of every ``m``-th vertex of each
    component, its own metric (dense) and constraints, and linear interpolation along the
    curve between the two (``P``). Applied to a residual ``r`` it returns ``Π P S_c Pᵀ Π r``:
    the coarse constrained solve ``S_c`` of the restricted residual, interpolated, on the
    tangent space of the fine constraints (``Π``: their Euclidean orthogonal projection,
    :class:`constraints.TangentProjector`, O(N) with a tiny constant; symmetric, so the sum
    stays a symmetric preconditioner that annihilates ``range Cᵀ`` and maps into ``ker C``).
    Added to the constraint preconditioner (a two-level additive Schwarz preconditioner) it
    carries what the banded ``H`` misses most on smooth curves, the lowest modes, whose hs
    energy grows one power of the frequency faster than h1's. (Projecting with the banded
    ``H`` instead, one more band solve per application, measured one iteration fewer: 7_2 at
    20 000 edges, iterate 15, 11 / 11 / 25 against 12 / 12 / 29.)

    Parameters
    ----------
    X : (N, 3) array
    layout : Layout
    metric : {"hs", "hs_pure"}
    jac : Jacobian
        The fine constraint Jacobian.
    size : int
        Coarse vertices wanted in all; components keep at least 8 (or all they have).
    order : float
        The metric's order (the fine operator's).
    """

    def __init__(self, X: np.ndarray, layout: Layout, metric: str, jac: Jacobian, size: int,
                 order: float = PAPER_ORDER):
        self.project = TangentProjector(jac)
        m = max(1, int(round(layout.n / max(size, 1))))
        idx, sizes, a, b, f = [], [], [], [], []
        offset = 0
        for c in range(layout.k):
            s0, s1 = int(layout.starts[c]), int(layout.starts[c + 1])
            step = m if (s1 - s0) // m >= 8 else 1
            local = np.arange(s1 - s0)
            ci = s0 + local[::step]
            k = len(ci)
            j = local // step  # the coarse vertex before each fine one, and the next
            a.append(offset + j)
            b.append(offset + (j + 1) % k)
            f.append((local - j * step) / step)
            idx.append(ci)
            sizes.append(k)
            offset += k
        self.a, self.b = np.concatenate(a), np.concatenate(b)
        self.f = np.concatenate(f)[:, None]
        self.n = offset
        idx = np.concatenate(idx)
        clay = layout_from_sizes(sizes, layout.is_link)
        Xc = X[idx]
        lc = np.linalg.norm(Xc[clay.nxt] - Xc, axis=1)
        self.jc = jacobian(Xc, make_constraints(Xc, clay, lc))
        # double precision: a single-precision factorization of a nearly relaxed 7_2's coarse
        # polygon (1 131 vertices) made the preconditioner indefinite (rᵀz < 0)
        self.fac = Factorization(gram_x(metric, Xc, clay, order=order), self.jc, np.float64)

    def prolong(self, Uc: np.ndarray) -> np.ndarray:
        """``P Uc``: (coarse vertices, 3) to (N, 3), linear along the curve."""
        return (1.0 - self.f) * Uc[self.a] + self.f * Uc[self.b]

    def restrict(self, R: np.ndarray) -> np.ndarray:
        """``Pᵀ R``: (N, 3) to (coarse vertices, 3)."""
        out = np.empty((self.n, 3))
        for d in range(3):
            out[:, d] = (np.bincount(self.a, (1.0 - self.f[:, 0]) * R[:, d], self.n)
                         + np.bincount(self.b, self.f[:, 0] * R[:, d], self.n))
        return out

    def __call__(self, R: np.ndarray) -> np.ndarray:
        uc, _ = self.fac.solve(self.restrict(self.project(R)), np.zeros(self.jc.con.size))
        return self.project(self.prolong(uc))


#: The multilevel preconditioner halves the curve down to at most ``COARSEST`` vertices,
#: while every level's contact ratio (closest vertices ``CONTACT_GAP`` edges apart or on other
#: components, in mean edge lengths) stays at least ``MIN_CONTACT``; its coarsest level is
#: solved densely when it has at most ``DENSE_MAX`` vertices, else by its banded ``H``.
COARSEST = 400
MIN_CONTACT = 0.5
DENSE_MAX = 1200
#: Levels at every ``STRIDE``-th halving (the curve quartered from level to level), the
#: coarsest always: at 10⁵ vertices every second level left out took FHW's count per solve
#: from 8 to 7-8 and the Borromean rings' from 17 to 15, and a level's set-up and solve cost
#: about its vertices (docs/lab/tree-engine.md, "Krylov iterations against N").
STRIDE = 2


@nb.njit(cache=True, parallel=True)
def _csr_product(ptr, cols, vals, Y, out):
    """``out = S Y`` for ``S`` in compressed rows and ``Y`` (m, d): rows in parallel, each
    summed in its own order (the same bits for any thread count)."""
    for i in nb.prange(out.shape[0]):
        for d in range(out.shape[1]):
            s = 0.0
            for t in range(ptr[i], ptr[i + 1]):
                s += vals[t] * Y[cols[t], d]
            out[i, d] = s


class _Sparse:
    """A sparse matrix by its entries ``(rows, cols, vals)``, with ``@`` on vectors and on
    (n, 3) arrays: the levels' interpolations (no scipy here: the extension ships numpy and
    numba only). Kept in compressed rows for a numba product: with ``np.add.at`` the first
    restriction and the last prolongation alone took 0.040 s of the 0.134 s of one application
    at 10⁵ vertices (0.0025 s now)."""

    def __init__(self, rows: np.ndarray, cols: np.ndarray, vals: np.ndarray, shape: tuple):
        self.rows, self.cols, self.vals, self.shape = rows, cols, vals, shape
        order = np.argsort(rows, kind="stable")
        self._cols = np.ascontiguousarray(cols[order], dtype=np.int64)
        self._vals = np.ascontiguousarray(vals[order], dtype=np.float64)
        self._ptr = np.zeros(shape[0] + 1, np.int64)
        np.cumsum(np.bincount(rows, minlength=shape[0]), out=self._ptr[1:])

    @property
    def T(self) -> _Sparse:
        return _Sparse(self.cols, self.rows, self.vals, (self.shape[1], self.shape[0]))

    def __matmul__(self, y: np.ndarray) -> np.ndarray:
        y = np.asarray(y, dtype=np.float64)
        Y = np.ascontiguousarray(y.reshape(y.shape[0], -1))
        out = np.empty((self.shape[0], Y.shape[1]))
        _csr_product(self._ptr, self._cols, self._vals, Y, out)
        return out.reshape((self.shape[0],) + y.shape[1:])

    def compressed(self) -> _Sparse:
        """This matrix with its compressed rows only (``@`` works, ``T`` and
        :meth:`toarray` do not): the multilevel's transfers, whose entry lists were 0.1 GB
        at 10⁶ vertices."""
        S = object.__new__(_Sparse)
        S.shape, S._cols, S._vals, S._ptr = self.shape, self._cols, self._vals, self._ptr
        S.rows = S.cols = S.vals = None
        return S

    def toarray(self) -> np.ndarray:
        A = np.zeros(self.shape)
        np.add.at(A, (self.rows, self.cols), self.vals)
        return A


def _halve(layout: Layout) -> tuple[np.ndarray, Layout, _Sparse]:
    """Every second vertex of each component with at least 16 vertices (the others kept
    whole): the kept indices, the coarse layout and the interpolation ``P`` (fine × coarse)
    from the coarse vertices to the fine ones, by the four-point subdivision scheme (Dubuc;
    Deslauriers & Dubuc): the kept vertices stay, a dropped one is
    ``(−c_{j−1} + 9 c_j + 9 c_{j+1} − c_{j+2}) / 16``. Its limit fields are C¹, so the
    interpolated fields of a coarse level have about the hs energy of the coarse level's own
    operator; linear interpolation's kinks do not (a kink's W^{3/2,2} energy grows like the
    log of the fine vertices per coarse edge, and faster above order 3/2)."""
    idx, sizes, rows, cols, vals = [], [], [], [], []
    offset = 0
    for c in range(layout.k):
        s0, s1 = int(layout.starts[c]), int(layout.starts[c + 1])
        local = np.arange(s1 - s0)
        if s1 - s0 < 16:
            k = s1 - s0
            rows.append(s0 + local)
            cols.append(offset + local)
            vals.append(np.ones(k))
        else:
            kept = local[::2]
            k = len(kept)
            j = np.arange(k)
            rows.append(s0 + kept)
            cols.append(offset + j)
            vals.append(np.ones(k))
            odd = local[1::2]
            jo = odd // 2
            for shift, w in ((-1, -1 / 16), (0, 9 / 16), (1, 9 / 16), (2, -1 / 16)):
                rows.append(s0 + odd)
                cols.append(offset + (jo + shift) % k)
                vals.append(np.full(len(odd), w))
        idx.append(s0 + local[::2] if s1 - s0 >= 16 else s0 + local)
        sizes.append(k)
        offset += k
    P = _Sparse(np.concatenate(rows), np.concatenate(cols), np.concatenate(vals),
                (layout.n, offset))
    return np.concatenate(idx), layout_from_sizes(sizes, layout.is_link), P


class Multilevel:
    """The coarse levels of the multilevel preconditioner: the curve halved again and again
    (every second vertex per component, :func:`_halve`) down to at most ``COARSEST`` vertices,
    a level at every ``STRIDE``-th halving and at the last, each with its own constraints and
    its own constraint preconditioner (the banded ``H`` of its own hs operator,
    :meth:`HsOperator.preconditioner_parts`), the coarsest solved densely. Applied to a
    residual ``R`` it returns ``Π_H P₁ (z₁ + P₂ (z₂ + …))`` with ``R₁ = P₁ᵀ Π_Hᵀ R``,
    ``R_l = P_lᵀ R_{l−1}`` and ``z_l`` the constrained solve of ``R_l`` at a level's halving
    (0 at the others): added to the fine constraint preconditioner, an additive multilevel
    (BPX) preconditioner. Each level's banded ``H`` matches the hs operator near its own grid's
    frequency and is too stiff below it (h1 grows as k², hs as k^{2s}); the sum over the levels
    covers every frequency, which one coarse level cannot do once N/COARSE_MAX grows.
    The interpolated sum leaves ``ker C``; it is brought back by ``Π_H = I − H⁻¹Cᵀ(CH⁻¹Cᵀ)⁻¹C``
    (the fine constraint preconditioner's projection) and the residual enters as ``Π_Hᵀ R``, so
    the correction stays symmetric positive semi-definite, into ``ker C``. The Euclidean
    projection of :class:`CoarseLevel` instead made coarse levels far below the fine one correct
    wrongly (5_2 at 8 000 vertices, one dense level of 63 vertices: 200 iterations, the cap,
    against 10 with ``Π_H``; docs/lab/tree-engine.md).
    Pins are not supported (the caller leaves it out). Levels stop at the first whose strands
    come too close (``MIN_CONTACT``); none (:attr:`levels` 0) when that is the first or the
    curve has at most ``COARSEST`` vertices.

    Parameters
    ----------
    X : (N, 3) array
    layout : Layout
    metric : {"hs", "hs_pure"}
    jac : Jacobian
        The fine constraint Jacobian.
    order : float
    fine : BandedSaddle, optional
        The fine constraint preconditioner (built from ``X`` if not given).
    """

    def __init__(self, X: np.ndarray, layout: Layout, metric: str, jac: Jacobian,
                 order: float = PAPER_ORDER, fine: BandedSaddle | None = None):
        self.jac = jac
        self.fine = (BandedSaddle(_parts(X, layout, metric, order), jac, product=False,
                                  barycenter_term=False, projected=True)
                     if fine is None else fine)
        halvings = []
        Xl, lay = X, layout
        while lay.n > COARSEST:
            idx, clay, P = _halve(lay)
            if clay.n == lay.n:
                break
            Xl, lay = Xl[idx], clay
            halvings.append((Xl, lay, P))
        # every STRIDE-th halving is a level, and the coarsest, while its strands stay apart
        depths = [d for d in range(len(halvings))
                  if (d + 1) % STRIDE == 0 or d == len(halvings) - 1]
        used = []
        for d in depths:
            Xl, lay, _ = halvings[d]
            ln = np.linalg.norm(Xl[lay.nxt] - Xl, axis=1)
            # a level whose strands cross is not the curve's shape (FHW at 100 000 vertices,
            # levels down to 390 vertices with this rule: 10 iterations per solve; with ratio
            # ≥ 2, down to 1 562 vertices and that level banded: 19)
            if closest_vertices(Xl, lay, CONTACT_GAP)[0] < MIN_CONTACT * ln.mean():
                break
            used.append((d, ln))
        depth = used[-1][0] + 1 if used else 0
        self.transfers: list[tuple[_Sparse, _Sparse]] = [
            (P.compressed(), P.T.compressed()) for *_, P in halvings[:depth]]
        #: per halving, its level's solve and constraint count, or None (no level there)
        self.solves: list = [None] * depth
        for i, (d, ln) in enumerate(used):
            Xl, lay, _ = halvings[d]
            jc = jacobian(Xl, make_constraints(Xl, lay, ln))
            if i == len(used) - 1 and lay.n <= DENSE_MAX:
                # double precision, as CoarseLevel's
                fac = Factorization(gram_x(metric, Xl, lay, order=order), jc, np.float64)
                self.solves[d] = (fac.solve, jc.con.size)
            else:
                self.solves[d] = (BandedSaddle(_parts(Xl, lay, metric, order), jc,
                                               product=False, barycenter_term=False,
                                               projected=True)._solve,
                                  jc.con.size)

    @property
    def levels(self) -> int:
        """Coarse levels (the fine one not counted)."""
        return sum(s is not None for s in self.solves)

    def __call__(self, R: np.ndarray) -> np.ndarray:
        """The correction for a residual ``R`` already free of its ``range Cᵀ`` part in the
        fine ``H``'s metric (``R − Cᵀμ`` with ``μ`` the multipliers of the fine constraint
        preconditioner's solve of ``R``, :meth:`HsSaddle._precondition`)."""
        rs = []
        r = R
        for _, Pt in self.transfers:
            r = Pt @ r
            rs.append(r)
        y = None
        for d in range(len(self.solves) - 1, -1, -1):
            if y is not None:
                y = self.transfers[d + 1][0] @ y
            if self.solves[d] is not None:
                solve, m = self.solves[d]
                z = solve(rs[d], np.zeros(m))[0]
                y = z if y is None else y + z
        v = self.transfers[0][0] @ y
        del rs, r, y  # (memory: the fine solve below is the preconditioner's peak)
        # back onto C v = 0 by the H-smallest change (one more band solve)
        v -= self.fine._solve(None, self.jac.matvec(v))[0]
        return v


def _parts(X, layout, metric, order):
    """The banded parts of the hs operator at ``X`` (:meth:`HsOperator.preconditioner_parts`),
    the same for single-precision weights, which take half the memory while built."""
    return HsOperator(X, layout, metric, order=order, single=True).preconditioner_edges()


class HsSaddle:
    """Saddle-point solves with ``Ã`` (:class:`HsOperator`) at one iterate, by projected
    preconditioned conjugate gradients (see the module's text).

    Parameters
    ----------
    op : HsOperator
    jac : Jacobian
        Constraint Jacobian at the same polygon (edge-length and barycenter rows; with pins
        the constraint preconditioner is bordered, :mod:`.pinned_solve`, and the coarse level
        is left out; with open components it is :class:`.banded.OpenBandedSaddle`, pins
        eliminated, and there is no coarse level either).
    rtol : float
        Relative tolerance of :meth:`solve`: the preconditioned residual norm
        ``sqrt(rᵀ K r)`` against that of the start.
    max_iter : int
        Iterations at most per solve.
    exact_backprojection : bool
        :meth:`pseudo_inverse` in ``Ã`` by the same Krylov method (tolerance ``rtol``)
        instead of in the preconditioner's metric ``H``.
    log : list, optional
        Where every solve appends its iteration count.
    recycle : HsSaddle, optional
        The previous iterate's solver, whose band memory this one takes over.
    X : (N, 3) array, optional
        The polygon (needed for the coarse levels).
    coarse : int, optional
        Vertices of a single coarse level (:class:`CoarseLevel`; 0: none). Default: the
        preconditioner ``PRECONDITIONER`` names, :class:`Multilevel` from ``MULTILEVEL_FROM``
        vertices on ("multilevel"), or :func:`coarse_size` vertices ("two_level").
    """

    def __init__(self, op: HsOperator, jac: Jacobian, rtol: float = RTOL, max_iter: int = 200,
                 exact_backprojection: bool = False, log: list | None = None,
                 recycle: HsSaddle | None = None, X: np.ndarray | None = None,
                 coarse: int | None = None):
        self.op = op
        self.jac = jac
        self._scratch = None  # (:meth:`_room`)
        self.rtol = rtol
        self.max_iter = max_iter
        self.exact_backprojection = exact_backprojection
        old = None if recycle is None else getattr(recycle.K, "base", recycle.K)
        if op.layout.has_open:  # dummy edges and pins eliminated in the band; no coarse level
            self.K = OpenBandedSaddle(op.preconditioner_parts(), jac, old)
            self.iterations = [] if log is None else log
            self.coarse = None
            return
        if jac.con.pinned is None:
            self.K = BandedSaddle(op.preconditioner_edges(), jac, old, product=False,
                                  barycenter_term=False, projected=True)
        else:  # the constraint preconditioner with pins: bordered (the iterates stay 0 there)
            self.K = BorderedPins(BandedSaddle(op.preconditioner_parts(),
                                               unpinned_jacobian(jac), old), jac)
        self.iterations: list[int] = [] if log is None else log
        self.coarse = None
        # the coarse levels project with the constraints' TangentProjector, which has no pins
        if X is None or jac.con.pinned is not None:
            return
        n = op.layout.n
        if coarse is None and PRECONDITIONER == "multilevel":
            if n >= MULTILEVEL_FROM:
                levels = Multilevel(X, op.layout, op.metric, jac, op.order, self.K)
                self.coarse = levels if levels.levels else None
            return
        size = coarse_size(n) if coarse is None else int(coarse)
        if size and size < n:
            self.coarse = CoarseLevel(X, op.layout, op.metric, jac, size, op.order)

    def release(self) -> None:
        """Let go of the operator, the coarse level and all of the constraint preconditioner
        but its band's memory (:meth:`BandedSaddle.release`) before the next iterate's solver
        is built. The solver is unusable afterwards."""
        self.K.release()
        self.__dict__ = {"K": self.K}

    def shed(self) -> bool:
        """Let go of the operator and the coarse levels, keeping the constraint
        preconditioner for :meth:`pseudo_inverse` (the back-projection's steps, all a line
        search asks of the solver once the direction is solved); :meth:`solve` and
        :meth:`metric_product` are unusable afterwards. Nothing is let go (False) with
        ``exact_backprojection``, whose back-projection solves with the operator."""
        if self.exact_backprojection:
            return False
        self.op = self.coarse = self._scratch = None
        return True

    @property
    def whole(self) -> bool:
        """Whether :meth:`shed` left the operator (:meth:`solve` can be called)."""
        return self.op is not None

    def _room(self) -> np.ndarray:
        """An (N, 3) array for the loop's temporary products with ``Cᵀ``, the same at every
        call (fresh, it came as new pages from the kernel every time at 10⁶ vertices)."""
        if self._scratch is None:
            self._scratch = np.empty((self.jac.con.layout.n, 3))
        return self._scratch

    def _precondition(self, R: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(z, μ)``: the constraint preconditioner's ``H z + Cᵀμ = R``, ``C z = 0``, plus the
        coarse level's correction; ``R`` becomes ``R − Cᵀμ`` (the solve's residual update,
        which is also the input of :class:`Multilevel`: one product with ``Cᵀ``, not two)."""
        z, mu = self.K._solve(R, np.zeros(self.jac.con.size))
        coarse = self.coarse(R) if isinstance(self.coarse, CoarseLevel) else None
        R -= self.jac.rmatvec(mu, out=self._room())
        if isinstance(self.coarse, Multilevel):
            z += self.coarse(R)
        elif coarse is not None:
            z += coarse
        return z, mu

    def solve(self, g: np.ndarray, r: np.ndarray, rtol: float | None = None
              ) -> tuple[np.ndarray, np.ndarray]:
        """``(u, λ)`` of ``[[Ã ⊗ I₃, Cᵀ], [C, 0]] [u; λ] = [g; r]``: ``C u = r`` to rounding,
        the first rows to the relative tolerance (λ from the last preconditioner solve)."""
        rtol = self.rtol if rtol is None else rtol
        n = g.shape[0]
        if np.any(r):
            x = self.K._solve(None, r)[0]
            res = self.op.product(x) - g
        else:  # x = 0: no product (one of ten at 10⁶ vertices, 0.14 s)
            x = np.zeros((n, 3))
            res = -np.asarray(g, dtype=np.float64)
        # the residual keeps only what the constraints cannot absorb, its Cᵀμ part moved into
        # the multipliers λ (Gould, Hribar & Nocedal's residual update, in _precondition; the
        # same iterates in exact arithmetic, res = Ã x − g + Cᵀλ throughout): without it, a
        # residual dominated by Cᵀλ swamped the projected part's rounding and the iterates left
        # C u = r (2% of |u| after 125 iterations at rtol 1e-10 on a trefoil)
        z, mu = self._precondition(res)
        lam = -mu
        rz = float(np.einsum("ij,ij->", res, z))
        if not rz > 0.0 and self.coarse is not None and np.any(res):
            # the coarse level made the preconditioner indefinite here: go on without it
            self.coarse = None
            z, mu = self._precondition(res)
            lam -= mu
            rz = float(np.einsum("ij,ij->", res, z))
        if not rz >= 0.0:  # NaN, or an indefinite constraint preconditioner
            raise np.linalg.LinAlgError("the hs preconditioner is not positive definite here")
        stop = rtol * rtol * rz
        p = -z
        its = 0
        work, work_ap = np.empty_like(p), np.empty_like(p)
        while rz > stop and its < self.max_iter:
            Ap = self.op.product(p, out=work_ap)
            pAp = float(np.einsum("ij,ij->", p, Ap))
            if not pAp > 0.0:
                break
            a = rz / pAp
            x += np.multiply(a, p, out=work)
            res += np.multiply(a, Ap, out=work)
            Ap = z = None  # (memory: the preconditioner's solves are the solve's peak)
            z, mu = self._precondition(res)
            lam -= mu
            rz_new = float(np.einsum("ij,ij->", res, z))
            if not rz_new > 0.0:  # converged to rounding, or the preconditioner broke down
                break
            p *= rz_new / rz
            p -= z
            rz = rz_new
            its += 1
        self.iterations.append(its)
        return x, lam

    def metric_product(self, V: np.ndarray) -> np.ndarray:
        """``Ã V`` for a field (N, 3)."""
        return self.op.product(V)

    def pseudo_inverse(self, phi: np.ndarray) -> np.ndarray:
        """``Ã⁻¹Cᵀ(CÃ⁻¹Cᵀ)⁻¹ φ`` (with ``exact_backprojection``), else the same in ``H``: a
        step of the back-projection onto ``C d = φ`` either way."""
        if self.exact_backprojection:
            return self.solve(np.zeros((self.op.layout.n, 3)), phi)[0]
        return self.K._solve(None, phi)[0]
