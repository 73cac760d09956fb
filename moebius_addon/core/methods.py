"""Further optimizers for the paper's comparison (section "Optimization methods employed",
Figs. 3 and 4), each usable with every metric.

Feasible methods keep the constraints of DESIGN.md (edge lengths, barycenter) at every iterate:

* ``projected_gradient``: the explicit projected gradient of :class:`flow.Relaxation`.
* ``projected_gradient_implicit``: backward Euler on the projected flow,
  ``G (Q − P)/τ + ∇L(Q) ⟂ T_P`` (L = E − λᵀΦ), solved inexactly by Newton–Krylov,
  back-projected, with Armijo backtracking on ``τ`` (every trial solves the implicit equation
  again: the paper's point).
* ``trust_region``: quadratic model in the 2-/3-dimensional subspace spanned by the projected
  gradient, the previous projected gradient moved to the current tangent space and, once the
  gradient is small, a truncated Newton direction; radius measured in the metric.

Both second-order methods use the Hessian of the Lagrangian ``E − λᵀΦ`` (λ the multipliers of
the saddle-point system, so that curvature of the constraint manifold is included) by forward
finite differences of the exact gradient and the exact constraint Jacobian: one extra gradient
per Hessian-vector product; no Hessian matrix is ever formed.

Infeasible methods replace the edge-length constraints by Hencky's stretch penalty

    E_α(P) = E(P) + α Σ_I log(l_I / l0_I)² l0_I

and compute gradients in the metric ``G + α DΦᵀ M DΦ`` (``M = diag(l0)``, the L² product of
edge functions; the paper leaves the penalty term out of the ``l2`` metric, and so do we by
default): ``ncg`` (Polak–Ribière PR+), ``lbfgs`` (history 30, initial inverse Hessian = inverse
of the current metric), ``nesterov`` (accelerated gradient with momentum reset when the energy
goes up), all with a weak Wolfe line search. Every trial step, the momentum step included, is
truncated by the continuous collision test, and the straight segment between two iterates is
collision-free for every method, so no method passes a strand through another (and linear
interpolation between iterates, as keyframes do, does not either).

Every run works at total length 1 around the origin, like :class:`flow.Relaxation`, and has its
interface: ``step()``, ``state()``, ``stop()``, ``result()``, ``x``, ``energy``, ``nit``,
``history`` (the Möbius energy ``E``, never the penalized one, so methods compare directly).
"""

from __future__ import annotations

import time

import numpy as np

from .collision import contact_time_x
from .constraints import jacobian, make_constraints
from .energy import energy_gradient_x
from .flow import (
    HISTORY_KEYS,
    Relaxation,
    RelaxResult,
    _check_names,
    _give_up,
    _number,
    _Run,
    _start,
)
from .linalg import spd_inverse
from .metrics import gram_x

FEASIBLE = ("projected_gradient", "projected_gradient_implicit", "trust_region")
INFEASIBLE = ("ncg", "lbfgs", "nesterov")
METHODS = FEASIBLE + INFEASIBLE

# Relaxation options that mean nothing without hard constraints; accepted (so that a caller
# can pass one option set to every method) and ignored by the penalty methods.
_FEASIBLE_ONLY = frozenset({
    "armijo", "growth", "backproject_iter", "backproject_tol", "edge_lengths", "barycenter",
    "reuse_factorization", "precision",
})
# Forward-difference displacement of a Hessian-vector product: the fastest vertex moves this
# fraction of an edge length: about 1e-7 relative error against central differences (measured
# on the trefoil and the FHW unknot), one gradient per product.
_FD_STEP = 1e-6


class _OutOfTime(Exception):
    """Raised inside a step when ``max_seconds`` runs out (one step may take many trials)."""


def _deadline(run) -> None:
    if run.max_seconds is not None and time.perf_counter() - run.t0 >= run.max_seconds:
        raise _OutOfTime


def make_run(method: str, P, metric: str = "hs", max_iter: int = 200, tol: float = 1e-6,
             **options):
    """A run object of ``method`` (see :data:`METHODS`) with :class:`flow.Relaxation`'s interface.

    Raises
    ------
    ValueError
        For an unknown method (the message lists the valid ones) or metric.
    """
    classes = {
        "projected_gradient": Relaxation,
        "projected_gradient_implicit": ImplicitProjectedGradient,
        "trust_region": TrustRegion,
        "ncg": NonlinearCG,
        "lbfgs": LBFGS,
        "nesterov": Nesterov,
    }
    if method not in classes:
        raise ValueError(f"unknown method {method!r}; choose one of {', '.join(METHODS)}")
    return classes[method](P, metric, max_iter, tol, **options)


# ------------------------------------------------------------------------------------------------
# Feasible second-order methods


class _Feasible(Relaxation):
    """Relaxation plus what the second-order methods need: multipliers and Hessian products."""

    def _prepare(self, X, E, g):
        super()._prepare(X, E, g)
        # λ of [[G, Cᵀ], [C, 0]] [u; λ] = [g; 0]: the Lagrangian gradient is g − Cᵀλ = G u
        _, self.lam = self.solver.solve(g, np.zeros(self.con.size))
        self.hess_products = getattr(self, "hess_products", 0)

    def _lagrangian_gradient(self, Y):
        _, gY = energy_gradient_x(Y, self.layout)
        return gY - jacobian(Y, self.con).rmatvec(self.lam)

    def _hess(self, Y, dLY, V):
        """``∇²L(Y) V`` by a forward difference of the exact Lagrangian gradient ``dLY`` at Y."""
        vmax = float(np.abs(V).max())
        if vmax == 0.0:
            return np.zeros_like(V)
        h = _FD_STEP * float(self.con.lengths0.mean()) / vmax
        self.hess_products += 1
        return (self._lagrangian_gradient(Y + h * V) - dLY) / h

    def _project(self, R):
        """Constraint preconditioner: ``z`` with ``G z + Cᵀμ = R``, ``C z = 0``."""
        return self.solver.solve(R, np.zeros(self.con.size))[0]

    def _gdot(self, a, b):
        return float(np.einsum("ij,ij->", a, self.solver.A @ b))

    def _pcg(self, apply_K, b, maxiter, rtol):
        """Projected preconditioned CG for ``K s = b`` on the tangent space (Gould–Hribar–
        Nocedal), preconditioner the metric. Stops at negative curvature (Steihaug).

        Returns ``(s, negative)``: the iterate and, on negative curvature in the first
        iteration, that direction (``negative`` True); ``s`` is None when nothing was found.
        """
        s = np.zeros_like(b)
        r = b.copy()
        z = self._project(r)
        rz = float(np.einsum("ij,ij->", r, z))
        if rz <= 0.0:
            return None, False
        rz0 = rz
        p = z.copy()
        for k in range(maxiter):
            _deadline(self)
            Kp = apply_K(p)
            curv = float(np.einsum("ij,ij->", p, Kp))
            if curv <= 0.0:
                return (p, True) if k == 0 else (s, False)
            a = rz / curv
            s += a * p
            r -= a * Kp
            z = self._project(r)
            rz_new = float(np.einsum("ij,ij->", r, z))
            if rz_new <= rtol * rtol * rz0:
                break
            p = z + (rz_new / rz) * p
            rz = rz_new
        return s, False

    def step(self) -> bool:
        """Advance by one accepted iterate. Returns False once the run is finished."""
        if self.done:
            return False
        # trial points far off the constraints may overflow in the back-projection; they are
        # rejected by the finiteness checks, the warnings would only be noise
        try:
            with np.errstate(over="ignore", invalid="ignore"):
                return self._step()
        except _OutOfTime:
            self._finish(False, f"time budget of {self.max_seconds:g} s used up")
            return False

    def _accept(self, Q, EQ, gQ, step):
        self.nit += 1
        E = self.E
        self._prepare(Q, EQ, gQ)
        self._record(step)
        self._check_stop(E)
        return not self.done

    def _give_up(self):
        return _give_up(self, self.gu)

    def result(self) -> RelaxResult:
        res = super().result()
        res.stats["hessian_products"] = self.hess_products
        return res


class ImplicitProjectedGradient(_Feasible):
    """Backward Euler on the projected Sobolev-gradient flow with Armijo backtracking.

    One iterate solves, for the displacement ``δ = P − Q`` in the tangent space ``T_P``,

        G δ / τ − ∇L(P − δ) ⟂ T_P        (L = E − λᵀΦ, λ at P)

    i.e. the stationarity condition of ``min L(P − δ) + |δ|²_G / (2τ)``, by at most
    ``newton_iter`` Newton steps whose systems ``(∇²L + G/τ) s = …`` are solved by projected
    CG (``cg_iter`` Hessian products at most, relative tolerance ``cg_rtol``). ``Q`` is then
    back-projected onto the constraints (DESIGN.md, step 4), its straight path checked for
    contact, and accepted by Armijo ``E(Q) ≤ E(P) − σ <∇E, δ>``; otherwise ``τ`` is halved and
    the implicit equation solved again. The first trial is ``growth`` times the last accepted τ.

    Extra options: ``newton_iter`` [2], ``cg_iter`` [10], ``cg_rtol`` [0.1], ``armijo``
    [1e-4 here: a Newton step on a quadratic decreases E by exactly ½<∇E, δ> as τ → ∞].
    """

    def __init__(self, P, metric="hs", max_iter=200, tol=1e-6, *, newton_iter: int = 2,
                 cg_iter: int = 10, cg_rtol: float = 0.1, armijo: float = 1e-4, **options):
        self.newton_iter = int(newton_iter)
        self.cg_iter = int(cg_iter)
        self.cg_rtol = float(cg_rtol)
        # the explicit method's default growth (8) suits the collision-bounded first trial;
        # the implicit step starts from growth × τ alone, measured with 1.5 (bench/paper.py)
        options.setdefault("growth", 1.5)
        super().__init__(P, metric, max_iter, tol, armijo=armijo, **options)

    def _implicit_point(self, tau):
        X = self.X
        A = self.solver.A
        delta = np.zeros_like(X)
        dL = self.g - self.jac.rmatvec(self.lam)  # = G u
        for k in range(self.newton_iter):
            if k:  # Lagrangian gradient at the current Newton iterate
                dL = self._lagrangian_gradient(X - delta)
                if not np.all(np.isfinite(dL)):
                    return None
            Y = X - delta
            rhs = dL - (A @ delta) / tau

            def apply_K(V, Y=Y, dL=dL):
                return self._hess(Y, dL, V) + (A @ V) / tau

            s, negative = self._pcg(apply_K, rhs, self.cg_iter, self.cg_rtol)
            if s is None or negative or not np.all(np.isfinite(s)):
                return None
            delta = delta + s
        return delta

    def _step(self) -> bool:
        X, E, g = self.X, self.E, self.g
        tau = self.growth * self.tau
        if self.nit == 0:  # first trial: no further than 2/3 of the explicit step's contact
            t_star = contact_time_x(X, self.u, self.layout, 1.5 * tau, self.eps)
            tau = min(tau, 2.0 / 3.0 * t_star)
        for _ in range(60):
            _deadline(self)
            delta = self._implicit_point(tau)
            if delta is not None:
                gd = float(np.einsum("ij,ij->", g, delta))
                Q, ok = self._backproject(X - delta)
                if ok and gd > 0 and contact_time_x(X, X - Q, self.layout, 1.0, self.eps) >= 1.0:
                    EQ, gQ = energy_gradient_x(Q, self.layout)
                    if EQ <= E - self.armijo * gd:
                        self.tau = tau
                        return self._accept(Q, EQ, gQ, tau)
            self.rejected += 1
            tau *= 0.5
            if tau * self.gu <= 1e-15 * abs(E):
                break
        return self._give_up()


def _trust_subproblem(B: np.ndarray, c: np.ndarray, radius: float) -> np.ndarray:
    """Exact minimizer of ``cᵀy + ½ yᵀBy`` over ``|y| ≤ radius`` (small dense B)."""
    if radius <= 0.0:
        return np.zeros_like(c)
    lam, Q = np.linalg.eigh(B)
    cq = Q.T @ c
    lo = lam[0]
    if lo > 0:
        y = -cq / lam
        if np.linalg.norm(y) <= radius:
            return Q @ y

    def norm_at(mu):
        return float(np.linalg.norm(cq / (lam + mu)))

    mu_lo = max(0.0, -lo)
    # hard case: c has (almost) no component along the lowest eigenvector
    if lo <= 0 and abs(cq[0]) <= 1e-12 * (np.linalg.norm(cq) + 1e-300):
        mask = lam > lam[0] + 1e-14 * (abs(lam).max() + 1e-300)
        y = np.zeros_like(cq)
        y[mask] = -cq[mask] / (lam[mask] + mu_lo)
        rest = radius**2 - float(y @ y)
        if rest > 0:
            y[0] = np.sqrt(rest)
            return Q @ y
    mu_hi = mu_lo + np.linalg.norm(c) / radius + 1.0
    while norm_at(mu_hi) > radius:
        mu_hi *= 2.0
    mu_lo = mu_lo + 1e-300
    for _ in range(200):
        mid = 0.5 * (mu_lo + mu_hi)
        if norm_at(mid) > radius:
            mu_lo = mid
        else:
            mu_hi = mid
        if mu_hi - mu_lo <= 1e-13 * mu_hi:
            break
    return Q @ (-cq / (lam + mu_hi))


class TrustRegion(_Feasible):
    """Subspace trust-region method (the paper's blend of a trust-region method with a
    two-dimensional subspace method, without eigenvalue computations).

    The model ``E + <∇E, s> + ½ <s, ∇²L s>`` is minimized over ``|s|_G ≤ Δ`` within the span of
    the projected gradient, the previous projected gradient moved to the current tangent space,
    and, once ``sqrt(<g,u>)`` is below ``newton_rtol`` times its start value, a truncated
    Newton direction (projected CG, ``cg_iter`` Hessian products at most). Steps are
    back-projected (DESIGN.md, step 4) and collision-checked; the radius shrinks to 2/3 of the
    first contact along a trial step. ``history["step"]`` holds ``|s|_G``.

    Extra options: ``newton_rtol`` [1e-2], ``cg_iter`` [20], ``cg_rtol`` [1e-2],
    ``eta`` [0.1] acceptance ratio.
    """

    def __init__(self, P, metric="hs", max_iter=200, tol=1e-6, *, newton_rtol: float = 1e-2,
                 cg_iter: int = 20, cg_rtol: float = 1e-2, eta: float = 0.1, **options):
        self.newton_rtol = float(newton_rtol)
        self.cg_iter = int(cg_iter)
        self.cg_rtol = float(cg_rtol)
        self.eta = float(eta)
        self.u_prev = None
        super().__init__(P, metric, max_iter, tol, **options)
        self.gn0 = float(np.sqrt(max(self.gu, 0.0)))
        self.radius = float(options.get("initial_step", 1.0)) * self.gn0

    def _newton_direction(self, dL):
        s, _ = self._pcg(lambda V: self._hess(self.X, dL, V), -dL, self.cg_iter, self.cg_rtol)
        return s

    def _basis(self, dL):
        u = self.u
        dirs = [-u]
        if self.u_prev is not None:
            dirs.append(-self._project(self.solver.A @ self.u_prev))
        if np.sqrt(max(self.gu, 0.0)) <= self.newton_rtol * self.gn0:
            nd = self._newton_direction(dL)
            if nd is not None:
                dirs.append(nd)
        V = []
        for d in dirs:  # Gram–Schmidt in the metric, twice
            w = d.copy()
            for _ in range(2):
                for v in V:
                    w -= self._gdot(v, w) * v
            nw = np.sqrt(max(self._gdot(w, w), 0.0))
            if nw > 1e-8 * np.sqrt(max(self._gdot(d, d), 1e-300)):
                V.append(w / nw)
        return V

    def _step(self) -> bool:
        X, E, g = self.X, self.E, self.g
        dL = g - self.jac.rmatvec(self.lam)
        V = self._basis(dL)
        k = len(V)
        HV = [self._hess(X, dL, v) for v in V]
        c = np.array([float(np.einsum("ij,ij->", g, v)) for v in V])
        B = np.array([[float(np.einsum("ij,ij->", V[i], HV[j])) for j in range(k)]
                      for i in range(k)])
        B = 0.5 * (B + B.T)
        truncated = False
        for _ in range(60):
            _deadline(self)
            y = _trust_subproblem(B, c, self.radius)
            ny = float(np.linalg.norm(y))
            pred = -float(c @ y + 0.5 * y @ B @ y)
            S = sum(yi * v for yi, v in zip(y, V, strict=True))
            if pred <= 1e-15 * abs(E) or ny == 0.0:
                break
            t_star = contact_time_x(X, -S, self.layout, 1.0, self.eps)
            if t_star < 1.0:
                if t_star == 0.0:  # already in contact along this step: jammed
                    break
                self.radius = 2.0 / 3.0 * t_star * ny
                self.rejected += 1
                truncated = True
                continue
            Q, ok = self._backproject(X + S)
            if ok and contact_time_x(X, X - Q, self.layout, 1.0, self.eps) >= 1.0:
                EQ, gQ = energy_gradient_x(Q, self.layout)
                rho = (E - EQ) / pred
            else:
                rho = -np.inf
            if rho < 0.25:
                self.radius = 0.25 * ny
            elif rho > 0.75 and ny >= 0.99 * self.radius:
                self.radius = 2.0 * self.radius
            if rho > self.eta and EQ < E:
                # a step cut short by a contact drops the momentum direction next time, so
                # that it does not keep pushing the same strands together
                self.u_prev = None if truncated else self.u
                return self._accept(Q, EQ, gQ, ny)
            self.rejected += 1
            if self.radius <= 1e-15 * max(self.gn0, 1e-300):
                break
        return self._give_up()


# ------------------------------------------------------------------------------------------------
# Infeasible (penalty) methods


class _PenaltyMetric:
    """Solver of ``(A ⊗ I₃ + α Cᵀ diag(l0) C) z = g`` (C: edge rows of DΦ) by Woodbury:

        z = G⁻¹g − G⁻¹Cᵀ (C G⁻¹ Cᵀ + diag(1/(α l0)))⁻¹ C G⁻¹ g

    with ``C G⁻¹ Cᵀ = (D A⁻¹ Dᵀ) ∘ (T Tᵀ)`` as in :mod:`linalg` (O(N²) once A⁻¹ is known)."""

    def __init__(self, A, jac, alpha, lengths0, penalty):
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

    def solve(self, g):
        z = self.Ainv @ g
        if self.Kinv is not None:
            z = z - self.Ainv @ self.jac.rmatvec(self.Kinv @ self.jac.matvec(z))
        return z


def _dot(a, b) -> float:
    return float(np.einsum("ij,ij->", a, b))


class _PenaltyRun(_Run):
    """Common state of the infeasible methods: normalization, penalty, metric, Wolfe search.

    Parameters (besides ``P, metric, max_iter, tol`` as in :class:`flow.Relaxation`)
    ----------
    alpha : float
        Weight of Hencky's stretch penalty, in units where the total length is 1.
    penalty_metric : {"auto", True, False}
        Add ``α DΦᵀ M DΦ`` to the metric; "auto": for every metric except ``l2`` (the paper).
    c1, c2 : float
        Weak Wolfe constants (sufficient decrease, curvature).
    energy_target, ftol, max_seconds, initial_step, target_lengths, check
        As in :class:`flow.Relaxation`; ``ftol`` applies to the penalized energy.
    """

    _GRADIENT = "gradient norm"

    def __init__(self, P, metric="hs", max_iter=200, tol=1e-6, *, alpha: float = 1e4,
                 penalty_metric="auto", c1: float = 1e-4, c2: float = 0.9,
                 energy_target: float | None = None, ftol: float = 1e-12,
                 max_seconds: float | None = None, initial_step: float = 1.0,
                 target_lengths: str = "equal", check: bool = True, **ignored):
        unknown = set(ignored) - _FEASIBLE_ONLY
        if unknown:
            raise TypeError(f"unknown option(s) {', '.join(sorted(unknown))}")
        _check_names(metric, target_lengths)
        if not 0 < c1 < c2 < 1:
            raise ValueError("Wolfe constants need 0 < c1 < c2 < 1")
        alpha = _number("alpha", alpha, 0)
        initial_step = _number("initial_step", initial_step, 0, above=True)
        # the penalty pulls a non-equilateral start to the mean lengths: no equilateral check
        Xn, lengths0 = _start(self, P, metric, max_iter, tol, energy_target, ftol, max_seconds,
                              target_lengths, check, equilateral=False)
        layout = self.layout
        self.alpha = float(alpha)
        self.penalty_in_metric = (metric != "l2") if penalty_metric == "auto" else bool(
            penalty_metric)
        self.c1, self.c2 = float(c1), float(c2)
        self.lengths0 = lengths0
        self.con = make_constraints(Xn, layout, lengths0, True, False)
        self.eps = 1e-3 * float(lengths0.mean())
        self.tau = float(initial_step)
        self.nit = 0
        self.rejected = 0
        self.evaluations = 0
        self.factorizations = 0
        self.done = False
        self.success = False
        self.message = ""
        self.history = {k: [] for k in (*HISTORY_KEYS, "penalized_energy")}
        self._set_point(Xn, self._evaluate(Xn))
        self._init_method()
        self._record(0.0)
        self._check_stop(None)

    # -- objective and metric ----------------------------------------------------------------

    def _evaluate(self, Y):
        """``(f, E, ∇f, φ)`` at Y: penalized energy, Möbius energy, gradient, log-stretches."""
        self.evaluations += 1
        E, g = energy_gradient_x(Y, self.layout)
        jac = jacobian(Y, self.con)
        lay = self.layout
        ln = np.linalg.norm(Y[lay.nxt] - Y, axis=1)
        phi = np.log(ln) - np.log(self.lengths0)
        f = E + self.alpha * float(np.sum(self.lengths0 * phi * phi))
        g = g + jac.rmatvec(2.0 * self.alpha * self.lengths0 * phi)
        return f, E, g, phi, jac

    def _metric_solver(self, Y, jac):
        self.factorizations += 1
        return _PenaltyMetric(gram_x(self.metric, Y, self.layout), jac, self.alpha,
                              self.lengths0, self.penalty_in_metric)

    def _set_point(self, Y, ev, solver=None):
        """Move to Y with its evaluation and the metric gradient there (with ``solver``, a
        metric built elsewhere, if given)."""
        self.X = Y
        self.f, self.E, self.g, self.phi, self.jac = ev
        self.msolver = solver if solver is not None else self._metric_solver(Y, self.jac)
        self.z = self.msolver.solve(self.g)
        self.gz = _dot(self.g, self.z)

    def _init_method(self):
        pass

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
        return (
            f"stalled at energy {self.E:.10g}: the line search found no decrease while the "
            f"gradient norm is still {gn:.3g}; strands are probably jammed — use more edges"
        )

    def _give_up(self):
        return _give_up(self, self.gz)

    def step(self) -> bool:
        """Advance by one accepted iterate. Returns False once the run is finished."""
        if self.done:
            return False
        try:
            return self._step()
        except _OutOfTime:
            self._finish(False, f"time budget of {self.max_seconds:g} s used up")
            return False

    def _accept(self, tau, f_prev):
        self.nit += 1
        self._record(tau)
        self._check_stop(f_prev)
        return not self.done

    def result(self) -> RelaxResult:
        if not self.done:
            self.stop("not finished (result taken early)")
        return RelaxResult(
            x=self.x, fun=self.E, nit=self.nit, success=self.success, message=self.message,
            history={k: list(v) for k, v in self.history.items()}, metric=self.metric,
            stats={
                "factorizations": self.factorizations,
                "gradient_evaluations": self.evaluations,
                "rejected_steps": self.rejected,
                "vertices": self.layout.n,
                "penalized_energy": self.f,
                "max_log_stretch": float(np.abs(self.phi).max()),
            },
        )

    # -- weak Wolfe line search with collision truncation --------------------------------------

    def _contact_cap(self, X, D, tau_search):
        """Largest allowed step along ``X + τD``: 2/3 of the first contact (DESIGN.md, step 3),
        or ``tau_search`` when there is none before it."""
        t = contact_time_x(X, -D, self.layout, 1.5 * tau_search, self.eps)
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
            _deadline(self)
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
            return self._give_up()
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

    def __init__(self, P, metric="hs", max_iter=200, tol=1e-6, *, history: int = 30, **options):
        self.m = int(history)
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
            return self._give_up()
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
            elif found is not None and contact_time_x(X, X - found[1], self.layout, 1.0,
                                                      self.eps) < 1.0:
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
                return self._give_up()
        tau, Xn, ev = found
        self.X_prev = X
        self.t = t_next
        self.tau = tau
        self._set_point(Xn, ev, solver)
        self.metric_at_x = False
        return self._accept(tau, f)
