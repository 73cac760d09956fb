"""The one door through which every optimizer (:mod:`.solvers`) reaches the numerics.

An engine is built per run from the polygon's layout and the metric. It evaluates the Möbius
energy and its gradient, the first contact along a motion, and holds the metric at the current
iterate with the saddle-point solver of docs/design.md, step 2 (``[[G, Cᵀ], [C, 0]]``,
``G = A ⊗ I₃``) or, for the penalty methods, the solver of the penalized metric. The
optimizers never call the kernels (:mod:`.moebius_dense`, :mod:`.collision`, :mod:`.metrics`,
:mod:`.linalg`, :mod:`.banded`) themselves, so a second engine that evaluates some of these
differently (e.g. a tree approximation of the far field) is one subclass here and one entry
in :data:`ENGINES`.

Engines by name (the ``engine=`` option of ``relax``, ``make_run`` and every run class):

* ``"exact"``: :class:`DenseEngine`, every pair of edges summed exactly, dense metric.
* ``"tree"``: :class:`TreeEngine`, the energy and its gradient by Barnes–Hut
  (:mod:`.barnes_hut`, admissibility ``theta``); contacts exact (the hierarchy of
  :mod:`.bvh` serves the contact search of every engine above its crossover); no dense
  matrix: direct O(N) saddle-point solves for the banded metrics (``l2``, ``h1``, ``h2``:
  :mod:`.banded`), preconditioned Krylov solves for ``hs`` and ``hs_pure`` (:mod:`.hs_tree`,
  :mod:`.hs_solve`).
* ``"auto"``: the tree from ``AUTO_TREE_FROM`` vertices on, else exact (the tangent-point
  energy of open curves: always exact).

This module is the one place for engines by name: their names (:data:`ENGINE_NAMES`), what
"auto" picks (:func:`uses_tree`, both of its thresholds), the classes (:data:`ENGINES`,
:func:`make_engine`) and the public evaluators of the energy (:func:`moebius_energy`,
:func:`moebius_gradient`), which pick the exact sum (:mod:`.moebius_dense`) or the tree
(:mod:`.barnes_hut`) by the same names.
"""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np

from ..energies import DEFAULT_ENERGY
from ..energies import choice as energy_choice
from ..energies.choice import MOEBIUS, EnergyChoice, check_energy
from ..geometry.collision import CONTACT_TREE_FROM, contact_time_x
from ..geometry.constraints import Jacobian
from ..geometry.layout import Layout, as_checked_layout
from ..metrics import hs_solve
from ..metrics.banded import BANDED_METRICS, BandedSaddle, OpenBandedSaddle
from ..metrics.gram import banded_parts, gram_x
from ..metrics.pinned_solve import BorderedPins, tree_borders, unpinned_jacobian
from ..metrics.saddle import SaddlePointSolver, spd_inverse
from ..tree import bvh as contact_bvh
from ..tree import hs_metric as hs_tree
from ..tree import moebius as barnes_hut
from .checks import check_flag
from .memory import available_memory, check_memory, give_back

# Deterministic refactorization rule (see SaddlePointSolver): one factorization costs about as
# much as N / _FACTOR_PER_ITER preconditioned Krylov iterations (measured here at N = 3000:
# ~1.1 s against ~15 ms per iteration).
_FACTOR_PER_ITER = 40.0
# From this many vertices on, a single-precision factorization refined by GMRES pays (FHW flow,
# ms per iteration single/double: 500: 28/21–23, 600: 27–34/32–34, 700: 42/49).
_AUTO_SINGLE_FROM = 600


class PenaltyMetric:
    """Solver of ``(A ⊗ I₃ + α Cᵀ diag(l0) C) z = g`` (C: edge rows of DΦ) by Woodbury:

        z = G⁻¹g − G⁻¹Cᵀ (C G⁻¹ Cᵀ + diag(1/(α l0)))⁻¹ C G⁻¹ g

    with ``C G⁻¹ Cᵀ = (D A⁻¹ Dᵀ) ∘ (T Tᵀ)`` as in :mod:`linalg` (O(N²) once A⁻¹ is known).
    ``penalty`` False (or ``alpha`` 0) leaves the penalty term out: ``z = G⁻¹ g``."""

    def __init__(self, A: np.ndarray, jac: Jacobian, alpha: float, lengths0: np.ndarray,
                 penalty: bool):
        self.jac = jac
        self.Ainv = spd_inverse(A)
        self.Kinv = None
        if penalty and alpha > 0:
            lay = jac.con.layout
            T, inv_l = jac.edge_fields()
            Y = (self.Ainv[lay.nxt] - self.Ainv) * inv_l[:, None]
            Y = (Y[:, lay.nxt] - Y) * inv_l[None, :]
            S = Y * (T @ T.T)
            S[np.diag_indices_from(S)] += 1.0 / (alpha * lengths0)
            self.Kinv = spd_inverse(S)

    def solve(self, g: np.ndarray) -> np.ndarray:
        """``z`` for the (N, 3) field ``g``."""
        z = self.Ainv @ g
        if self.Kinv is not None:
            z = z - self.Ainv @ self.jac.rmatvec(self.Kinv @ self.jac.matvec(z))
        return z


class DenseEngine:
    """Exact energy, gradient and contact times over all edge pairs; dense metric ``A`` with
    a factorized saddle-point solver (docs/design.md, steps 1–4).

    Parameters
    ----------
    layout : Layout
        Components of the stacked vertex array every method below takes (``X``: (N, 3), at the
        run's scale, total length 1).
    metric : {"hs", "hs_pure", "h2", "h1", "l2"}
        Metric of :meth:`update`, :meth:`metric_product` and :meth:`penalty_solver`; ``hs``
        and ``hs_pure`` of the order that fits the energy (``energy.metric_order``).
    precision : {"auto", "double", "single"}
        Precision of the saddle-point factorization ("auto": single from 600 vertices on,
        refined by GMRES to double-precision results).
    reuse_factorization : bool
        Reuse the factorization as a GMRES preconditioner across iterates while that pays.
    theta, krylov_rtol, exact_backprojection
        The tree engine's options (:class:`TreeEngine`); the exact engine checks and ignores
        them, so that one option set fits every engine.
    """

    name = "exact"
    #: Whether a trial's energy is worth testing before its back-projection finishes
    #: (solvers.projected._EARLY): here an energy costs less than the Newton steps it saves.
    early_energy_test = True

    def __init__(self, layout: Layout, metric: str, *, precision: str = "auto",
                 reuse_factorization: bool = False, theta: float | None = None,
                 krylov_rtol: float | None = None, exact_backprojection: bool = False,
                 energy: EnergyChoice = MOEBIUS):
        if precision not in ("auto", "double", "single"):
            raise ValueError("precision must be 'auto', 'double' or 'single'")
        if precision == "auto":
            precision = "single" if layout.n >= _AUTO_SINGLE_FROM else "double"
        self.layout = layout
        self.metric = metric
        #: The energy the run minimizes (:mod:`.energy_choice`).
        self.energy_choice = energy
        self.theta = energy.default_theta if theta is None else barnes_hut.check_theta(theta)
        self.krylov_rtol = hs_solve.RTOL if krylov_rtol is None else hs_solve.check_rtol(
            krylov_rtol)
        self.exact_backprojection = check_flag("exact_backprojection", exact_backprojection)
        self.solver = SaddlePointSolver(
            reuse=check_flag("reuse_factorization", reuse_factorization),
            factor_cost=layout.n / _FACTOR_PER_ITER,
            dtype=np.float32 if precision == "single" else np.float64,
        )
        self._gram = None  # the Gram matrix's memory, refilled at every update
        #: Meshes the curve is repelled from and never crosses (``obstacles.ObstacleField``):
        #: their energy is added to the curve's, their contacts bound every step.
        self.obstacles = None
        #: Tube radius at the run's scale (:mod:`.thickness`): strands are kept twice this
        #: apart, obstacles this far; 0: the contact distance alone (``set_thickness``).
        self.radius = 0.0
        #: Per component, pairs of edges this many apart along it or nearer are not tested
        #: for contact (None: 1, the edges that share a vertex).
        self.near = None
        self._penalty_factorizations = 0
        self._banded_factorizations = 0

    @classmethod
    def check_size(cls, n: int) -> None:
        """ValueError for a size whose run would not fit in memory (the exact engine's dense
        sizes are bounded by ``solvers.base.check_dense_size``)."""

    @classmethod
    def holds_dense(cls, metric: str) -> bool:
        """Whether this engine holds ``metric`` as a dense N × N matrix (run sizes are then
        bounded by ``solvers.base.check_dense_size``)."""
        return True

    @property
    def dense_metric(self) -> bool:
        """:meth:`holds_dense` for this engine's metric."""
        return self.holds_dense(self.metric)

    def solves_pins(self, n_pinned: int) -> bool:
        """Whether the saddle-point solves with ``n_pinned`` pinned vertices need no dense
        matrix (the exact engine's always do)."""
        return False

    # -- energy, gradient, contact -------------------------------------------------------------

    def energy(self, X: np.ndarray) -> float:
        """The run's energy of ``X`` (N, 3) (plus the obstacles' weighted energy, if any)."""
        return self._plus_obstacles(self.energy_choice.exact(X, self.layout), X)

    def trial_energy(self, X: np.ndarray, gradient: bool = True) -> float:
        """The energy of a line search's trial ``X``, to be compared with the iterate's (the
        last :meth:`energy_gradient`): here :meth:`energy`. The tree engine may evaluate it
        with the iterate's split, and with its gradient unless ``gradient`` is False (a trial
        whose back-projection is not finished; :meth:`TreeEngine.trial_energy`)."""
        return self.energy(X)

    def energy_gradient(self, X: np.ndarray) -> tuple[float, np.ndarray]:
        """``(E, ∇E)`` at ``X``; ``∇E`` is (N, 3). Its ``E`` may differ from :meth:`energy`
        in the last bits (the two kernels sum in different orders)."""
        return self._plus_obstacle_gradient(*self.energy_choice.exact_gradient(X, self.layout),
                                            X)

    def result_energy(self, X: np.ndarray, E: float) -> float:
        """The energy a run reports for its result ``X`` (``RelaxResult.fun``), whose value in
        the run was ``E``: here ``E`` itself, exact already."""
        return E

    def _plus_obstacles(self, E: float, X: np.ndarray) -> float:
        return E if self.obstacles is None else E + self.obstacles.energy(X, self.layout.nxt)

    def _plus_obstacle_gradient(self, E: float, g: np.ndarray, X: np.ndarray
                                ) -> tuple[float, np.ndarray]:
        if self.obstacles is None:
            return E, g
        Eo, go = self.obstacles.energy_gradient(X, self.layout.nxt, self.layout.prv)
        return E + Eo, g + go

    def set_thickness(self, radius: float, near: np.ndarray) -> None:
        """Keep tubes of ``radius`` (the run's scale) apart: strands ``2 × radius`` (pairs of
        one strand more than ``near`` edges apart along it, per component), obstacles
        ``radius`` (:mod:`.thickness`)."""
        self.radius = float(radius)
        self.near = near

    def contact_time(self, X: np.ndarray, U: np.ndarray, tau_max: float, eps: float) -> float:
        """Smallest ``τ ≤ tau_max`` at which ``X − τU`` comes within ``eps`` of touching
        itself (edges not adjacent) or an obstacle, or ``tau_max`` when it does not. With a
        thickness (:meth:`set_thickness`), within ``max(eps, 2 × radius)`` of itself (pairs
        nearer than ``near`` along a strand left out) or ``max(eps, radius)`` of an obstacle."""
        t = contact_time_x(X, U, self.layout, tau_max, max(eps, 2.0 * self.radius),
                           near=self.near, tree=self._contact_tree(X))
        if self.obstacles is not None and t > 0.0:
            t = self.obstacles.contact_time(X, U, self.layout.nxt, t, max(eps, self.radius))
        return t

    def _contact_tree(self, X: np.ndarray):
        """The edge hierarchy of ``X`` for its contact searches, kept for the next search
        from the same polygon (a step's bound and its trials' paths all start at the
        iterate: at 10⁶ edges a build took 0.12-0.14 s, the copy and comparison 5 ms); None
        below the size that searches by the hierarchy."""
        if self.layout.n < CONTACT_TREE_FROM:
            return None
        kept = self._kept_contact_tree
        if kept is not None and np.array_equal(kept[0], X):
            return kept[1]
        tree = contact_bvh.build(X, self.layout)
        self._kept_contact_tree = (np.array(X, dtype=np.float64), tree)
        return tree

    #: ``(polygon, hierarchy)`` of the last contact search (:meth:`_contact_tree`).
    _kept_contact_tree = None

    def path_is_free(self, X: np.ndarray, Q: np.ndarray, eps: float) -> bool:
        """Whether the straight path from ``X`` to a trial ``Q`` keeps ``eps`` from contact
        (:meth:`contact_time` up to the whole step)."""
        return self.contact_time(X, X - Q, 1.0, eps) >= 1.0

    # -- metric and saddle-point solves at the current iterate ---------------------------------

    def update(self, X: np.ndarray, jac: Jacobian) -> None:
        """Move to the iterate ``X`` with constraint Jacobian ``jac``: assemble the metric
        there and update (refactor or keep, see ``SaddlePointSolver``) the solver."""
        self._kept_contact_tree = None  # the last iterate's (its memory, for the new solver)
        # the previous iterate's Gram matrix is no longer needed: its memory takes the new one
        self._gram = gram_x(self.metric, X, self.layout, out=self._gram,
                            order=self.energy_choice.metric_order)
        self.solver.update(self._gram, jac)

    def solve(self, g: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(u, λ)`` of ``[[G, Cᵀ], [C, 0]] [u; λ] = [g; r]`` at the current iterate."""
        return self.solver.solve(g, r)

    def pseudo_inverse(self, phi: np.ndarray) -> np.ndarray:
        """``G⁻¹Cᵀ(CG⁻¹Cᵀ)⁻¹ φ`` with the stored factorization (modified Newton, step 4)."""
        return self.solver.pseudo_inverse(phi)

    def newton_steps(self, n: int) -> int:
        """The back-projection's budget of modified Newton steps for a run's
        ``backproject_iter`` ``n``: ``n``, its steps being the metric's own."""
        return n

    def metric_product(self, V: np.ndarray) -> np.ndarray:
        """``A V`` for an (N, 3) field ``V``: the metric ``G`` applied to it."""
        return self.solver.A @ V

    def refactor(self) -> None:
        """Factor the current iterate's system afresh (a stale one may be what failed)."""
        self.solver.refactor()

    #: Whether the engine holds less at once (the tree's :func:`lean_run`); never for the
    #: dense engine.
    lean = False

    def shed(self) -> None:
        """The direction at the current iterate is solved: until the next :meth:`update`
        the run asks only :meth:`pseudo_inverse` (and the energies and contact tests), so an
        engine may let go of what the solves needed. A later :meth:`solve` or
        :meth:`metric_product` still works (it may cost a rebuild). Nothing here."""

    @property
    def fresh(self) -> bool:
        """Whether the factorization belongs to the current iterate."""
        return self.solver.fresh

    # -- the penalty methods' metric -----------------------------------------------------------

    def penalty_solver(self, X: np.ndarray, jac: Jacobian, alpha: float, lengths0: np.ndarray,
                       penalty_in_metric: bool) -> PenaltyMetric:
        """Solver of the penalized metric ``G + α DΦᵀ diag(l0) DΦ`` at ``X`` (``jac``: DΦ at
        X; without the penalty term unless ``penalty_in_metric``); ``.solve(g)``."""
        self._penalty_factorizations += 1
        return PenaltyMetric(gram_x(self.metric, X, self.layout,
                                    order=self.energy_choice.metric_order),
                             jac, alpha, lengths0, penalty_in_metric)

    # -- statistics ----------------------------------------------------------------------------

    @property
    def factorizations(self) -> int:
        """Metric factorizations so far (saddle-point and penalty solvers)."""
        return self.solver.n_factor + self._penalty_factorizations

    @property
    def krylov_iterations(self) -> list[int]:
        """GMRES iterations of every saddle-point solve so far (0: direct solve)."""
        return list(self.solver.krylov_its)


#: Up to this many vertices a run on the tree reports its result's exact energy
#: (:meth:`TreeEngine.result_energy`): the all-pairs sum took 0.02 s at 1 648 edges and 1.8 s
#: at 20 000 (one thread, load 6; docs/lab/cables-and-obstacles.md), under 3 % of such a run.
EXACT_RESULT_MAX = 20000


#: How far (in mean edge lengths, largest vertex displacement) a trial of the line search may
#: be from the polygon of the last frame and still be evaluated with its split
#: (:meth:`TreeEngine.trial_energy`): one leaf's length. A split kept for moved clusters is less
#: admissible; at the trials the cable runs took (0.8–4.4 edge lengths,
#: docs/lab/cables-and-obstacles.md,
#: "Open cables on the tree engine") the kept split's energy was as close to the exact one as a
#: fresh split's (1.1–1.5e-6 both), and differed from it by 2e-8 to 2.6e-7.
FRAME_REUSE = 8.0
#: How far (as :data:`FRAME_REUSE`) a polygon may be from the last frame's and still have its
#: energy and gradient evaluated with that split: a trial of the line search then comes with
#: its gradient, and an accepted trial is the next iterate without a second pass or a new
#: frame. Against the exact sum (FHW 5 000 edges, 100 open cables of 200;
#: docs/lab/cables-and-obstacles.md),
#: the kept split's gradient erred within 25 % of a fresh split's after smooth moves of up to
#: 16 edge lengths (5e-4 and 1e-4), and after random ones (every vertex its own way) of 4 about
#: twice as much (3e-7 to 5e-7 against 2e-7); at 8 about 4 times as much.
GRADIENT_REUSE = 4.0
#: Below this many vertices the tree engine tests a trial's energy before its back-projection
#: finishes (as the exact engine); from here on it finishes every trial first. Seconds per
#: iteration with the test on / off, alternated (two rounds, FHW, two threads, load 0.8–2):
#: 1 648 edges 0.039, 0.053 / 0.047, 0.061; the (2, 5) torus knot at 5 000 edges 0.143, 0.192
#: / 0.160, 0.185; FHW 10 000 0.295, 0.328 / 0.231, 0.269; 100 cables of 200 (off) 1.7×
#: faster than before (docs/lab/cables-and-obstacles.md).
EARLY_TEST_BELOW = 5000
#: From this many vertices on a run on the tree is *lean* (:func:`lean_run`): it keeps only
#: what each phase of an iteration needs (:meth:`TreeEngine.shed`, :meth:`TreeEngine.update`):
#: the hs operator and the coarse levels go once the direction is solved, the last frame while
#: the next iterate's solver is built and used (built again, the same, if a trial asks for
#: its split). The iterates are the same. FHW at 10⁶ vertices, 2 threads: peak 3.81 → 3.21 GB
#: at the same seconds per iteration (18.4 and 18.6 s); docs/lab/tree-engine.md, "Memory at
#: 10⁶ edges: where it goes, and what was tried".
LEAN_FROM = 200_000
#: Peak resident memory per vertex of a run on the tree that is not lean (FHW at 10⁶
#: vertices, 2 threads: 4.54–4.59 GB for the whole process, before single-precision weights).
FULL_BYTES_PER_VERTEX = 4_600
#: A lean run also returns the heap's free pages between its phases (``malloc_trim``,
#: :func:`trim_run`) when a full run's peak would take more than this share of the memory the
#: system has available when the engine is made: the pages come back as small pages, 1.2×
#: the seconds (FHW at 10⁶: 38.2 against 31.1–31.5 s for setup and one iteration), and the
#: peak did not fall (3.19 against 3.21 GB).
LEAN_SHARE = 0.5
#: From this many vertices on the hs operator stores its near weights in single precision
#: (``HsOperator(single=True)``): 0.42 GB less at 10⁶ vertices and faster products; the
#: iterates change at rounding level (docs/lab/tree-engine.md, "Memory at 10⁶ edges: where it goes,
#: and what was tried").
SINGLE_WEIGHTS_FROM = 200_000
#: The tree's budget of back-projection steps for hs, times the run's ``backproject_iter``
#: (rounded up): its steps are in the preconditioner's banded metric, which contracts more
#: slowly than hs's own, so the same budget rejected trials that hs accepts
#: (docs/lab/repulsor.md, "The tree's back-projection gets a fifth more steps").
BANDED_NEWTON = Fraction(6, 5)


def lean_run(n: int) -> bool:
    """Whether a tree run of ``n`` vertices is lean (:data:`LEAN_FROM`)."""
    return n >= LEAN_FROM


def trim_run(n: int) -> bool:
    """Whether a lean run of ``n`` vertices returns the heap's free pages between its phases
    (:data:`LEAN_SHARE`): when a full run's peak (:data:`FULL_BYTES_PER_VERTEX`) would exceed
    :data:`LEAN_SHARE` of the memory available now, or where the system does not say."""
    if n < LEAN_FROM:
        return False
    available = available_memory()
    return available is None or FULL_BYTES_PER_VERTEX * float(n) > LEAN_SHARE * available


def _moved2(X0: np.ndarray, X: np.ndarray) -> float:
    """The largest squared displacement of a vertex from ``X0`` to ``X``."""
    return float(np.max(np.sum((X - X0) ** 2, axis=1))) if X.shape == X0.shape else np.inf


def tree_solves_pins(n_pinned: int, open_curves: bool) -> bool:
    """Whether the tree engine's solvers take ``n_pinned`` pinned vertices without a dense
    matrix: any number on a layout with open components (its band solver eliminates them,
    :class:`banded.OpenBandedSaddle`, for the banded metrics and as hs's preconditioner),
    else up to ``pinned_solve.TREE_MAX_PINS`` (bordered)."""
    return open_curves or tree_borders(n_pinned)


class TreeEngine(DenseEngine):
    """:class:`DenseEngine` with the energy and its gradient by Barnes–Hut: a hierarchy and a
    far/near split built at every polygon whose gradient is evaluated, so that an iterate's
    energy is one function of the polygon and the gradient its exact derivative; a line
    search's trials nearby keep the iterate's split (:meth:`trial_energy`), so that it
    compares values of one approximated sum. ``theta``: admissibility in (0, 2), default
    ``barnes_hut.THETA``.

    Nothing dense either in the metric (except the penalty methods' :meth:`penalty_solver`,
    dense as in the exact engine): the banded metrics (``l2``, ``h1``, ``h2``) are solved
    directly in O(N) (:class:`banded.BandedSaddle`, factored afresh at every iterate); ``hs``
    and ``hs_pure`` are applied through a hierarchy of arcs (:mod:`.hs_tree`) and solved by
    preconditioned conjugate gradients (:mod:`.hs_solve`; ``krylov_rtol`` their tolerance),
    the back-projection's steps in the preconditioner's banded metric unless
    ``exact_backprojection``. With up to ``pinned_solve.TREE_MAX_PINS`` pinned vertices
    these solvers are bordered by the pin rows (:mod:`.pinned_solve`; hs then without its
    coarse level); with more pins, or without one kind of constraint, the saddle-point
    systems are solved as in the exact engine (dense; sizes are bounded).

    Layouts with open components: the Möbius energy as above (O'Hara's regularized
    kernel, :mod:`._arc_field`); every metric, the banded ones solved by
    :class:`banded.OpenBandedSaddle` with any number of pins eliminated in the band, ``hs``
    and ``hs_pure`` by conjugate gradients preconditioned with it (no coarse level)."""

    name = "tree"
    _frame = None  # the last frame, the polygon it was built at and its mean edge length
    _trial = None  # the last trial evaluated with its gradient: (X, E, ∇E)
    _saddle = None  # the solver of the current iterate (BandedSaddle or HsSaddle)
    #: Peak memory of a run per vertex: measured 5.3–7.4 kB over its first steps (7_2 at
    #: 20 000, 50 000 and 100 000 vertices, hs and h2, explicit and implicit; docs/api.md),
    #: 4.6 kB (3.9 lean) for the whole process at 10⁶ (docs/lab/cables-and-obstacles.md).
    BYTES_PER_VERTEX = 8_000

    @classmethod
    def check_size(cls, n: int) -> None:
        check_memory(cls.BYTES_PER_VERTEX * float(n), f"a tree-engine run of {n} vertices",
                     "resample to fewer vertices (core.resample(P, n)); 100 000 take about "
                     "1 GB, and a few hundred untangle most knots")

    def __init__(self, layout: Layout, metric: str, **options):
        self.check_size(layout.n)  # before anything is built
        super().__init__(layout, metric, **options)
        self._tree_krylov: list[int] = []  # per solve: Krylov iterations (0: direct)
        self.lean = lean_run(layout.n)
        #: a lean run short of memory also returns the heap's free pages (:func:`trim_run`)
        self.trim = trim_run(layout.n)

    @classmethod
    def holds_dense(cls, metric: str) -> bool:
        return metric not in BANDED_METRICS + hs_tree.METRICS

    @property
    def early_energy_test(self) -> bool:
        """Below :data:`EARLY_TEST_BELOW` vertices; above, the energy (0.56 s for 20 000
        edges of cables) costs more than the Newton steps it saves (15 ms each there), and a
        finished trial's energy comes with its gradient (:data:`GRADIENT_REUSE`), which an
        accepted trial keeps."""
        return self.layout.n < EARLY_TEST_BELOW

    def solves_pins(self, n_pinned: int) -> bool:
        return tree_solves_pins(n_pinned, self.layout.has_open)

    def update(self, X: np.ndarray, jac: Jacobian) -> None:
        self._kept_contact_tree = None  # the last iterate's (its memory, for the new solver)
        con = jac.con
        pins = 0 if con.pinned is None else con.pinned.size
        if self.layout.has_open and self.metric in BANDED_METRICS and (
                con.edge_lengths and con.barycenter):
            # open components: dummy edges and any number of pins eliminated in the band
            old, self._saddle = self._saddle, None
            if old is not None:
                old.release()
            self._saddle = OpenBandedSaddle(banded_parts(self.metric, X, self.layout), jac,
                                            getattr(old, "base", old))
            self._banded_factorizations += 1
            return
        if self.dense_metric or not (con.edge_lengths and con.barycenter) or (
                pins and not self.solves_pins(pins)):
            # the tree's solvers need both kinds of rows, and few pins: else solve densely
            super().update(X, jac)
            return
        self._at = (X, jac)
        if self.lean and self._frame is not None:
            # the frame waits as its polygon while the solver is built and used (_frame_at)
            self._frame = (self._frame[0], None, self._frame[2])
            self._trial = None  # the accepted trial's gradient has been taken
        old, self._saddle = self._saddle, None  # its memory is reused: no longer usable
        if old is not None:
            old.release()  # all but the band, before the new one is built
        if self.trim:
            give_back()
        if self.metric in BANDED_METRICS:
            old = getattr(old, "base", old)
            band = BandedSaddle(banded_parts(self.metric, X, self.layout),
                                unpinned_jacobian(jac) if pins else jac,
                                old if isinstance(old, BandedSaddle) else None)
            self._saddle = BorderedPins(band, jac) if pins else band
        else:
            self._saddle = hs_solve.HsSaddle(
                hs_tree.HsOperator(X, self.layout, self.metric,
                                   order=self.energy_choice.metric_order,
                                   single=True if self.layout.n >= SINGLE_WEIGHTS_FROM
                                   else None),
                jac, rtol=self.krylov_rtol,
                exact_backprojection=self.exact_backprojection, log=self._tree_krylov,
                recycle=old if isinstance(old, hs_solve.HsSaddle) else None, X=X)
        self._banded_factorizations += 1

    def shed(self) -> None:
        if self.lean and isinstance(self._saddle, hs_solve.HsSaddle) and self._saddle.shed():
            if self.trim:
                give_back()

    def _whole(self) -> None:
        """The solver able to solve again after :meth:`shed` (built afresh at the iterate)."""
        if isinstance(self._saddle, hs_solve.HsSaddle) and not self._saddle.whole:
            self.update(*self._at)

    def solve(self, g: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        if self._saddle is None:
            return super().solve(g, r)
        self._whole()
        if isinstance(self._saddle, (BandedSaddle, BorderedPins)):
            self._tree_krylov.append(0)
        return self._saddle.solve(g, r)

    def pseudo_inverse(self, phi: np.ndarray) -> np.ndarray:
        if self._saddle is None:
            return super().pseudo_inverse(phi)
        return self._saddle.pseudo_inverse(phi)

    def newton_steps(self, n: int) -> int:
        """``n``, or a fifth more (:data:`BANDED_NEWTON`) where hs's back-projection steps
        in the preconditioner's banded metric, which contracts more slowly than hs's own."""
        if isinstance(self._saddle, hs_solve.HsSaddle) and not self.exact_backprojection:
            return math.ceil(BANDED_NEWTON * n)
        return n

    def metric_product(self, V: np.ndarray) -> np.ndarray:
        if self._saddle is None:
            return super().metric_product(V)
        self._whole()
        return self._saddle.metric_product(V)

    def refactor(self) -> None:
        if self._saddle is None:
            super().refactor()  # the tree's solvers are built afresh at every iterate

    @property
    def fresh(self) -> bool:
        return True if self._saddle is not None else self.solver.fresh

    @property
    def factorizations(self) -> int:
        return super().factorizations + self._banded_factorizations

    @property
    def krylov_iterations(self) -> list[int]:
        return super().krylov_iterations + self._tree_krylov

    def _frame_at(self, X: np.ndarray, reach: float = 0.0) -> barnes_hut.Frame:
        """The frame of the last evaluation when ``X`` is its polygon or no vertex of ``X``
        is more than ``reach`` mean edge lengths from it, else a fresh one built at ``X``."""
        if self._frame is not None:
            X0, frame, h = self._frame
            if np.array_equal(X0, X) or (reach > 0.0 and _moved2(X0, X) <= (reach * h) ** 2):
                if frame is None:  # let go by update(): the same frame again
                    frame = self.energy_choice.frame(X0, self.layout, self.theta)
                    self._frame = (X0, frame, h)
                return frame
        lay = self.layout
        ln2 = np.sum((X[lay.nxt] - X) ** 2, axis=1)
        h = float(np.mean(np.sqrt(ln2[lay.real] if lay.has_open else ln2)))
        self._frame = None  # the old one goes before the new one is built
        self._frame = (X.copy(), self.energy_choice.frame(X, lay, self.theta), h)
        self._trial = None  # evaluated with the frame it replaces
        return self._frame[1]

    def energy(self, X: np.ndarray) -> float:
        return self._plus_obstacles(self._frame_at(X).energy(X), X)

    def trial_energy(self, X: np.ndarray, gradient: bool = True) -> float:
        """The energy of a trial with the split of the last evaluated polygon (normally the
        iterate's, whose gradient made the trial) while no vertex is more than
        :data:`FRAME_REUSE` mean edge lengths from where it was built, else with a fresh one:
        the line search compares values of one function. Within :data:`GRADIENT_REUSE` the
        trial's gradient comes with it (one pass), kept for :meth:`energy_gradient` should
        the trial be accepted; beyond, an accepted trial's energy and gradient come from a
        frame built there."""
        frame = self._frame_at(X, FRAME_REUSE)
        if not gradient or _moved2(self._frame[0], X) > (GRADIENT_REUSE * self._frame[2]) ** 2:
            return self._plus_obstacles(frame.energy(X), X)
        E, G = self._plus_obstacle_gradient(*frame.energy_gradient(X), X)
        self._trial = (X.copy(), E, G)
        return E

    def result_energy(self, X: np.ndarray, E: float) -> float:
        """The exact energy of the result up to :data:`EXACT_RESULT_MAX` vertices (``E``, the
        tree's, above): the far field errs by a few 1e-5 (low on round curves), and a run that
        ends at the circle reported 3.99991 where no closed curve goes below 4."""
        if self.layout.n > EXACT_RESULT_MAX:
            return E
        return self._plus_obstacles(self.energy_choice.exact(X, self.layout), X)

    def energy_gradient(self, X: np.ndarray) -> tuple[float, np.ndarray]:
        """``(E, ∇E)`` at ``X`` with the split of the last frame while no vertex is more than
        :data:`GRADIENT_REUSE` mean edge lengths from where it was built (the trial's own
        pass when ``X`` is the last trial), else with a fresh one."""
        if self._trial is not None and np.array_equal(self._trial[0], X):
            return self._trial[1], self._trial[2].copy()
        return self._plus_obstacle_gradient(
            *self._frame_at(X, GRADIENT_REUSE).energy_gradient(X), X)


# ------------------------------------------------------------------------------------------------
# engines by name, and what "auto" picks

#: The names of the ``engine=`` option (of the runs and of the evaluators), "auto" first.
ENGINE_NAMES = ("auto", "exact", "tree")

# "auto" takes the tree from a size on, and the size depends on what is evaluated: a run pays
# for the whole iteration, where the tree's metric (no dense matrix) wins early; the energy
# alone (moebius_energy, moebius_gradient) pays for the energy, where the frame's build costs
# more than the exact sum up to a few thousand edges. Measurements: docs/lab/cables-and-obstacles.md
# ("Tree engine").

#: From this many vertices on, "auto" runs on the tree engine: its whole iteration (energy,
#: metric and solves) measured faster from about 900 edges on (FHW, median seconds per
#: iteration exact / tree: 800: 36-40 / 41-44 ms, 1 000: 84-88 / 42-46 ms, 1 648: 248-252 /
#: 64-76 ms; busy machine, alternated).
AUTO_TREE_FROM = 1000
#: From this many edges on, "auto" evaluates the energy alone with the tree: at the default
#: theta (frame included, 7_2, alternated on a shared machine) the energy alone measured
#: 0.5-0.8x the exact speed at 1 000 edges, 0.7-1.2x at 2 000, 1.6-2.2x at 3 000,
#: energy+gradient 1.4-2.3x at 1 000, 2.9-3.9x at 2 000, 4.5-6.0x at 3 000. (Before the
#: tangent-point energy:
#: ``barnes_hut.TREE_FROM``.)
ENERGY_TREE_FROM = 3000


def uses_tree(engine: str, n: int, *, run: bool = False) -> bool:
    """Whether ``engine`` ("exact", "tree" or "auto") evaluates a polygon of ``n`` edges with
    the tree: "auto" from :data:`AUTO_TREE_FROM` on for a run (``run``), from
    :data:`ENERGY_TREE_FROM` on for the energy alone. ValueError naming the valid names for
    another one."""
    if engine not in ENGINE_NAMES:
        raise ValueError(f"unknown engine {engine!r}; choose one of {', '.join(ENGINE_NAMES)}")
    return engine == "tree" or (
        engine == "auto" and n >= (AUTO_TREE_FROM if run else ENERGY_TREE_FROM))


#: Engines by name; :func:`make_engine` resolves a run's ``engine=`` here ("auto" too).
ENGINES: dict[str, type[DenseEngine]] = {"exact": DenseEngine, "tree": TreeEngine}


def make_engine(name: str, layout: Layout, metric: str, **options) -> DenseEngine:
    """The engine ``name`` (a key of :data:`ENGINES`) for a run on ``layout`` in ``metric``.

    ``options`` go to the engine's constructor (``precision``, ``reuse_factorization``,
    ``theta``). A name that selects among engines by the problem (e.g. by its size) belongs
    here too, so that callers only ever pass names.

    Raises
    ------
    ValueError
        For an unknown name (the message lists the valid ones).
    """
    # only "auto" looks at the size
    return engine_class(name, layout.n if name == "auto" else 0)(layout, metric, **options)


def engine_class(name: str, n: int) -> type[DenseEngine]:
    """The class the engine ``name`` runs for a polygon of ``n`` vertices ("auto": the tree
    from ``AUTO_TREE_FROM`` vertices on); ValueError naming the valid names for an unknown
    one."""
    if name not in ENGINES:  # "auto", or an unknown name (ValueError)
        name = "tree" if uses_tree(name, n, run=True) else "exact"
    return ENGINES[name]


# ------------------------------------------------------------------------------------------------
# the public evaluators


def _frame(X, layout, engine, theta, choice: EnergyChoice = MOEBIUS, k: int = 0):
    """The tree's frame of the energy ``choice`` for ``engine``/``theta`` at X (θ None: the
    energy's own default), or None for the exact sum (and for an energy without a tree)."""
    theta = choice.default_theta if theta is None else barnes_hut.check_theta(theta)
    if choice.record.frame is None or not uses_tree(engine, layout.n):
        return None
    return choice.frame(X, layout, theta, k)


def moebius_energy(P, *, engine: str = "auto", theta: float | None = None,
                   closed=True) -> float:
    """Discrete Möbius energy of a closed polygon or a link.

    Parameters
    ----------
    P : (N, 3) array or list of (N_k, 3) arrays
        Vertices of a closed polygon (vertex ``i`` joined to ``i+1``, the last to the first), or
        the components of a link.
    engine : {"exact", "tree", "auto"}
        "exact": the sum over all pairs; "tree": Barnes–Hut on a hierarchy of edges with
        admissibility ``theta`` (relative error about 1e-4 at the default, O(N log N); open
        curves too); "auto": the tree from ``ENERGY_TREE_FROM`` edges on.
    theta : float, optional
        Admissibility of the tree in (0, 2) (default ``barnes_hut.THETA``); smaller is more
        accurate and slower.
    closed : bool or sequence of bool
        False: ``P`` is an open polyline (for a link: one flag per component, or one for
        all), whose energy is O'Hara's regularized sum (docs/api.md, "Open curves").

    Returns
    -------
    float
        ``4 + Σ`` over ordered pairs of disjoint edges (docs/design.md); 4 for a regular polygon,
        invariant under similarities and reversal. Scale-free (computed at a size near 1 for
        curves spanning more than 2^64 or less than 2^-64).
    """
    return _evaluate(P, MOEBIUS, engine, theta, closed, True, False)[0]


def moebius_gradient(P, *, engine: str = "auto", theta: float | None = None, closed=True):
    """Exact derivative of :func:`moebius_energy` with respect to the vertices.

    Parameters
    ----------
    P : (N, 3) array or list of (N_k, 3) arrays
    engine, theta, closed
        As in :func:`moebius_energy`; with the tree, the exact derivative of the approximated
        sum.

    Returns
    -------
    (N, 3) array or list of arrays
        Same shape as ``P``; units 1/length.
    """
    return _evaluate(P, MOEBIUS, engine, theta, closed, False, True)[1]


def _evaluate(P, choice: EnergyChoice, engine, theta, closed, want_energy: bool,
              want_gradient: bool):
    """``(E or None, ∇E or None)`` of the energy ``choice`` on one input check, one frame and
    one pass: with the gradient, the energy is the one its pass sums (within rounding of the
    value sum's, :func:`energy`; a second pass cost 0.28 of the tree's E+g at 20 000 edges)."""
    X, layout, k = as_checked_layout(P, closed)
    frame = _frame(X, layout, engine, theta, choice, k)
    e = g = None
    if want_gradient:
        e, g = choice.exact_gradient(X, layout, k) if frame is None else frame.energy_gradient(X)
        e = e if want_energy else None
    else:
        e = choice.exact(X, layout, k) if frame is None else frame.energy(X)
    if k:  # X was scaled by 2^-k: E(2^k X) = 2^(k s) E(X), ∇E(2^k X) = 2^(k (s − 1)) ∇E(X)
        s = choice.scaling
        e = None if e is None else e * 2.0 ** (k * s)
        g = None if g is None else g * 2.0 ** (k * (s - 1.0))
    return e, (None if g is None else layout.split(g))


#: The names of the ``energy=`` option of :func:`energy`, :func:`energy_gradient` and the runs.
ENERGY_NAMES = energy_choice.ENERGY_NAMES


def energy(P, *, energy: str = DEFAULT_ENERGY, alpha: float | None = None,
           beta: float | None = None, engine: str = "auto", theta: float | None = None,
           closed=True, **options) -> float:
    """The energy ``energy`` of a closed polygon, a link or open polylines.

    Parameters
    ----------
    P : (N, 3) array or list of (N_k, 3) arrays
        Vertices of a closed polygon, or the components of a link (as :func:`moebius_energy`).
    energy : {"moebius", "tangent_point", "bending"}
        A name of :data:`ENERGY_NAMES` (the records of ``core.energies``). "moebius": exactly
        :func:`moebius_energy`. "tangent_point": the discrete tangent-point energy
        ``Σ_{(I, J) ordered, disjoint} l_I l_J |T_I × (m_I − m_J)|^α / |m_I − m_J|^β``
        (docs/design.md, "Tangent-point energy"). "bending": the discrete elastic rod's
        ``Σ_i 4 tan²(φ_i/2) / ℓ_i`` over interior vertices (docs/api.md, "Bending stiffness").
    alpha, beta : float
        The tangent-point exponents: finite, ``α > 0``, ``α + 1 < β < 2α + 1`` (None: 2, 4.5).
        With another energy they are refused (ValueError), not ignored
        (:func:`.energy_choice.check_energy`, the runs' check).
    **options
        The weights of added energies: ``stiffness=w`` adds ``w`` times the bending energy
        of ``P`` as it is (a run's stiffness acts at total length 1: docs/api.md).
    engine : {"exact", "tree", "auto"}
        As in :func:`moebius_energy` ("auto": the tree from ``ENERGY_TREE_FROM`` edges on).
    theta : float, optional
        Admissibility of the tree in (0, 2); default the energy's own (its record's
        ``default_theta``). An energy without a tree (bending) is summed exactly.
    closed : bool or sequence of bool
        As in :func:`moebius_energy`.

    Returns
    -------
    float
        The energy; the tangent-point energy scales as ``λ^(2 + α − β)`` under ``P → λP``,
        the bending energy as ``1/λ``.
    """
    choice = check_energy(energy, alpha, beta, **options)  # ValueError naming what is wrong
    return _evaluate(P, choice, engine, theta, closed, True, False)[0]


def energy_gradient(P, *, energy: str = DEFAULT_ENERGY, alpha: float | None = None,
                    beta: float | None = None, engine: str = "auto", theta: float | None = None,
                    closed=True, **options):
    """:func:`energy` and its exact derivative with respect to the vertices (with the tree,
    the exact derivative of the approximated sum).

    Returns
    -------
    (float, (N, 3) array or list of arrays)
        The energy and the gradient, shaped like ``P``, from one pass over the pairs: the
        gradient is exactly :func:`moebius_gradient`'s for "moebius", the energy
        :func:`energy`'s within rounding (the two sums add their terms in other orders).
    """
    choice = check_energy(energy, alpha, beta, **options)
    return _evaluate(P, choice, engine, theta, closed, True, True)
