"""Infeasible (penalty) methods of the paper's comparison (section "Optimization methods
employed", Figs. 3 and 4), each usable with every metric. They replace the edge-length
constraints by Hencky's stretch penalty

    E_α(P) = E(P) + α Σ_I log(l_I / l0_I)² l0_I

and compute gradients in the metric ``G + α DΦᵀ M DΦ`` (``M = diag(l0)``, the L² product of
edge functions; the paper leaves the penalty term out of the ``l2`` metric, and so do we by
default): ``ncg`` (Polak–Ribière PR+), ``lbfgs`` (history 30, initial inverse Hessian = inverse
of the current metric), ``nesterov`` (accelerated gradient with momentum reset when the energy
goes up), all with a weak Wolfe line search. Every trial step, the momentum step included, is
truncated by the continuous collision test, and the straight segment between two iterates is
collision-free for every method, so no method passes a strand through another (and linear
interpolation between iterates, as keyframes do, does not either).

The history holds the Möbius energy ``E``, never the penalized one, so methods compare
directly; ``history["penalized_energy"]`` holds that.
"""

from __future__ import annotations

import time

import numpy as np

from ..energies.choice import DEFAULT_ENERGY, take_energy_options
from ..geometry.constraints import jacobian, make_constraints
from ..geometry.pins import count_pins
from ._interrupts import resumable
from .base import HISTORY_KEYS, SETTLE_ITERATIONS, Run, _check_names, _OutOfTime, check_number

#: Default weight α of Hencky's stretch penalty (units where the total length is 1).
DEFAULT_PENALTY_WEIGHT = 1e4

# Relaxation options that mean nothing without hard constraints; accepted (so that a caller
# can pass one option set to every method) and ignored by the penalty methods.
_FEASIBLE_ONLY = frozenset({
    "armijo", "growth", "backproject_iter", "backproject_tol", "edge_lengths", "barycenter",
    "reuse_factorization", "precision", "exact_backprojection", "push_apart",
})


def _dot(a, b) -> float:
    return float(np.einsum("ij,ij->", a, b))


def pinned_refusal(method: str) -> str:
    """Why ``method`` (a penalty method) refuses ``pinned=``, and what to use instead."""
    return (f"method {method!r} cannot keep pinned vertices fixed (it holds the edge lengths "
            f"by a penalty, without constraint rows to pin them with): use a feasible method, "
            f"projected_gradient, projected_gradient_implicit or trust_region, or pass no "
            f"pinned=")


class _PenaltyRun(Run):
    """Common state of the infeasible methods: normalization, penalty, metric, Wolfe search.

    Parameters (besides ``P, metric, max_iter, tol`` as in :class:`.projected.Relaxation`)
    ----------
    penalty : float
        Weight α of Hencky's stretch penalty, in units where the total length is 1 (``alpha``
        and ``beta`` are the tangent-point energy's exponents).
    penalty_metric : {"auto", True, False}
        Add ``α DΦᵀ M DΦ`` to the metric; "auto": for every metric except ``l2`` (the paper).
    c1, c2 : float
        Weak Wolfe constants (sufficient decrease, curvature).
    energy_target, ftol, max_seconds, initial_step, target_lengths, check, engine, theta,
    energy, alpha, beta
        As in :class:`.projected.Relaxation`; ``ftol`` applies to the penalized energy.
    """

    _DENSE_METRIC = True  # engine.penalty_solver is dense for every engine

    _GRADIENT = "gradient norm"

    def __init__(self, P, metric="hs", max_iter=200, tol=1e-6, *,
                 penalty: float = DEFAULT_PENALTY_WEIGHT, penalty_metric="auto", c1: float = 1e-4,
                 c2: float = 0.9, energy_target: float | None = None, ftol: float = 1e-12,
                 max_seconds: float | None = None, initial_step: float = 1.0,
                 target_lengths: str = "equal", check: bool = True, engine: str = "auto",
                 theta: float | None = None, pinned=None, pin_tangents: bool = False,
                 obstacles=None, obstacle_weight: float = 1.0, container=None,
                 obstacle_tol: float | None = None, closed=True,
                 energy=DEFAULT_ENERGY, length_target=None,
                 length_growth=None, settle: float = 0.0,
                 settle_iterations: int = SETTLE_ITERATIONS, thickness: float = 0.0,
                 **ignored):
        energy_options = take_energy_options(ignored)
        unknown = set(ignored) - _FEASIBLE_ONLY
        if unknown:
            raise TypeError(f"unknown option(s) {', '.join(sorted(unknown))}")
        if count_pins(pinned):
            raise ValueError(pinned_refusal(self.NAME))
        if check_number("thickness", thickness, 0) > 0:
            # the stretch a tube may bend in is counted in edges of the target length
            # (..thickness), which a penalty lets drift
            raise ValueError(f"method {self.NAME!r} cannot keep a thickness (it holds the edge "
                             f"lengths by a penalty, and the tube's rule counts edges along a "
                             f"strand): use a feasible method, projected_gradient, "
                             f"projected_gradient_implicit or trust_region, or thickness=0")
        _check_names(metric, target_lengths)
        c1, c2 = check_number("c1", c1), check_number("c2", c2)
        if not 0 < c1 < c2 < 1:
            raise ValueError("Wolfe constants need 0 < c1 < c2 < 1")
        weight = check_number("penalty", penalty, 0)
        initial_step = check_number("initial_step", initial_step, 0, above=True)
        # the penalty pulls a non-equilateral start to the mean lengths: no equilateral check
        super().__init__(P, metric, max_iter, tol, energy_target=energy_target, ftol=ftol,
                         max_seconds=max_seconds, target_lengths=target_lengths, check=check,
                         equilateral=False, engine=engine, theta=theta, obstacles=obstacles,
                         obstacle_weight=obstacle_weight, container=container,
                         obstacle_tol=obstacle_tol, closed=closed,
                         energy=energy, length_target=length_target,
                         length_growth=length_growth,  # refused there, by name
                         settle=settle, settle_iterations=settle_iterations, **energy_options)
        self.alpha = float(weight)  # α of the docs (docs/design.md, the penalty methods)
        self.penalty_in_metric = (metric != "l2") if penalty_metric == "auto" else bool(
            penalty_metric)
        self.c1, self.c2 = float(c1), float(c2)
        self.con = make_constraints(self.X, self.layout, self.lengths0, True, False)
        self.tau = float(initial_step)
        self.evaluations = 0
        self.history = {k: [] for k in (*HISTORY_KEYS, "penalized_energy")}
        self._set_point(self.X, self._evaluate(self.X))
        self._init_method()
        self._record(0.0)
        self._check_stop(None)

    # -- objective and metric ----------------------------------------------------------------

    def _evaluate(self, Y):
        """``(f, E, ∇f, φ)`` at Y: penalized energy, Möbius energy, gradient, log-stretches."""
        self.evaluations += 1
        E, g = self.engine.energy_gradient(Y)
        jac = jacobian(Y, self.con)
        lay = self.layout
        ln = np.linalg.norm(Y[lay.nxt] - Y, axis=1)
        phi = np.log(ln) - np.log(self.lengths0)
        f = E + self.alpha * float(np.sum(self.lengths0 * phi * phi))
        g = g + jac.rmatvec(2.0 * self.alpha * self.lengths0 * phi)
        return f, E, g, phi, jac

    def _metric_solver(self, Y, jac):
        return self.engine.penalty_solver(Y, jac, self.alpha, self.lengths0,
                                          self.penalty_in_metric)

    def _set_point(self, Y, ev, solver=None):
        """Move to Y with its evaluation and the metric gradient there (with ``solver``, a
        metric built elsewhere, if given)."""
        msolver = solver if solver is not None else self._metric_solver(Y, ev[4])
        z = msolver.solve(ev[2])
        # committed whole (an interruption before leaves the last point as it was)
        self.X, self.msolver, self.z = Y, msolver, z
        self.f, self.E, self.g, self.phi, self.jac = ev
        self.gz = _dot(self.g, self.z)

    def _init_method(self):
        pass

    def _resume(self) -> None:
        """Nothing to rebuild after an interruption: every point's metric solver is made
        afresh and committed with it (:meth:`_set_point`)."""

    # -- bookkeeping ----------------------------------------------------------------------------

    def _record(self, tau):
        h = self.history
        h["energy"].append(self.E)
        h["step"].append(float(tau))
        h["grad_norm"].append(float(np.sqrt(max(self.gz, 0.0))))
        h["constraint_residual"].append(float(np.abs(self.phi).max()))
        h["seconds"].append(time.perf_counter() - self.t0)
        h["penalized_energy"].append(self.f)

    def _objective(self) -> float:
        return self.f  # ftol applies to the penalized energy

    def _stall_message(self, gn):
        return (f"stalled at energy {self.E:.10g}: the line search found no decrease while "
                f"the gradient norm is still {gn:.3g}; {self._stall_cause()}")

    @resumable
    def step(self) -> bool:
        """Advance by one accepted iterate. Returns False once the run is finished."""
        if self.done:
            return False
        try:
            return self._step()
        except _OutOfTime:
            return self._time_up()

    def _accept(self, tau, f_prev):
        self.nit += 1
        self._record(tau)
        self._check_stop(f_prev)
        return not self.done

    def _stats(self) -> dict:
        return {
            "factorizations": self.engine.factorizations,
            "gradient_evaluations": self.evaluations,
            "rejected_steps": self.rejected,
            "vertices": self.layout.n,
            "penalized_energy": self.f,
            "max_log_stretch": float(np.abs(self.phi).max()),
            **super()._stats(),
        }

    # -- weak Wolfe line search with collision truncation --------------------------------------

    def _contact_cap(self, X, D, tau_search):
        """Largest allowed step along ``X + τD``: 2/3 of the first contact (docs/design.md, step 3),
        or ``tau_search`` when there is none before it."""
        t = self.engine.contact_time(X, -D, 1.5 * tau_search, self.eps)
        return tau_search if t >= 1.5 * tau_search else 2.0 / 3.0 * t

    def _wolfe(self, X, f, g, D, tau0, max_expand=8.0):
        """Weak Wolfe step along D from X (bisection/expansion, Lewis–Overton style).

        Returns ``(tau, Y, evaluation)`` or None. Trial steps never exceed 2/3 of the first
        contact along the line, so the straight path to every trial point is collision-free.
        """
        gd = _dot(g, D)
        if not gd < 0.0:
            return None
        tau_max = self._contact_cap(X, D, max_expand * tau0)
        tau = min(tau0, tau_max)
        lo, hi = 0.0, np.inf
        best = None
        for _ in range(50):
            self._deadline()
            Y = X + tau * D
            ev = self._evaluate(Y)
            fY, gY = ev[0], ev[2]
            if not np.isfinite(fY) or fY > f + self.c1 * tau * gd:
                hi = tau
                self.rejected += 1
            else:
                best = (tau, Y, ev)
                if _dot(gY, D) < self.c2 * gd and tau < tau_max:
                    lo = tau
                else:
                    return best
            if hi < np.inf:
                tau = 0.5 * (lo + hi)
                if (hi - lo) <= 1e-12 * hi:
                    break
            else:
                tau = min(2.0 * tau, tau_max)
            if tau * abs(gd) <= 1e-16 * abs(f):
                break
        return best


class NonlinearCG(_PenaltyRun):
    """Polak–Ribière PR+ (Nocedal–Wright §5.2) with the metric as (variable) preconditioner:
    ``β = max(0, <g₊, z₊ − z>/<g, z>)``, ``z = (metric)⁻¹ g``; restart with ``−z`` whenever
    the direction is not a descent direction."""

    NAME = "ncg"

    def _init_method(self):
        self.D = -self.z
        self.gd_prev = None

    def _step(self) -> bool:
        gd = _dot(self.g, self.D)
        if self.gd_prev is None:
            tau0 = self.tau
        else:  # Nocedal–Wright (3.60): same first-order change as the last step
            tau0 = self.tau * self.gd_prev / gd
        found = self._wolfe(self.X, self.f, self.g, self.D, tau0)
        if found is None and self.gd_prev is not None:  # restart along −z once
            self.D = -self.z
            gd = _dot(self.g, self.D)
            found = self._wolfe(self.X, self.f, self.g, self.D, self.tau)
        if found is None:
            return self._give_up(self.gz)
        tau, Y, ev = found
        z_old, gz_old, f_old = self.z, self.gz, self.f
        self._set_point(Y, ev)
        beta = max(0.0, _dot(self.g, self.z - z_old) / gz_old)
        D = -self.z + beta * self.D
        if not _dot(self.g, D) < 0.0:
            D = -self.z
        self.D = D
        self.tau = tau
        self.gd_prev = gd
        return self._accept(tau, f_old)


class LBFGS(_PenaltyRun):
    """L-BFGS (Nocedal–Wright Alg. 7.4/7.5) with ``history`` pairs and the inverse of the
    *current* metric as initial inverse Hessian (the paper's modification)."""

    NAME = "lbfgs"

    def __init__(self, P, metric="hs", max_iter=200, tol=1e-6, *, history: int = 30, **options):
        self.m = check_number("history", history, 1, integer=True)
        super().__init__(P, metric, max_iter, tol, **options)

    def _init_method(self):
        self.pairs: list[tuple[np.ndarray, np.ndarray, float]] = []
        self.first = True

    def _direction(self):
        q = self.g.copy()
        alphas = []
        for s, y, rho in reversed(self.pairs):
            a = rho * _dot(s, q)
            alphas.append(a)
            q -= a * y
        r = self.msolver.solve(q)
        for (s, y, rho), a in zip(self.pairs, reversed(alphas), strict=True):
            b = rho * _dot(y, r)
            r += (a - b) * s
        return -r

    def _step(self) -> bool:
        D = self._direction()
        tau0 = self.tau if self.first else 1.0
        found = self._wolfe(self.X, self.f, self.g, D, tau0)
        if found is None and self.pairs:  # forget the history once, retry along −z
            self.pairs.clear()
            D = -self.z
            found = self._wolfe(self.X, self.f, self.g, D, self.tau)
        if found is None:
            return self._give_up(self.gz)
        tau, Y, ev = found
        X_old, g_old, f_old = self.X, self.g, self.f
        self._set_point(Y, ev)
        s, y = Y - X_old, self.g - g_old
        sy = _dot(s, y)
        if sy > 1e-12 * np.sqrt(_dot(s, s) * _dot(y, y)):
            self.pairs.append((s, y, 1.0 / sy))
            if len(self.pairs) > self.m:
                self.pairs.pop(0)
        self.first = False
        return self._accept(tau, f_old)


class Nesterov(_PenaltyRun):
    """Nesterov's accelerated gradient (1983) in the metric, after Nesterov / O'Donoghue–Candès:

        Y = X + β (X − X_prev)   (truncated to 2/3 of the first contact along the line),
        X₊ = Y − τ (metric at Y)⁻¹ ∇f(Y)   (weak Wolfe τ, collision-truncated),

    ``β = (t_k − 1)/t_{k+1}``, ``t_{k+1} = (1 + sqrt(1 + 4 t_k²))/2``. When ``f(X₊) > f(X)``
    the momentum is reset to 0 and the step is redone from X, so the energy never rises; so it
    is when the straight segment from X to X₊ would touch itself.
    One metric factorization per iterate (at Y); the recorded gradient norm at X₊ uses that
    metric, and the metric at X is built only for a reset."""

    NAME = "nesterov"

    def _init_method(self):
        self.X_prev = self.X
        self.t = 1.0
        self.metric_at_x = True

    def _step(self) -> bool:
        X, f = self.X, self.f
        t_next = 0.5 * (1.0 + np.sqrt(1.0 + 4.0 * self.t * self.t))
        beta = (self.t - 1.0) / t_next
        M = X - self.X_prev
        found = None
        if beta > 0.0 and np.any(M):
            beta = min(beta, self._contact_cap(X, M, beta))
            Y = X + beta * M
            ev = self._evaluate(Y)
            solver = self._metric_solver(Y, ev[4])
            found = self._wolfe(Y, ev[0], ev[2], -solver.solve(ev[2]), self.tau)
            if found is not None and found[2][0] > f:
                found = None  # the energy went up: reset the momentum
            elif found is not None and not self.engine.path_is_free(X, found[1], self.eps):
                # X → Y → X₊ is collision-free by construction; the straight X → X₊ (what
                # a keyframe interpolates) must be too
                found = None
        if found is None:
            self.t = 1.0
            t_next = 1.0
            if not self.metric_at_x:
                self.msolver = self._metric_solver(X, self.jac)
                self.z = self.msolver.solve(self.g)
                self.gz = _dot(self.g, self.z)
                self.metric_at_x = True
            solver = self.msolver
            found = self._wolfe(X, f, self.g, -self.z, self.tau)
            if found is None:
                return self._give_up(self.gz)
        tau, Xn, ev = found
        self.X_prev = X
        self.t = t_next
        self.tau = tau
        self._set_point(Xn, ev, solver)
        self.metric_at_x = False
        return self._accept(tau, f)
