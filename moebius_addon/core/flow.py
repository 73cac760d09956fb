"""The projected Sobolev-gradient flow (DESIGN.md, "One iteration"; the paper's "Projected
gradient" and "Restoring feasibility and time step size rules").

One iteration at a feasible polygon P:

1. ``g = ∇E(P)``, ``G = A ⊗ I₃``, ``C = DΦ(P)``;
2. ``[[G, Cᵀ], [C, 0]] [u; λ] = [g; 0]`` (``u`` is the projected G-gradient, ``<g,u> = uᵀGu``);
3. ``τ* =`` first contact of ``P − τu``; first trial ``τ = min(2/3 τ*, growth · τ_prev)``;
4. ``Q = P − τu``, then ``Q ← Q − G⁻¹Cᵀ(CG⁻¹Cᵀ)⁻¹Φ(Q)`` until ``|Φ(Q)|`` is below tolerance,
   else halve τ; the straight path from P to Q is tested for contact too;
5. accept when ``E(Q) ≤ E(P) − σ τ <g, u>``, else halve τ. (A trial that misses this by more
   than the rest of its back-projection is estimated to change E is rejected once
   ``|Φ| ≤ 1e-5``: in every run compared, the same decisions with a third fewer Newton steps.)

The run works on a copy scaled to total length 1 and centred at the origin, so tolerances mean
the same for every size; results are mapped back.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from ._layout import as_unit_layout
from .collision import contact_time_x
from .constraints import Constraints, jacobian, make_constraints, residual
from .energy import energy_gradient_x, energy_x
from .linalg import Factorization, SaddlePointSolver
from .metrics import METRICS, gram_x
from .polygon import check_polygon

HISTORY_KEYS = ("energy", "step", "grad_norm", "constraint_residual", "seconds")

# Deterministic refactorization rule (see SaddlePointSolver): one factorization costs about as
# much as N / _FACTOR_PER_ITER preconditioned Krylov iterations (measured here at N = 3000:
# ~1.1 s against ~15 ms per iteration).
_FACTOR_PER_ITER = 40.0
# From this many vertices on, a single-precision factorization refined by GMRES pays (FHW flow,
# ms per iteration single/double, session 3: 500: 28/21–23, 600: 27–34/32–34, 700: 42/49).
_AUTO_SINGLE_FROM = 600
# A run that stops moving with a projected gradient above this many times tol is jammed, not
# converged (near the minimum Armijo fails on round-off with sqrt(<g,u>) ≈ 1e-8, DESIGN.md).
_STALL_FACTOR = 1e3
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
# Memory a run holds at its peak, in bytes per vertex pair: the Gram matrix (float64), the
# inverse from its factorization and the Schur complement, all N × N (measured peak at 3000
# vertices: 17.4 bytes per pair in single precision, 25.2 in double; with room for more).
_BYTES_PER_PAIR = 32
# Share of the machine's physical memory a run may need before it is refused.
_MEMORY_SHARE = 0.75


@dataclass
class IterationState:
    """What a callback sees after every accepted iterate (and what ``Relaxation`` exposes)."""

    nit: int
    x: object  # polygon (N, 3) or list of arrays, in the caller's coordinates
    energy: float
    step: float
    grad_norm: float
    constraint_residual: float
    seconds: float


@dataclass
class RelaxResult:
    """Outcome of :func:`relax`, in the spirit of ``scipy.optimize.OptimizeResult``."""

    x: object
    fun: float
    nit: int
    success: bool
    message: str
    history: dict = field(default_factory=dict)
    metric: str = "hs"
    stats: dict = field(default_factory=dict)

    def __repr__(self) -> str:
        return (
            f"RelaxResult(fun={self.fun:.10g}, nit={self.nit}, success={self.success}, "
            f"message={self.message!r})"
        )


def _check_names(metric: str, target_lengths: str) -> None:
    if metric not in METRICS:
        raise ValueError(f"unknown metric {metric!r}; choose one of {', '.join(METRICS)}")
    if target_lengths not in ("equal", "keep"):
        raise ValueError("target_lengths must be 'equal' or 'keep'")


def _number(name: str, value, low: float = -np.inf, *, above: bool = False,
            integer: bool = False):
    """``value`` as a finite float (an int with ``integer``) at least ``low`` (above it with
    ``above``), else ValueError naming the option: NaN compares False with every bound, so
    plain comparisons let it through to a run that then stalls for no visible reason."""
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number, got {value!r}") from None
    if not np.isfinite(x) or x < low or (above and x == low):
        bound = "" if low == -np.inf else f" {'>' if above else '>='} {low:g}"
        raise ValueError(f"{name} must be a finite number{bound}, got {value!r}")
    if integer:
        if x != int(x):
            raise ValueError(f"{name} must be a whole number, got {value!r}")
        return int(x)
    return x


def _physical_memory() -> float | None:
    """Bytes of physical memory, or None where the system does not say (Windows)."""
    try:
        return float(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    except (AttributeError, ValueError, OSError):
        return None


def _check_memory(n: int) -> None:
    """Refuse a polygon whose dense N × N matrices would not fit in memory (an absurd size:
    a machine swapping or killed by the out-of-memory handler says nothing useful)."""
    total = _physical_memory()
    need = _BYTES_PER_PAIR * float(n) ** 2
    if total is None or need <= _MEMORY_SHARE * total:
        return
    most = int(np.sqrt(_MEMORY_SHARE * total / _BYTES_PER_PAIR))
    raise ValueError(
        f"{n} vertices need about {need / 1e9:.1f} GB for the dense metric and its "
        f"factorization (memory grows as N²), more than this machine's "
        f"{total / 1e9:.1f} GB allow: resample to at most {most} vertices "
        f"(core.resample(P, n)); a few hundred are plenty to untangle a knot"
    )


def _start(run, P, metric, max_iter, tol, energy_target, ftol, max_seconds, target_lengths,
           check, equilateral):
    """Set-up shared by every run (this one and those of ``methods``): the options, the start
    checked and scaled to total length 1 around the origin (results are mapped back), and the
    target edge lengths — "equal": the mean per component, the start refused unless it is
    equilateral already when ``equilateral``. Returns the scaled start and the targets."""
    run.t0 = time.perf_counter()
    run.max_iter = _number("max_iter", max_iter, 0, integer=True)
    run.tol = _number("tol", tol, 0)
    run.energy_target = None if energy_target is None else _number("energy_target",
                                                                   energy_target)
    run.ftol = _number("ftol", ftol, 0)
    run.max_seconds = None if max_seconds is None else _number("max_seconds", max_seconds, 0)
    X, layout, e2 = as_unit_layout(P)  # exact scaling of curves far from size 1
    _check_memory(layout.n)
    if check:
        check_polygon(P)
    run.layout = layout
    run.metric = metric
    ln = np.linalg.norm(X[layout.nxt] - X, axis=1)
    shift = X.mean(axis=0)
    scale = float(ln.sum())
    Xn = (X - shift) / scale
    ln = ln / scale
    run._shift = np.ldexp(shift, e2)  # results are mapped back by these
    run._scale = float(np.ldexp(scale, e2))
    if target_lengths == "keep":
        return Xn, ln.copy()
    lengths0 = np.empty_like(ln)
    for c in range(layout.k):
        s = slice(layout.starts[c], layout.starts[c + 1])
        mean = ln[s].mean()
        spread = float(np.abs(ln[s] / mean - 1).max())
        if equilateral and spread > 1e-6:
            where = f"component {c}" if layout.is_link else "the polygon"
            raise ValueError(
                f"{where} is not equilateral (edge lengths differ by up to "
                f"{100 * spread:.3g}%); call core.resample(P, n) first, or pass "
                f"target_lengths='keep' to keep its edge lengths"
            )
        lengths0[s] = mean
    return Xn, lengths0


def _give_up(run, gu: float) -> bool:
    """End a run whose line search found no acceptable step: at the minimum the test fails on
    round-off (DESIGN.md, step 6), which is convergence; anywhere else it is a failure worth
    reporting (``gu``: the squared gradient norm in the metric). Returns False."""
    gn = float(np.sqrt(max(gu, 0.0)))
    if gn <= _STALL_FACTOR * run.tol:
        run._finish(True, "converged: no further decrease above round-off")
    else:
        run._finish(False, run._stall_message(gn))
    return False


class _Run:
    """What every run shares (this module's and those of ``methods``): its state as the caller
    sees it and the stopping rules. Subclasses set the history and ``E``; ``_objective`` is
    what the relative-change test watches, ``_GRADIENT`` how messages call the gradient norm."""

    _GRADIENT = "projected gradient norm"

    @property
    def x(self):
        """Current polygon (or list of arrays for a link) in the caller's coordinates."""
        return self.layout.split(self.X * self._scale + self._shift)

    @property
    def energy(self) -> float:
        return self.E

    def state(self) -> IterationState:
        h = self.history
        return IterationState(
            self.nit, self.x, h["energy"][-1], h["step"][-1], h["grad_norm"][-1],
            h["constraint_residual"][-1], h["seconds"][-1],
        )

    def _objective(self) -> float:
        return self.E

    def _finish(self, success: bool, message: str) -> None:
        self.done = True
        self.success = success
        self.message = message

    def stop(self, message: str = "stopped by the caller") -> None:
        """End the run cleanly after the current iterate (e.g. ESC in Blender)."""
        if not self.done:
            self._finish(True, message)

    def _check_stop(self, prev: float | None) -> None:
        gn = self.history["grad_norm"][-1]
        cur = self._objective()
        if gn <= self.tol:
            self._finish(True, f"{self._GRADIENT} {gn:.3g} below tol {self.tol:g}")
        elif self.energy_target is not None and self.E <= self.energy_target:
            self._finish(True, f"energy {self.E:.10g} reached the target {self.energy_target:g}")
        elif prev is not None and abs(prev - cur) <= self.ftol * abs(cur):
            if gn <= _STALL_FACTOR * self.tol:
                self._finish(True, f"relative energy change below ftol {self.ftol:g}")
            else:
                self._finish(False, self._stall_message(gn))
        elif self.nit >= self.max_iter:
            self._finish(False, f"maximum number of iterations ({self.max_iter}) reached")
        elif self.max_seconds is not None and time.perf_counter() - self.t0 >= self.max_seconds:
            self._finish(False, f"time budget of {self.max_seconds:g} s used up")


class Relaxation(_Run):
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
        than 1.5 or 4 on the FHW unknot (docs/benchmarks.md).
    backproject_iter, backproject_tol : int, float
        Modified Newton iterations and tolerance on ``max |Φ|`` (dimensionless).
    edge_lengths, barycenter : bool
        Which constraints to keep.
    target_lengths : {"equal", "keep"}
        "equal": the start must be equilateral (per component; use :func:`resample`);
        "keep": the start's own edge lengths are the targets.
    check : bool
        Run :func:`check_polygon` on the start (disable only for inputs checked already).
    reuse_factorization : bool
        Reuse the saddle-point factorization as a GMRES preconditioner across iterations
        instead of factoring every iterate (pays only late in a flow, see docs/benchmarks.md).
    precision : {"auto", "double", "single"}
        Precision of the factorization; "single" is refined to double precision by GMRES on
        the exact system (same iterates up to the solver tolerance, cheaper factorization);
        "auto" uses it from 600 vertices on.
    interpolate : bool
        After an Armijo failure shrink τ to the minimizer of the parabola through E(P), the
        slope −<g,u> and E(Q), kept in [0.1, 0.5] τ, instead of halving it (fewer rejected
        trials, but smaller accepted steps: measured more iterations on the FHW unknot).
    """

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
    ):
        _check_names(metric, target_lengths)
        if not 0 < armijo < 1:
            raise ValueError("armijo must lie in (0, 1)")
        growth = _number("growth", growth, 1)
        initial_step = _number("initial_step", initial_step, 0, above=True)
        backproject_iter = _number("backproject_iter", backproject_iter, 0, integer=True)
        backproject_tol = _number("backproject_tol", backproject_tol, 0, above=True)
        Xn, lengths0 = _start(self, P, metric, max_iter, tol, energy_target, ftol, max_seconds,
                              target_lengths, check, equilateral=True)
        layout = self.layout
        self.armijo = float(armijo)
        self.growth = growth
        self.backproject_iter = backproject_iter
        self.backproject_tol = backproject_tol
        self.interpolate = bool(interpolate)
        self.con: Constraints = make_constraints(Xn, layout, lengths0, edge_lengths, barycenter)
        if precision not in ("auto", "double", "single"):
            raise ValueError("precision must be 'auto', 'double' or 'single'")
        if precision == "auto":
            precision = "single" if layout.n >= _AUTO_SINGLE_FROM else "double"
        self.solver = SaddlePointSolver(
            reuse=bool(reuse_factorization),
            factor_cost=layout.n / _FACTOR_PER_ITER,
            dtype=np.float32 if precision == "single" else np.float64,
        )
        self.eps = 1e-3 * float(lengths0.mean())  # contact distance
        self.X = Xn
        self.tau = initial_step / self.growth
        self.nit = 0
        self.done = False
        self.success = False
        self.message = ""
        self.rejected = 0
        self._gram = None  # the Gram matrix's memory, refilled at every iterate
        self._prepare(Xn, *energy_gradient_x(Xn, layout))
        self.history = {k: [] for k in HISTORY_KEYS}
        self._record(0.0)
        self._check_stop(None)

    # -- state ---------------------------------------------------------------------------------

    def _prepare(self, X: np.ndarray, E: float, g: np.ndarray) -> None:
        """Steps 1–2 at the (feasible) polygon X."""
        self.X = X
        self.E = E
        self.g = g
        self.jac = jacobian(X, self.con)
        # the previous iterate's Gram matrix is no longer needed: its memory takes the new one
        self._gram = gram_x(self.metric, X, self.layout, out=self._gram)
        self.solver.update(self._gram, self.jac)
        self.u, _ = self.solver.solve(g, np.zeros(self.con.size))
        self.gu = float(np.einsum("ij,ij->", g, self.u))
        self._gnorm = float(np.linalg.norm(g))
        self.phi = residual(X, self.con)

    def _record(self, tau: float) -> None:
        h = self.history
        h["energy"].append(self.E)
        h["step"].append(tau)
        h["grad_norm"].append(float(np.sqrt(max(self.gu, 0.0))))
        h["constraint_residual"].append(float(np.abs(self.phi).max()) if self.phi.size else 0.0)
        h["seconds"].append(time.perf_counter() - self.t0)

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
            self._bp_left = self.backproject_iter + 1
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
            d = self.solver.pseudo_inverse(phi)
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
        if self.interpolate:  # the parabola needs the energy of the finished trial
            return (*self._backproject(Q), None)
        Q, ok = self._backproject(Q, _EARLY)
        if not ok or self._bp_size <= self.backproject_tol:
            return Q, ok, None
        EQ = energy_x(Q, self.layout)
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

    def step(self) -> bool:
        """Advance by one accepted iterate. Returns False once the run is finished."""
        if self.done:
            return False
        X, u, E, gu = self.X, self.u, self.E, self.gu
        tau0 = self.growth * self.tau
        tau_star = contact_time_x(X, u, self.layout, 1.5 * tau0, self.eps)
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
            if not ok and not self.solver.fresh and not refactored:
                # a stale factorization may be what failed: refactor once, same step
                self.solver.refactor()
                refactored = True
                continue
            shrink = 0.5
            # Armijo on the energy alone first (a rejected trial needs no gradient), then the
            # contact test of the path P → Q, then Armijo again on the energy that comes with
            # the gradient (the two kernels sum in different orders)
            if EQ is None:
                EQ = energy_x(Q, self.layout) if ok else np.inf
            if EQ <= target and contact_time_x(X, X - Q, self.layout, 1.0, self.eps) >= 1.0:
                EQ, gQ = energy_gradient_x(Q, self.layout)
                if EQ <= target:
                    self.tau = tau
                    self.nit += 1
                    self._prepare(Q, EQ, gQ)
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
        return _give_up(self, gu)

    def _stall_message(self, gn: float) -> str:
        return (
            f"stalled at energy {self.E:.10g}: steps collapsed while the projected gradient "
            f"norm is still {gn:.3g}; strands are probably jammed against each other — use "
            f"more edges"
        )

    def result(self) -> RelaxResult:
        if not self.done:
            self.stop("not finished (result taken early)")
        return RelaxResult(
            x=self.x,
            fun=self.E,
            nit=self.nit,
            success=self.success,
            message=self.message,
            history={k: list(v) for k, v in self.history.items()},
            metric=self.metric,
            stats={
                "factorizations": self.solver.n_factor,
                "krylov_iterations": list(self.solver.krylov_its),
                "rejected_steps": self.rejected,
                "vertices": self.layout.n,
            },
        )


def relax(
    P,
    metric: str = "hs",
    max_iter: int = 200,
    tol: float = 1e-6,
    callback: Callable[[IterationState], bool | None] | None = None,
    method: str = "projected_gradient",
    **options,
) -> RelaxResult:
    """Relax a knot or link by the projected Sobolev-gradient flow of the Möbius energy.

    Parameters
    ----------
    P : (N, 3) array or list of arrays
        Equilateral closed polygon (see :func:`resample`) or link.
    metric : {"hs", "hs_pure", "h2", "h1", "l2"}
        Gradient metric; ``hs`` (geometric W^{3/2,2}) is the paper's and the fastest.
    max_iter, tol : int, float
        Iteration limit and tolerance on the projected gradient norm ``sqrt(<g, u>)``.
    callback : callable, optional
        ``callback(state)`` after every accepted iterate; returning True stops the run cleanly.
    method : str
        ``projected_gradient`` (the paper's explicit method, DESIGN.md) or another optimizer
        from :mod:`moebius_addon.core.methods` (``METHODS`` lists them).
    **options
        See :class:`Relaxation` (``energy_target``, ``ftol``, ``max_seconds``, ``initial_step``,
        ``armijo``, ``growth``, ``backproject_iter``, ``backproject_tol``, ``edge_lengths``,
        ``barycenter``, ``target_lengths``, ``check``, ``reuse_factorization``,
        ``precision``).

    Returns
    -------
    RelaxResult
        ``x`` (same shape as ``P``), ``fun``, ``nit``, ``success``, ``message`` and ``history``
        (per-iteration lists from the start: energy, step, grad_norm, constraint_residual,
        seconds). Deterministic for a given input.
    """
    if method == "projected_gradient":
        run = Relaxation(P, metric, max_iter, tol, **options)
    else:
        from .methods import make_run

        run = make_run(method, P, metric, max_iter, tol, **options)
    while not run.done:
        before = run.nit
        run.step()
        # every accepted iterate reaches the callback, the last one of the run included
        if run.nit > before and callback is not None and callback(run.state()):
            run.stop("stopped by callback")
    return run.result()


def sobolev_gradient(P, metric: str = "hs", projected: bool = True):
    """The ``metric``-gradient of the Möbius energy at ``P``.

    Parameters
    ----------
    P : (N, 3) array or list of arrays
    metric : {"hs", "hs_pure", "h2", "h1", "l2"}
    projected : bool
        Project onto the tangent space of the constraints (edge lengths and barycenter fixed),
        as the flow does; otherwise ``G⁻¹ ∇E``.

    Returns
    -------
    same shape as P
        Direction of steepest ascent in that metric (the flow moves along its negative); the
        paper's Fig. 2 compares these fields.
    """
    X, layout, k = as_unit_layout(P)  # u(2^k X) = 2^k u(X): every Gram matrix scales as 4^-k
    _, g = energy_gradient_x(X, layout)
    A = gram_x(metric, X, layout)
    if not projected:
        u = np.linalg.solve(A, g)
    else:
        ln = np.linalg.norm(X[layout.nxt] - X, axis=1)
        con = make_constraints(X, layout, ln)
        fac = Factorization(A, jacobian(X, con))
        u, _ = fac.solve(g, np.zeros(con.size))
    return layout.split(np.ldexp(u, k) if k else u)
