"""The projected Sobolev-gradient flow, the paper's explicit method (docs/design.md, "One
iteration"; the paper's "Projected gradient" and "Restoring feasibility and time step size
rules").

One iteration at a feasible polygon P:

1. ``g = ∇E(P)``, ``G = A ⊗ I₃``, ``C = DΦ(P)``;
2. ``[[G, Cᵀ], [C, 0]] [u; λ] = [g; 0]`` (``u`` is the projected G-gradient, ``<g,u> = uᵀGu``);
3. ``τ* =`` first contact of ``P − τu``; first trial ``τ = min(2/3 τ*, growth · τ_prev)``;
4. ``Q = P − τu``, then ``Q ← Q − G⁻¹Cᵀ(CG⁻¹Cᵀ)⁻¹Φ(Q)`` until ``|Φ(Q)|`` is below tolerance,
   else halve τ; the straight path from P to Q is tested for contact too;
5. accept when ``E(Q) ≤ E(P) − σ τ <g, u>``, else halve τ. (A trial that misses this by more
   than the rest of its back-projection is estimated to change E is rejected once
   ``|Φ| ≤ 1e-5``: in every run compared, the same decisions with a third fewer Newton steps.)

Energy, gradient, metric, solves and contact times come from the run's engine.
"""

from __future__ import annotations

import time

import numpy as np

from ..energies.choice import DEFAULT_ENERGY
from ..geometry.constraints import Constraints, jacobian, make_constraints, residual
from ._interrupts import resumable
from .base import (
    HISTORY_KEYS,
    SETTLE_ITERATIONS,
    Run,
    Status,
    _check_names,
    check_dense_size,
    check_number,
)
from .checks import check_flag

# The modified Newton back-projection gives up on a trial step once |Φ| shrinks by less than
# this factor per iteration (it converges linearly; slower means the step left its basin).
_CONTRACTION = 0.5
# Trials whose straight step breaks the constraints by more than this (max |Φ|: relative edge
# length change) are rejected before any solve. Measured on the FHW unknot at 600 edges: every
# back-projection that succeeded started below 0.11, most failing ones above 0.12.
_MAX_TRIAL_RESIDUAL = 0.12
# The back-projection pauses at this |Φ| for a first Armijo test: a trial that fails it by
# more than the energy can still move is rejected without the last Newton steps (FHW at 1648
# edges: half the back-projections belong to rejected trials, about 6 steps each).
_EARLY = 1e-5
# Smallest back-projection tolerance taken at all (a run also raises it to its own rounding,
# below): the residuals are log edge lengths computed from float64 coordinates; before that
# floor the FHW unknot at 600 edges stalled at once with 3e-15 and ran with 1e-14, and
# 1e-300 ran into a reported jam (Blender's Back-projection Digits go up to 14 as well).
MIN_BACKPROJECT_TOL = 1e-14
# A growth whose path meets something, or whose back-projection fails, is halved up to this
# many times (1 % becomes 0.004 %) before the iteration goes on without growing.
_GROWTH_HALVINGS = 8
# A growing run whose growth was blocked this many iterations in a row ends STALLED ("growth
# blocked"): its descent steps alone did not make room, and whether such a step is still found
# on a curve with (almost) nothing to descend depends on the last bits of the sums (a round
# circle in a sphere ran to max_iter with one BLAS thread and stopped at once with two).
_GROWTH_PATIENCE = 20


def check_line_search(armijo: float, growth: float) -> tuple[float, float]:
    """The explicit method's Armijo constant in (0, 1) and step growth >= 1, or ValueError
    naming the option."""
    if not 0 < check_number("armijo", armijo) < 1:
        raise ValueError("armijo must lie in (0, 1)")
    return float(armijo), check_number("growth", growth, 1)


class Relaxation(Run):
    """A projected Sobolev-gradient run that advances one accepted iterate per :meth:`step`.

    Parameters
    ----------
    P : (N, 3) array or list of (N_k, 3) arrays
        Closed polygon or link; equilateral per component unless ``target_lengths="keep"``.
    metric : {"hs", "hs_pure", "h2", "h1", "l2"}
        Metric of the gradient; ``hs`` is the paper's geometric W^{3/2,2}.
    max_iter : int
        Accepted iterations at most.
    tol : float
        Stop once ``sqrt(<g, u>)`` (scale-free) is below this.
    energy_target : float, optional
        Stop once the energy is at or below this (e.g. 4.01 for "round").
    ftol : float
        Stop once the relative energy decrease of an iteration is below this.
    max_seconds : float, optional
        Wall-time budget.
    initial_step, armijo, growth : float
        First trial step, Armijo constant σ (paper: 1/2), cap on the step growth per iteration:
        the first trial is ``min(growth · τ_prev, 2/3 τ*)``. The paper starts at ``2/3 τ*``
        alone; a cap of 8 keeps the contact search bounded and measured fewer iterations
        than 1.5 or 4 on the FHW unknot (docs/lab/exact-engine.md).
    backproject_iter, backproject_tol : int, float
        Modified Newton iterations and tolerance on ``max |Φ|`` (dimensionless). The tree
        engine's hs allows a fifth more iterations (``engine.BANDED_NEWTON``): its steps are
        in a banded metric, which contracts more slowly.
    edge_lengths, barycenter : bool
        Which constraints to keep.
    target_lengths : {"equal", "keep"}
        "equal": the start must be equilateral (per component; use :func:`resample`);
        "keep": the start's own edge lengths are the targets.
    check : bool
        Run :func:`check_polygon` on the start (disable only for inputs checked already).
    reuse_factorization : bool
        Reuse the saddle-point factorization as a GMRES preconditioner across iterations
        instead of factoring every iterate (pays only late in a flow, see docs/lab/exact-engine.md).
    precision : {"auto", "double", "single"}
        Precision of the factorization; "single" is refined to double precision by GMRES on
        the exact system (same iterates up to the solver tolerance, cheaper factorization);
        "auto" uses it from 600 vertices on.
    interpolate : bool
        After an Armijo failure shrink τ to the minimizer of the parabola through E(P), the
        slope −<g,u> and E(Q), kept in [0.1, 0.5] τ, instead of halving it (fewer rejected
        trials, but smaller accepted steps: measured more iterations on the FHW unknot).
    engine : str
        Name of the numerical engine (``core.runs.engine.ENGINES``): "exact", "tree" or "auto".
    theta : float, optional
        Admissibility of the tree in (0, 2) (default ``barnes_hut.THETA``); checked
        for every engine.
    krylov_rtol : float, optional
        Relative tolerance of the tree engine's Krylov solves with ``hs`` and ``hs_pure``
        (default ``hs_tree.RTOL``); checked for every engine.
    exact_backprojection : bool
        The tree engine's back-projection steps in the metric itself (Krylov solves) instead
        of its banded preconditioner's metric.
    pinned : sequence of int, optional
        Vertices that keep their position exactly (for a link: one list per component). Their
        coordinates are eliminated from the saddle-point system and the back-projection (zero
        velocity); an edge between two pins has no length row and a component with a pin no
        barycenter rows. The tree engine borders its O(N) solvers with the pin rows for up
        to ``pinned_solve.TREE_MAX_PINS`` pins, and solves densely beyond (sizes bounded as
        for the exact engine). See :func:`..pins.check_pins` for what is refused.
    pin_tangents : bool
        Also pin both neighbours of every pinned vertex (fixed tangents at the pins).
    closed : bool or sequence of bool
        False: ``P`` is an open polyline (a link: one flag per component, or one for all),
        relaxed with O'Hara's regularized energy of an open polygon on the exact engine
        (docs/api.md, "Open curves").
    energy, **energy_options
        The energy minimized: ``"moebius"`` (default) or ``"tangent_point"`` with exponents
        ``alpha``, ``beta`` (default 2, 4.5), and ``stiffness`` (default 0), the weight of the
        bending energy added to it (the options of the records in ``core.energies``; other
        names are refused). The energies of the history are those of the curve scaled to
        total length 1 (the same as the caller's curve's when the energy is scale-invariant:
        Möbius, and tangent-point with β = α + 2, without stiffness).
    length_target : float or sequence of float, optional
        Grow the total length (caller's units; of the whole curve, or one per component) to
        this during the run, then hold it (:mod:`.growth`; docs/api.md, "Length growth").
    length_growth : float, optional
        Relative growth per iteration, > 0 (default ``growth.DEFAULT_LENGTH_GROWTH``, 1 %);
        needs ``length_target``.
    settle, settle_iterations : float, int
        Stop (converged) once no vertex moved more than ``settle`` mean edge lengths in each
        of ``settle_iterations`` (default 5) iterations in a row: the shape no longer changes
        visibly. 0 (default): not used.
    thickness : float
        Tube radius ``r`` in the caller's units (default 0: centre lines alone). Every
        iterate and the straight path between iterates keep strands ``2r`` apart (parts of
        one strand more than π r apart along it) and ``r`` from the obstacles and the
        container (:mod:`..thickness`; docs/api.md, "Thickness"); a start that breaks it is
        refused, naming where and the distance found, unless ``push_apart``.
    push_apart : bool
        With a thickness: a start whose tubes meet is not refused; the run keeps the tubes
        its iterates allow (never thinner than before) as the flow pushes the strands apart,
        until they reach ``thickness`` (the message says by which iteration, or how far they
        got).
    """

    _OPEN_CURVES = True
    _LENGTH_GROWTH = True
    NAME = "projected_gradient"

    def __init__(
        self,
        P,
        metric: str = "hs",
        max_iter: int = 200,
        tol: float = 1e-6,
        *,
        energy_target: float | None = None,
        ftol: float = 1e-12,
        max_seconds: float | None = None,
        initial_step: float = 1.0,
        armijo: float = 0.5,
        growth: float = 8.0,
        backproject_iter: int = 10,
        backproject_tol: float = 1e-10,
        edge_lengths: bool = True,
        barycenter: bool = True,
        target_lengths: str = "equal",
        check: bool = True,
        reuse_factorization: bool = False,
        precision: str = "auto",
        interpolate: bool = False,
        engine: str = "auto",
        theta: float | None = None,
        krylov_rtol: float | None = None,
        exact_backprojection: bool = False,
        pinned=None,
        pin_tangents: bool = False,
        obstacles=None,
        obstacle_weight: float = 1.0,
        container=None,
        obstacle_tol: float | None = None,
        closed=True,
        energy=DEFAULT_ENERGY,
        length_target=None,
        length_growth: float | None = None,
        settle: float = 0.0,
        settle_iterations: int = SETTLE_ITERATIONS,
        thickness: float = 0.0,
        push_apart: bool = False,
        **energy_options,
    ):
        _check_names(metric, target_lengths)
        edge_lengths = check_flag("edge_lengths", edge_lengths)
        barycenter = check_flag("barycenter", barycenter)
        interpolate = check_flag("interpolate", interpolate)
        armijo, growth = check_line_search(armijo, growth)
        initial_step = check_number("initial_step", initial_step, 0, above=True)
        backproject_iter = check_number("backproject_iter", backproject_iter, 0, integer=True)
        backproject_tol = check_number("backproject_tol", backproject_tol, 0, above=True)
        if backproject_tol < MIN_BACKPROJECT_TOL:
            raise ValueError(
                f"backproject_tol must be at least {MIN_BACKPROJECT_TOL:g}, got "
                f"{backproject_tol!r}: the constraint residuals are log edge lengths, whose "
                f"float64 rounding alone exceeds that (the default is 1e-10)")
        super().__init__(P, metric, max_iter, tol, energy_target=energy_target, ftol=ftol,
                         max_seconds=max_seconds, target_lengths=target_lengths, check=check,
                         equilateral=True, engine=engine, theta=theta, precision=precision,
                         reuse_factorization=reuse_factorization, krylov_rtol=krylov_rtol,
                         exact_backprojection=exact_backprojection, pinned=pinned,
                         pin_tangents=pin_tangents, fixed_lengths=edge_lengths,
                         obstacles=obstacles, obstacle_weight=obstacle_weight, container=container,
                         obstacle_tol=obstacle_tol, closed=closed, energy=energy,
                         length_target=length_target, length_growth=length_growth,
                         settle=settle, settle_iterations=settle_iterations,
                         thickness=thickness, push_apart=push_apart, **energy_options)
        self.armijo = float(armijo)
        self.growth = growth
        self.backproject_iter = backproject_iter
        # an edge length taken as the difference of coordinates of size |x| is rounded by
        # about ε|x|/l: no back-projection brings the log lengths closer than that. A link
        # component 1e5 lengths from another (coordinates of 8e3 against edges of 1e-2 at the
        # run's scale) stalled at once on 1e-10; curves of one piece stay below it up to 10⁶
        # edges (4ε · 0.16 · N)
        real = self.lengths0[self.layout.real] if self.layout.has_open else self.lengths0
        self.backproject_tol = max(backproject_tol, 4.0 * np.finfo(float).eps * float(
            np.abs(self.X).max()) / float(real.min()))
        self.interpolate = interpolate
        if not self.engine.dense_metric:  # the tree's solvers need both rows and few pins
            if self.pinned is not None and not self.engine.solves_pins(self.pinned.size):
                check_dense_size(self.layout.n, "pins")
            elif not (edge_lengths and barycenter):
                check_dense_size(self.layout.n, "constraints")
        self.con: Constraints = make_constraints(self.X, self.layout, self.lengths0,
                                                 edge_lengths, barycenter, self.pinned)
        self.tau = initial_step / self.growth
        self._blocked = 0  # iterations in a row whose growth was blocked (_GROWTH_PATIENCE)
        self._prepare(self.X, *self.engine.energy_gradient(self.X))
        self.history = {k: [] for k in (*HISTORY_KEYS, "length")}
        self._record(0.0)
        self._check_stop(None)

    # -- state ---------------------------------------------------------------------------------

    def _prepare(self, X: np.ndarray, E: float, g: np.ndarray) -> None:
        """Steps 1–2 at the (feasible) polygon X; the iterate is committed whole at the end
        (an interruption before leaves the last one as it was, :mod:`._interrupts`)."""
        jac = jacobian(X, self.con)
        self.engine.update(X, jac)
        u, _ = self.engine.solve(g, np.zeros(self.con.size))
        self.engine.shed()  # the line search needs no more solves here
        phi = residual(X, self.con)
        self.X, self.E, self.g, self.jac, self.u, self.phi = X, E, g, jac, u, phi
        self.gu = float(np.einsum("ij,ij->", g, u))
        self._gnorm = float(np.linalg.norm(g))

    def _resume(self) -> None:
        """After an interruption inside a step: the engine built again at the accepted
        iterate (its last update may have stopped half-way)."""
        self.engine.update(self.X, self.jac)

    def _record(self, tau: float) -> None:
        h = self.history
        h["energy"].append(self.E)
        h["step"].append(tau)
        h["grad_norm"].append(float(np.sqrt(max(self.gu, 0.0))))
        h["constraint_residual"].append(float(np.abs(self.phi).max()) if self.phi.size else 0.0)
        h["seconds"].append(time.perf_counter() - self.t0)
        ln = self.jac.ln[self.layout.real] if self.layout.has_open else self.jac.ln
        h["length"].append(float(ln.sum()) * self._scale)

    # -- one iteration -------------------------------------------------------------------------

    def _backproject(self, Q: np.ndarray, tol: float | None = None,
                     resume: bool = False) -> tuple[np.ndarray, bool]:
        """Modified Newton steps until ``max |Φ(Q)|`` is below ``tol`` (default: the run's
        tolerance; never below it). ``resume=True`` goes on from where the last call stopped
        with the same steps and checks as one uninterrupted call."""
        tol = self.backproject_tol if tol is None else max(tol, self.backproject_tol)
        if not resume:
            self._bp_prev = np.inf  # residual before the last step
            self._bp_step = 0.0  # Euclidean norm of the last step
            self._bp_left = self.engine.newton_steps(self.backproject_iter) + 1
        while self._bp_left > 0:
            phi = residual(Q, self.con)
            size = float(np.abs(phi).max()) if phi.size else 0.0
            self._bp_size = size
            if size <= tol:
                return Q, True
            self._bp_left -= 1
            if not size < _CONTRACTION * self._bp_prev:
                return Q, False  # not contracting (or NaN): the step is too long
            self._bp_prev = size
            d = self.engine.pseudo_inverse(phi)
            self._bp_step = float(np.linalg.norm(d))
            Q = Q - d
            if not np.all(np.isfinite(Q)):
                return Q, False
        return Q, False

    def _project(self, Q: np.ndarray, target: float) -> tuple[np.ndarray, bool, float | None]:
        """Step 4 for the trial ``Q`` whose Armijo target is ``target``: ``(Q, ok, EQ)``.

        ``EQ`` is the trial's energy where this already decided: above ``target`` for a trial
        rejected at ``|Φ| ≤ _EARLY`` (it misses Armijo by more than the rest of the
        back-projection could change), −inf for one finished after passing that test (the
        energy with the gradient decides); None where the energy is still to be computed."""
        if self.interpolate or not self.engine.early_energy_test:
            # the parabola needs the energy of the finished trial; an engine whose energy
            # costs more than the Newton steps the test saves finishes every trial
            return (*self._backproject(Q), None)
        Q, ok = self._backproject(Q, _EARLY)
        if not ok or self._bp_size <= self.backproject_tol:
            return Q, ok, None
        EQ = self.engine.trial_energy(Q, gradient=False)  # Q moves on if it passes
        if EQ > target + self._energy_margin():
            return Q, True, EQ
        Q, ok = self._backproject(Q, resume=True)
        return Q, ok, (-np.inf if ok else None)

    def _energy_margin(self) -> float:
        """How far the energy may still move while the back-projection finishes: the
        remaining steps are taken to shrink like the last one (ratio ρ ≤ _CONTRACTION) and the
        gradient along them to stay below 20 times the norm of the current iterate's. An
        estimate, not a proof, chosen generously: in every run compared (FHW 600 and 1648,
        helix 1940, and the test) the decisions and iterates were the same as without it."""
        if not np.isfinite(self._bp_prev):
            return np.inf  # no step taken yet: no estimate of how far the rest goes
        rho = self._bp_size / self._bp_prev
        rest = self._bp_step * rho / (1.0 - rho)
        return 20.0 * self._gnorm * rest + 1e-14 * abs(self.E)

    @resumable
    def step(self) -> bool:
        """Advance by one accepted iterate. Returns False once the run is finished."""
        if self.done:
            return False
        X, u, E, gu = self.X, self.u, self.E, self.gu
        tau0 = self.growth * self.tau
        tau_star = self.engine.contact_time(X, u, 1.5 * tau0, self.eps)
        tau = min(tau0, 2.0 / 3.0 * tau_star)
        refactored = False
        for _ in range(60):
            Q = X - tau * u
            with np.errstate(divide="ignore", invalid="ignore"):
                r0 = float(np.abs(residual(Q, self.con)).max()) if self.con.size else 0.0
            if r0 > _MAX_TRIAL_RESIDUAL:
                # Φ(X − τu) grows like τ²: this trial is far outside the back-projection's
                # basin; shrink at once, without solves, to about where it would succeed
                self.rejected += 1
                tau *= min(0.5, max(0.1, 0.9 * np.sqrt(_MAX_TRIAL_RESIDUAL / r0)))
                continue
            target = E - self.armijo * tau * gu
            with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
                # a wild trial may overflow on its way to rejection; it is never accepted
                Q, ok, EQ = self._project(Q, target)
            if not ok and not self.engine.fresh and not refactored:
                # a stale factorization may be what failed: refactor once, same step
                self.engine.refactor()
                refactored = True
                continue
            shrink = 0.5
            # Armijo on the energy alone first (a rejected trial needs no gradient), then the
            # contact test of the path P → Q, then Armijo again on the energy that comes with
            # the gradient (the two kernels sum in different orders)
            if EQ is None:
                EQ = self.engine.trial_energy(Q) if ok else np.inf
            if EQ <= target and self.engine.path_is_free(X, Q, self.eps):
                if self._growing:  # the length grows from the accepted trial
                    return self._accept_grown(self._grow(X, Q), tau, E)
                EQ, gQ = self.engine.energy_gradient(Q)
                if EQ <= target:
                    self._prepare(Q, EQ, gQ)
                    self.tau = tau
                    self.nit += 1
                    self._record(tau)
                    self._check_stop(E)
                    return not self.done
            elif ok and self.interpolate:
                # minimizer of the parabola through E, slope −<g,u> and E(Q), kept in
                # [0.1, 0.5] τ (safeguarded backtracking, Nocedal & Wright §3.5)
                curv = EQ - E + tau * gu
                if curv > 0:
                    shrink = min(0.5, max(0.1, 0.5 * gu * tau / curv))
            self.rejected += 1
            tau *= shrink
            if tau * gu <= 1e-15 * abs(E):
                break
        if self._growing:  # no descent step: the length may still grow from the iterate
            grown = self._grow(X, X)
            if grown[1] is not None:
                return self._accept_grown(grown, self.tau, E, step=0.0)
            return self._growth_blocked()
        return self._give_up(gu)

    # -- length growth (.growth) ---------------------------------------------------------------

    @property
    def _growing(self) -> bool:
        """Whether the length is still to grow (``length_target=`` not reached yet)."""
        return self.growth_schedule is not None and not self.growth_schedule.reached

    def _grow(self, X: np.ndarray, Q: np.ndarray):
        """``(G, con, free)``: ``Q`` (an accepted trial from the iterate ``X``, or ``X``
        itself) back-projected onto target lengths grown by one iteration's growth, those
        constraints and the components' grown lengths; ``(Q, None, None)`` where no growth
        was possible. Nothing of the run changes here (:meth:`_accept_grown` commits).

        The straight path from ``X`` to the grown polygon is tested for contact with the curve
        itself, the obstacles and the container like every step (it is what the keyframes
        interpolate); where it fails, or the back-projection does, the growth is halved, up to
        :data:`_GROWTH_HALVINGS` times."""
        sched = self.growth_schedule
        rate = sched.rate
        old = self.con
        try:
            for _ in range(_GROWTH_HALVINGS + 1):
                free = sched.propose(rate)
                self.con = sched.constraints(old, free)
                with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
                    G, ok = self._backproject(Q)
                if ok and self.engine.path_is_free(X, G, self.eps):
                    return G, self.con, free
                rate *= 0.5
        finally:
            self.con = old
        return Q, None, None

    def _accept_grown(self, grown, tau: float, E: float, step: float | None = None) -> bool:
        """Make the polygon of ``grown`` (:meth:`_grow`: grown, or a descent step whose
        growth was blocked) the next iterate. No Armijo test: growth may raise the energy
        (obstacles, the container, an energy that is not scale-invariant); the descent part
        passed it already."""
        Q, con, free = grown
        EQ, gQ = self.engine.energy_gradient(Q)
        if con is None:
            self._prepare(Q, EQ, gQ)
            self._blocked += 1
        else:
            old, self.con = self.con, con
            try:
                self._prepare(Q, EQ, gQ)
            except BaseException:  # an interruption leaves the last iterate whole
                self.con = old
                raise
            self.growth_schedule.commit(free)
            self.lengths0 = con.lengths0
            self._blocked = 0
        self.tau = tau
        self.nit += 1
        self._record(tau if step is None else step)
        self._check_stop(E)
        if not self.done and self._growing and self._blocked >= _GROWTH_PATIENCE:
            return self._growth_blocked(f"for {self._blocked} iterations in a row")
        return not self.done

    def _growth_blocked(self, how: str = "and no descent step left") -> bool:
        """End a growing run that can neither descend nor grow, or has not grown for
        :data:`_GROWTH_PATIENCE` iterations."""
        self._finish(False, f"growth blocked at {self.growth_schedule.words()}: no room to "
                            f"grow without contact {how} (the container or "
                            f"the obstacles leave too little room, or strands are jammed)",
                     Status.STALLED)
        return False

    def _check_stop(self, prev: float | None) -> None:
        if not self._growing:
            super()._check_stop(prev)
            return
        self._push_apart()
        if self.nit >= self.max_iter:  # no convergence before the target length is reached
            self._finish(False, f"maximum number of iterations ({self.max_iter}) reached "
                                f"while growing ({self.growth_schedule.words()})",
                         Status.MAX_ITER)
        elif self.max_seconds is not None and time.perf_counter() - self.t0 >= self.max_seconds:
            self._time_up()

    def nudge(self, rng: np.random.Generator, scale: float):
        """A feasible polygon near the current iterate, for a restart (``restarts=`` of
        :func:`..flow.relax`): white noise solved in the run's metric and projected onto the
        constraints (a smooth field, zero at the pins), scaled so that the largest vertex moves
        ``scale`` mean edge lengths (less where that would reach a contact), back-projected;
        the straight path from the iterate to it touches nothing (the step is halved until it
        does not). In the caller's coordinates, as :attr:`x`.

        Raises ValueError when no such step was found (30 halvings)."""
        X = self.X
        V = rng.standard_normal(X.shape)
        u, _ = self.engine.solve(V, np.zeros(self.con.size))
        ln = self.lengths0[self.layout.real] if self.layout.has_open else self.lengths0
        size = float(np.abs(u).max())
        if not size > 0:
            raise ValueError("no free vertex to nudge")
        tau = scale * float(ln.mean()) / size
        tau = min(tau, 2.0 / 3.0 * self.engine.contact_time(X, u, tau, self.eps))
        for _ in range(30):
            Q, ok = self._backproject(X - tau * u)
            if ok and self.engine.path_is_free(X, Q, self.eps):
                Y = Q * self._scale + self._shift
                if self.pinned is not None:
                    Y[self.pinned] = self._pinned_at
                return self.layout.split(Y)
            tau *= 0.5
        raise ValueError("no nudge of the polygon kept its constraints without contact")

    def _stall_message(self, gn: float) -> str:
        return (f"stalled at energy {self.E:.10g}: steps collapsed while the projected "
                f"gradient norm is still {gn:.3g}; {self._stall_cause()}")

    def _stats(self) -> dict:
        return {
            "factorizations": self.engine.factorizations,
            "krylov_iterations": self.engine.krylov_iterations,
            "rejected_steps": self.rejected,
            "vertices": self.layout.n,
            **super()._stats(),
        }
