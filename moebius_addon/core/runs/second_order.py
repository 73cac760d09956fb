"""Feasible second-order methods of the paper's comparison (section "Optimization methods
employed", Figs. 3 and 4), each usable with every metric; they keep the constraints of
docs/design.md (edge lengths, barycenter) at every iterate, like :class:`.projected.Relaxation`:

* ``projected_gradient_implicit``: backward Euler on the projected flow,
  ``G (Q − P)/τ + ∇L(Q) ⟂ T_P`` (L = E − λᵀΦ), solved inexactly by Newton–Krylov,
  back-projected, with Armijo backtracking on ``τ`` (every trial solves the implicit equation
  again: the paper's point).
* ``trust_region``: quadratic model in the 2-/3-dimensional subspace spanned by the projected
  gradient, the previous projected gradient moved to the current tangent space and, once the
  gradient is small, a truncated Newton direction; radius measured in the metric.

Both use the Hessian of the Lagrangian ``E − λᵀΦ`` (λ the multipliers of the saddle-point
system, so that curvature of the constraint manifold is included) by forward finite
differences of the exact gradient and the exact constraint Jacobian: one extra gradient per
Hessian-vector product; no Hessian matrix is ever formed.
"""

from __future__ import annotations

import numpy as np

from ..geometry.constraints import jacobian, residual
from ._interrupts import resumable
from .base import _OutOfTime, check_number
from .projected import Relaxation

# Forward-difference displacement of a Hessian-vector product: the fastest vertex moves this
# fraction of an edge length: about 1e-7 relative error against central differences (measured
# on the trefoil and the FHW unknot), one gradient per product.
_FD_STEP = 1e-6


class _Feasible(Relaxation):
    """Relaxation plus what the second-order methods need: multipliers and Hessian products.

    Their own step rules replace the explicit method's line search, so its ``interpolate``
    option is refused here rather than ignored.
    """

    _LENGTH_GROWTH = False  # the growth rides on the explicit method's line search

    def __init__(self, P, metric, max_iter, tol, *, interpolate: bool = False, **options):
        if interpolate:
            raise ValueError(
                f"interpolate shapes the line search of projected_gradient only; "
                f"{type(self).__name__} chooses its steps otherwise: leave it False"
            )
        super().__init__(P, metric, max_iter, tol, **options)

    def _prepare(self, X, E, g):
        # Relaxation._prepare's steps 1–2, keeping λ of the one saddle-point solve
        # [[G, Cᵀ], [C, 0]] [u; λ] = [g; 0] (the Lagrangian gradient is g − Cᵀλ = G u): calling
        # it and solving again for λ doubled the solves and the Krylov iterations per iterate
        # committed whole at the end, as Relaxation._prepare
        jac = jacobian(X, self.con)
        self.engine.update(X, jac)
        u, lam = self.engine.solve(g, np.zeros(self.con.size))
        phi = residual(X, self.con)
        self.X, self.E, self.g, self.jac, self.u, self.lam, self.phi = X, E, g, jac, u, lam, phi
        self.gu = float(np.einsum("ij,ij->", g, u))
        self._gnorm = float(np.linalg.norm(g))
        self.hess_products = getattr(self, "hess_products", 0)

    def _lagrangian_gradient(self, Y):
        _, gY = self.engine.energy_gradient(Y)
        return gY - jacobian(Y, self.con).rmatvec(self.lam)

    def _hess(self, Y, dLY, V):
        """``∇²L(Y) V`` by a forward difference of the exact Lagrangian gradient ``dLY`` at Y."""
        vmax = float(np.abs(V).max())
        if vmax == 0.0:
            return np.zeros_like(V)
        h = _FD_STEP * float(self.con.lengths0.mean()) / vmax
        self.hess_products += 1
        return (self._lagrangian_gradient(Y + h * V) - dLY) / h

    def _tangent_solve(self, R):
        """Constraint preconditioner: ``z`` with ``G z + Cᵀμ = R``, ``C z = 0``."""
        return self.engine.solve(R, np.zeros(self.con.size))[0]

    def _gdot(self, a, b):
        return float(np.einsum("ij,ij->", a, self.engine.metric_product(b)))

    def _pcg(self, apply_K, b, maxiter, rtol):
        """Projected preconditioned CG for ``K s = b`` on the tangent space (Gould–Hribar–
        Nocedal), preconditioner the metric. Stops at negative curvature (Steihaug).

        Returns ``(s, negative)``: the iterate and, on negative curvature in the first
        iteration, that direction (``negative`` True); ``s`` is None when nothing was found.
        """
        s = np.zeros_like(b)
        r = b.copy()
        z = self._tangent_solve(r)
        rz = float(np.einsum("ij,ij->", r, z))
        if rz <= 0.0:
            return None, False
        rz0 = rz
        p = z.copy()
        for k in range(maxiter):
            self._deadline()
            Kp = apply_K(p)
            curv = float(np.einsum("ij,ij->", p, Kp))
            if curv <= 0.0:
                return (p, True) if k == 0 else (s, False)
            a = rz / curv
            s += a * p
            r -= a * Kp
            z = self._tangent_solve(r)
            rz_new = float(np.einsum("ij,ij->", r, z))
            if rz_new <= rtol * rtol * rz0:
                break
            p = z + (rz_new / rz) * p
            rz = rz_new
        return s, False

    @resumable
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
            return self._time_up()

    def _accept(self, Q, EQ, gQ, step):
        E = self.E
        self._prepare(Q, EQ, gQ)
        self.nit += 1
        self._record(step)
        self._check_stop(E)
        return not self.done

    def _stats(self) -> dict:
        return {**super()._stats(), "hessian_products": self.hess_products}


class ImplicitProjectedGradient(_Feasible):
    """Backward Euler on the projected Sobolev-gradient flow with Armijo backtracking.

    One iterate solves, for the displacement ``δ = P − Q`` in the tangent space ``T_P``,

        G δ / τ − ∇L(P − δ) ⟂ T_P        (L = E − λᵀΦ, λ at P)

    i.e. the stationarity condition of ``min L(P − δ) + |δ|²_G / (2τ)``, by at most
    ``newton_iter`` Newton steps whose systems ``(∇²L + G/τ) s = …`` are solved by projected
    CG (``cg_iter`` Hessian products at most, relative tolerance ``cg_rtol``). ``Q`` is then
    back-projected onto the constraints (docs/design.md, step 4), its straight path checked for
    contact, and accepted by Armijo ``E(Q) ≤ E(P) − σ <∇E, δ>``; otherwise ``τ`` is halved and
    the implicit equation solved again. The first trial is ``growth`` times the last accepted τ.

    Extra options: ``newton_iter`` [2], ``cg_iter`` [10], ``cg_rtol`` [0.1], ``armijo``
    [1e-4 here: a Newton step on a quadratic decreases E by exactly ½<∇E, δ> as τ → ∞].
    """

    NAME = "projected_gradient_implicit"

    def __init__(self, P, metric="hs", max_iter=200, tol=1e-6, *, newton_iter: int = 2,
                 cg_iter: int = 10, cg_rtol: float = 0.1, armijo: float = 1e-4, **options):
        self.newton_iter = check_number("newton_iter", newton_iter, 1, integer=True)
        self.cg_iter = check_number("cg_iter", cg_iter, 1, integer=True)
        self.cg_rtol = check_number("cg_rtol", cg_rtol, 0, above=True)
        # the explicit method's default growth (8) suits the collision-bounded first trial;
        # the implicit step starts from growth × τ alone, measured with 1.5 (bench/paper.py)
        options.setdefault("growth", 1.5)
        super().__init__(P, metric, max_iter, tol, armijo=armijo, **options)

    def _implicit_point(self, tau):
        X = self.X
        delta = np.zeros_like(X)
        dL = self.g - self.jac.rmatvec(self.lam)  # = G u
        for k in range(self.newton_iter):
            if k:  # Lagrangian gradient at the current Newton iterate
                dL = self._lagrangian_gradient(X - delta)
                if not np.all(np.isfinite(dL)):
                    return None
            Y = X - delta
            rhs = dL - self.engine.metric_product(delta) / tau

            def apply_K(V, Y=Y, dL=dL):
                return self._hess(Y, dL, V) + self.engine.metric_product(V) / tau

            s, negative = self._pcg(apply_K, rhs, self.cg_iter, self.cg_rtol)
            if s is None or negative or not np.all(np.isfinite(s)):
                return None
            delta = delta + s
        return delta

    def _step(self) -> bool:
        X, E, g = self.X, self.E, self.g
        tau = self.growth * self.tau
        if self.nit == 0:  # first trial: no further than 2/3 of the explicit step's contact
            t_star = self.engine.contact_time(X, self.u, 1.5 * tau, self.eps)
            tau = min(tau, 2.0 / 3.0 * t_star)
        for _ in range(60):
            self._deadline()
            delta = self._implicit_point(tau)
            if delta is not None:
                gd = float(np.einsum("ij,ij->", g, delta))
                Q, ok = self._backproject(X - delta)
                if ok and gd > 0 and self.engine.path_is_free(X, Q, self.eps):
                    EQ, gQ = self.engine.energy_gradient(Q)
                    if EQ <= E - self.armijo * gd:
                        self.tau = tau
                        return self._accept(Q, EQ, gQ, tau)
            self.rejected += 1
            tau *= 0.5
            if tau * self.gu <= 1e-15 * abs(E):
                break
        return self._give_up(self.gu)


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
    back-projected (docs/design.md, step 4) and collision-checked; the radius shrinks to 2/3 of the
    first contact along a trial step. ``history["step"]`` holds ``|s|_G``.

    Extra options: ``newton_rtol`` [1e-2], ``cg_iter`` [20], ``cg_rtol`` [1e-2],
    ``eta`` [0.1] acceptance ratio.
    """

    NAME = "trust_region"

    def __init__(self, P, metric="hs", max_iter=200, tol=1e-6, *, newton_rtol: float = 1e-2,
                 cg_iter: int = 20, cg_rtol: float = 1e-2, eta: float = 0.1, **options):
        self.newton_rtol = check_number("newton_rtol", newton_rtol, 0)
        self.cg_iter = check_number("cg_iter", cg_iter, 1, integer=True)
        self.cg_rtol = check_number("cg_rtol", cg_rtol, 0, above=True)
        self.eta = check_number("eta", eta, 0)
        if not self.eta < 1:
            raise ValueError(f"eta must lie in [0, 1) (the share of the predicted decrease a "
                             f"step must achieve), got {eta!r}")
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
            dirs.append(-self._tangent_solve(self.engine.metric_product(self.u_prev)))
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
            self._deadline()
            y = _trust_subproblem(B, c, self.radius)
            ny = float(np.linalg.norm(y))
            pred = -float(c @ y + 0.5 * y @ B @ y)
            S = sum(yi * v for yi, v in zip(y, V, strict=True))
            if pred <= 1e-15 * abs(E) or ny == 0.0:
                break
            t_star = self.engine.contact_time(X, -S, 1.0, self.eps)
            if t_star < 1.0:
                if t_star == 0.0:  # already in contact along this step: jammed
                    break
                self.radius = 2.0 / 3.0 * t_star * ny
                self.rejected += 1
                truncated = True
                continue
            Q, ok = self._backproject(X + S)
            if ok and self.engine.path_is_free(X, Q, self.eps):
                EQ, gQ = self.engine.energy_gradient(Q)
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
        return self._give_up(self.gu)
