"""What every run shares, whatever its method: the options, the start checked and scaled, the
stopping rules with their status codes, the state a caller sees, and the result.

A run works on a copy of the start scaled to total length 1 and centred at the origin, so
tolerances mean the same for every size; ``x`` and the result are mapped back. Every run
reaches the numerics (energy, gradient, metric, saddle-point solves, contact times) through
one engine object (:mod:`..engine`), chosen by name with ``engine=``.

Status codes (``RelaxResult.status``, in the spirit of ``scipy.optimize.OptimizeResult``):

====  ==================  ==============================================================
code  name                meaning
====  ==================  ==============================================================
0     ``CONVERGED``       gradient norm below ``tol``, relative change below ``ftol``, or
                          no further decrease above round-off
1     ``TARGET``          the energy reached ``energy_target``
2     ``MAX_ITER``        ``max_iter`` accepted iterations
3     ``TIME``            the ``max_seconds`` budget is used up
4     ``STALLED``         steps collapsed with the gradient still large (jammed strands)
5     ``STOPPED``         stopped by the caller (``stop()``) or a callback
6     ``NOT_FINISHED``    result taken before the run finished (also: still running)
====  ==================  ==============================================================
"""

from __future__ import annotations

import enum
import os
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from ..energies.choice import DEFAULT_ENERGY, check_run_energy, take_energy_options
from ..geometry.container import check_container, check_inside
from ..geometry.edge_pairs import SLACK
from ..geometry.layout import as_unit_layout
from ..geometry.obstacles import ObstacleField, auto_obstacle_tol, check_obstacles
from ..geometry.pins import check_pins
from ..geometry.polygon import CheckedCurve, check_curve, check_layout, layout_contact_ratio
from ..geometry.thickness import check_thickness, closest_tested, near_counts
from ..metrics.gram import METRICS
from ..metrics.pinned_solve import TREE_MAX_PINS
from .checks import (
    check_flag,
    check_number,
)
from .engine import make_engine
from .growth import DEFAULT_LENGTH_GROWTH, LengthGrowth

HISTORY_KEYS = ("energy", "step", "grad_norm", "constraint_residual", "seconds")

#: A stalled curve nearer than this many edge lengths to an obstacle, or strands this near
#: each other, are said to be pressed together (:meth:`Run._stall_cause`).
STALL_CONTACT = 1.0
#: The largest ``obstacle_weight``: the obstacle energy of a curve near a mesh reaches 1e9 and
#: more, and 1e300 times it made the gradient NaN (a trefoil stalled at once, energy 6.3e302).
MAX_OBSTACLE_WEIGHT = 1e6
#: ``push_apart`` keeps tubes this much thinner than the start allows (beside the contact
#: test's own margin ``SLACK``), so that the first step has room.
PUSH_MARGIN = 1.01
#: Iterations in a row without visible motion that end a run with ``settle`` set.
SETTLE_ITERATIONS = 5
# A run that stops moving with a projected gradient above this many times tol is jammed, not
# converged (near the minimum Armijo fails on round-off with sqrt(<g,u>) ≈ 1e-8, docs/design.md).
_STALL_FACTOR = 1e3
# Farthest a vertex may lie from the centre, in shortest edge lengths (Run._check_reach): a
# circle of N edges reaches N/2π, so one curve meets it only beyond 6·10⁶ edges.
MAX_REACH = 1e6
# Memory a run holds at its peak, in bytes per vertex pair: the Gram matrix (float64), the
# inverse from its factorization and the Schur complement, all N × N (measured peak at 3000
# vertices: 17.4 bytes per pair in single precision, 25.2 in double; with room for more).
_BYTES_PER_PAIR = 32
# Tubes closer than this many times their contact distance touch (Run.tubes_touch): the
# steps approach a contact by a third of the gap each, and stop within 0.1 % (_pairs.SLACK).
_TOUCH = 1.01
# Share of the machine's physical memory a run may need before it is refused.
_MEMORY_SHARE = 0.75
# Largest polygon whose dense factorization runs: numpy's bundled OpenBLAS (numpy 1.26, 2 threads)
# segfaults in a double-precision Cholesky (np.linalg.cholesky, LAPACK potrf) of an SPD matrix
# at 16 000 and 17 000 rows and factors 15 000 (21 s); single-threaded, 17 000 works. Every
# engine's saddle-point solve is dense today, so every run is bounded by this.
DENSE_MAX_VERTICES = 15000


class Status(enum.IntEnum):
    """Why a run stopped: ``RelaxResult.status`` (see the module docstring for the table)."""

    CONVERGED = 0
    TARGET = 1
    MAX_ITER = 2
    TIME = 3
    STALLED = 4
    STOPPED = 5
    NOT_FINISHED = 6


@dataclass
class IterationState:
    """What a callback sees after every accepted iterate (and what a run exposes)."""

    nit: int
    x: object  # polygon (N, 3) or list of arrays, in the caller's coordinates
    energy: float
    step: float
    grad_norm: float
    constraint_residual: float
    seconds: float


@dataclass
class RelaxResult:
    """Outcome of a run, in the spirit of ``scipy.optimize.OptimizeResult``: ``message`` says
    why it stopped in words, ``status`` (a :class:`Status`) in a number to decide on."""

    x: object
    #: the energy of ``x``: on the tree engine up to ``engine.EXACT_RESULT_MAX`` vertices the
    #: exact sum (the tree's value, which the run saw, is ``stats["run_energy"]`` and the
    #: history's last); on the exact engine the run's own value
    fun: float
    nit: int
    success: bool
    message: str
    status: int
    history: dict = field(default_factory=dict)
    metric: str = "hs"
    stats: dict = field(default_factory=dict)
    #: refinements of the run (``refine=``): iteration, ``edges_before``, ``edges_after``,
    #: ``reason`` (and the energies before and after for a jam); empty for a plain run
    refinements: list = field(default_factory=list)
    #: the energy minimized: ``"moebius"`` or ``"tangent_point(α, β)"``
    #: (``energy_choice.EnergyChoice.label``)
    energy: str = DEFAULT_ENERGY

    def __repr__(self) -> str:
        return (
            f"RelaxResult(fun={self.fun:.10g}, nit={self.nit}, success={self.success}, "
            f"status={int(self.status)}, message={self.message!r})"
        )


def _check_names(metric: str, target_lengths: str) -> None:
    if metric not in METRICS:
        raise ValueError(f"unknown metric {metric!r}; choose one of {', '.join(METRICS)}")
    if target_lengths not in ("equal", "keep"):
        raise ValueError("target_lengths must be 'equal' or 'keep'")


def _physical_memory() -> float | None:
    """Bytes of physical memory, or None where the system does not say (Windows)."""
    try:
        return float(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    except (AttributeError, ValueError, OSError):
        return None


#: Why a run holds its metric as a dense matrix, and the way out the refusal names.
_DENSE_WHY = {
    "engine": "or run on the tree engine (engine='tree' or 'auto'), which stores nothing dense",
    "method": "or use a feasible method (projected_gradient, projected_gradient_implicit, "
              "trust_region) on the tree engine: the penalty methods (ncg, lbfgs, nesterov) "
              "hold the metric as a dense matrix on every engine",
    "constraints": "or keep both constraints (edge_lengths and barycenter): without them the "
                   "tree engine solves with a dense matrix",
    "pins": f"or pin at most {TREE_MAX_PINS} vertices: with more the tree engine solves "
            f"with a dense matrix",
}


def check_dense_size(n: int, why: str = "engine") -> None:
    """Refuse a polygon whose dense N × N matrices would not fit in memory (an absurd size:
    a machine swapping or killed by the out-of-memory handler says nothing useful), or whose
    dense factorization would crash the process (``DENSE_MAX_VERTICES``). ``why`` the run is
    dense (a key of ``_DENSE_WHY``) chooses the way out the message names."""
    if n > DENSE_MAX_VERTICES:
        raise ValueError(
            f"{n} vertices are more than the dense metric's factorization handles "
            f"({DENSE_MAX_VERTICES}: numpy's multithreaded OpenBLAS Cholesky crashes the process "
            f"from about 16 000 on): resample to at most {DENSE_MAX_VERTICES} vertices "
            f"(core.resample(P, n); a few hundred are plenty to untangle a knot), "
            f"{_DENSE_WHY[why]}"
        )
    total = _physical_memory()
    need = _BYTES_PER_PAIR * float(n) ** 2
    if total is None or need <= _MEMORY_SHARE * total:
        return
    most = int(np.sqrt(_MEMORY_SHARE * total / _BYTES_PER_PAIR))
    raise ValueError(
        f"{n} vertices need about {need / 1e9:.1f} GB for the dense metric and its "
        f"factorization (memory grows as N²), more than this machine's "
        f"{total / 1e9:.1f} GB allow: resample to at most {most} vertices "
        f"(core.resample(P, n)); a few hundred are plenty to untangle a knot), "
        f"{_DENSE_WHY[why]}"
    )


class _OutOfTime(Exception):
    """Raised inside a step when ``max_seconds`` runs out (one step may take many trials)."""


def _mesh_labels(obstacles, container):
    """What messages call each obstacle and the container: ``(obstacle labels, obstacles as a
    list, container label, container)``. Given as a mapping (name → ``(V, F)``, one entry for
    the container), they are called by their names (a Blender object's), else by position."""
    if isinstance(obstacles, Mapping):
        labels = [f"obstacle '{name}'" for name in obstacles]
        obstacles = list(obstacles.values())
    else:
        count = 1 if isinstance(obstacles, tuple) and len(obstacles) == 2 and not isinstance(
            obstacles[0], tuple) else len(obstacles) if isinstance(obstacles, Sequence) else 0
        labels = [f"obstacle {m}" for m in range(count)]
    label = "the container"
    if isinstance(container, Mapping):
        if len(container) != 1:
            raise ValueError(f"container given as a mapping must name one mesh, got "
                             f"{len(container)}")
        ((name, container),) = container.items()
        label = f"the container '{name}'"
    return labels, obstacles, label, container


class Run:
    """Set-up and stopping rules shared by every method (:mod:`.projected`,
    :mod:`.second_order`, :mod:`.penalty`).

    The constructor checks the shared options, checks the start and scales it to total length
    1 around the origin (``X``; results are mapped back), sets the target edge lengths
    (``lengths0``: "equal", the mean per component, the start refused unless it is
    equilateral already when ``equilateral``; "keep", the start's own) and the contact
    distance ``eps``, and builds the ``engine``. Subclasses check their own options before
    calling it, then set ``E``, the history and their state; ``_objective`` is what the
    relative-change test watches, ``_GRADIENT`` how messages call the gradient norm.

    ``pinned`` (with ``pin_tangents``) is checked first (:func:`..pins.check_pins`;
    ``fixed_lengths``: whether the run keeps edge lengths) and kept as ``self.pinned``
    (sorted stacked indices, or None); ``x`` returns the caller's own coordinates there.
    """

    _GRADIENT = "projected gradient norm"
    #: Whether the method relaxes open polylines (``closed=False``): the feasible ones.
    _OPEN_CURVES = False
    #: Whether the method needs the metric as a dense matrix whatever the engine (the penalty
    #: methods' solver is dense).
    _DENSE_METRIC = False
    #: Whether the method grows the length to ``length_target`` (the explicit method: the
    #: growth rides on its accepted steps, :meth:`.projected.Relaxation._grow`).
    _LENGTH_GROWTH = False
    #: the method's name in ``METHODS`` (what messages call it)
    NAME = ""

    def __init__(self, P, metric: str, max_iter: int, tol: float, *,
                 energy_target: float | None, ftol: float, max_seconds: float | None,
                 target_lengths: str, check: bool, equilateral: bool, engine: str = "auto",
                 theta: float | None = None, pinned=None, pin_tangents: bool = False,
                 fixed_lengths: bool = True, obstacles=None, obstacle_weight: float = 1.0,
                 container=None, obstacle_tol: float | None = None, closed=True,
                 energy=DEFAULT_ENERGY, length_target=None, length_growth=None,
                 settle: float = 0.0, settle_iterations: int = SETTLE_ITERATIONS,
                 thickness: float = 0.0, push_apart: bool = False, **engine_options):
        _check_names(metric, target_lengths)
        check = check_flag("check", check)
        pin_tangents = check_flag("pin_tangents", pin_tangents)
        fixed_lengths = check_flag("fixed_lengths", fixed_lengths)
        #: The energy minimized (:mod:`..energies.choice`): ``energy`` and the options its
        #: record brings (``alpha``, ``beta``, ``stiffness``)
        self.energy_choice = check_run_energy(energy, **take_energy_options(engine_options))
        self.t0 = time.perf_counter()
        self.max_iter = check_number("max_iter", max_iter, 0, integer=True)
        self.tol = check_number("tol", tol, 0)
        self.energy_target = None if energy_target is None else check_number("energy_target",
                                                                             energy_target)
        self.ftol = check_number("ftol", ftol, 0)
        self.max_seconds = None if max_seconds is None else check_number("max_seconds",
                                                                         max_seconds, 0)
        #: the shape has settled once no vertex moved more than ``settle`` mean edge lengths in
        #: each of ``settle_iterations`` iterations in a row (0: never)
        self.settle = check_number("settle", settle, 0)
        self.settle_iterations = check_number("settle_iterations", settle_iterations, 1,
                                              integer=True)
        self._settle_from: np.ndarray | None = None
        self._still = 0
        obstacle_weight = check_number("obstacle_weight", obstacle_weight, 0)
        if obstacle_weight > MAX_OBSTACLE_WEIGHT:
            raise ValueError(f"obstacle_weight must be at most {MAX_OBSTACLE_WEIGHT:g}, got "
                             f"{obstacle_weight!r}: the weighted sum overflows float64 (the "
                             "step bound, not the weight, keeps the curve off the meshes)")
        #: tube radius in the caller's units (:mod:`..thickness`; 0: none)
        self.thickness = check_number("thickness", thickness, 0)
        push_apart = check_flag("push_apart", push_apart)
        #: with ``push_apart``, the radius to reach (the run's units) while the tubes kept
        #: (``engine.radius``) grow to it as the flow pushes the strands apart; else None
        self._radius_goal: float | None = None
        if obstacle_tol is not None:
            obstacle_tol = check_number("obstacle_tol", obstacle_tol, 0)
            if obstacle_tol >= 1.0:
                raise ValueError(f"obstacle_tol must be below 1 (a relative error bound of the "
                                 f"obstacle energy; 0: every pair exactly; None: chosen by "
                                 f"size), got {obstacle_tol!r}")
        obstacle_labels, obstacles, container_label, container = _mesh_labels(obstacles,
                                                                              container)
        meshes = None if obstacles is None else check_obstacles(obstacles)
        container = None if container is None else check_container(container)
        # a start checked at the door (AdaptiveRun) comes with its layout: not made again
        X, layout, e2 = ((P.X, P.layout, P.exponent) if isinstance(P, CheckedCurve)
                         else as_unit_layout(P, closed))  # exact scaling far from size 1
        if layout.has_open:
            self._check_open(engine)
        self.pinned = check_pins(pinned, layout, X, tangents=pin_tangents,
                                 edge_lengths=fixed_lengths)
        if self.pinned is not None:
            # the caller's own coordinates there (np.ldexp by an even exponent is exact):
            # mapping the run's copy back would round them
            self._pinned_at = np.ldexp(X[self.pinned], e2)
        # the engine is built first (cheap): it says whether its metric is a dense matrix
        self.engine = make_engine(engine, layout, metric, theta=theta,
                                  energy=self.energy_choice, **engine_options)
        if self._DENSE_METRIC:
            check_dense_size(layout.n, "method")
        elif self.engine.dense_metric:
            check_dense_size(layout.n)
        if check:  # once: a checked start only for the coarseness it may have left out
            if isinstance(P, CheckedCurve):
                check_curve(P, closed=closed)
            else:
                check_layout(X, layout, e2)
        self.layout = layout
        self.metric = metric
        ln = np.linalg.norm(X[layout.nxt] - X, axis=1)
        shift = X.mean(axis=0)
        # total length 1; an energy that is not scale-invariant reports its values there, so
        # for it an open curve's closing chord (the dummy edge of ._layout) is left out
        scale = float((ln[layout.real] if layout.has_open and not
                       self.energy_choice.scale_invariant else ln).sum())
        self.X = (X - shift) / scale
        ln = ln / scale
        self._check_reach(ln, layout)
        self._shift = np.ldexp(shift, e2)  # results are mapped back by these
        self._scale = float(np.ldexp(scale, e2))
        self.lengths0 = ln.copy() if target_lengths == "keep" else self._equal_lengths(
            ln, equilateral)
        if layout.has_open:  # the dummy edges (._layout) have no row: any positive target
            self.lengths0[~layout.real] = 1.0
        self.eps = 1e-3 * self._mean_edge()  # contact distance
        #: the length growth (:mod:`.growth`), or None
        self.growth_schedule = self._check_growth(length_target, length_growth, fixed_lengths)
        radius = self.thickness / self._scale
        if self.thickness > 0:
            if not fixed_lengths:
                raise ValueError("thickness= needs the edge-length constraints: the stretch "
                                 "along a strand that a tube may bend in is counted in edges "
                                 "of the target length, which edge_lengths=False does not "
                                 "keep; turn them on or pass thickness=0")
            near = near_counts(layout, self.lengths0, radius, self._scale)
            self.engine.set_thickness(radius, near)
            if push_apart:  # the tubes the start allows, grown after each iterate
                self._radius_goal, self._near_goal = radius, near
                radius = self._reachable_radius(None)
                self.engine.set_thickness(radius, near)
            check_thickness(self.X, layout, near, radius, self._scale, radius * self._scale)
        if meshes is not None or container is not None:
            # a container is one more obstacle (its wall repels, the contact bound stops every
            # step short of it) that the curve starts inside (.container)
            meshes = list(meshes or [])
            labels = list(obstacle_labels)
            if container is not None:
                V, F = container
                check_inside((V - self._shift) / self._scale, F, self.X, layout,
                             container_label)
                meshes.append(container)
                labels.append(container_label)
            field = ObstacleField(meshes, self._shift, self._scale, obstacle_weight, labels,
                                  auto_obstacle_tol(obstacle_tol, layout, meshes))
            field.fixed = self.pinned  # a pinned end and tangent may lie on a mesh
            if self._radius_goal is not None:
                radius = min(radius, self._reachable_radius(field))
                self.engine.set_thickness(radius, self._near_goal)
            field.check_clear(self.X, layout, max(self.eps, radius), radius * self._scale)
            self.engine.obstacles = field
        #: the iteration at which the pushed-apart tubes reached the thickness asked
        self.thickness_reached_at: int | None = None
        self.nit = 0
        self.rejected = 0
        self.done = False
        self.success = False
        self.message = ""
        self.status = Status.NOT_FINISHED

    def _check_growth(self, length_target, length_growth, fixed_lengths: bool):
        """The :class:`.growth.LengthGrowth` of ``length_target`` and ``length_growth``, None
        without a target; ValueError where the method or the options cannot grow."""
        if length_target is None:
            if length_growth is not None:
                raise ValueError("length_growth needs length_target=, the total length to grow "
                                 "to (growth stops there)")
            return None
        if not self._LENGTH_GROWTH:
            name = self.NAME
            raise ValueError(f"method {name!r} cannot grow the curve's length (length_target=): "
                             f"use method='projected_gradient'")
        if not fixed_lengths:
            raise ValueError("length_target= grows the target edge lengths, which a run without "
                             "the edge-length constraints (edge_lengths=False) does not keep: "
                             "turn them on")
        rate = DEFAULT_LENGTH_GROWTH if length_growth is None else length_growth
        return LengthGrowth(length_target, rate, self.lengths0, self.layout, self.pinned,
                            self._scale)

    def _check_reach(self, ln: np.ndarray, layout) -> None:
        """Refuse coordinates too far out for their edges: a step of the flow is a small
        fraction of an edge, and float64 coordinates ``MAX_REACH`` edges from the centre round
        it to 1e-10 of an edge and worse (a link of two components 1e5 times their size apart
        relaxed; 3e5 apart the back-projection stopped contracting and the run stalled)."""
        short = float((ln[layout.real] if layout.has_open else ln).min())
        reach = float(np.abs(self.X).max()) / short
        if reach > MAX_REACH:
            what = ("its components are too far apart" if layout.k > 1 else
                    "it has too many edges")
            raise ValueError(
                f"vertices lie {reach:.3g} edge lengths from the centre of the curve, more than "
                f"the {MAX_REACH:.0e} at which float64 coordinates still resolve a step of the "
                f"flow: {what}. Move the components closer together (components that far "
                f"apart do not interact: relax them one at a time), or use fewer edges")

    def _check_open(self, engine: str) -> None:
        """Refuse open polylines where the method or the engine cannot run them."""
        if not self._OPEN_CURVES:
            name = self.NAME
            raise ValueError(
                f"method {name!r} cannot relax open curves (closed=False): use a "
                f"feasible method, projected_gradient, projected_gradient_implicit or "
                f"trust_region, on the exact engine")

    def _equal_lengths(self, ln: np.ndarray, equilateral: bool) -> np.ndarray:
        layout = self.layout
        lengths0 = np.empty_like(ln)
        real = layout.real if layout.has_open else None
        for c in range(layout.k):
            s = slice(layout.starts[c], layout.starts[c + 1])
            if real is not None and not layout.closed[c]:  # the dummy edge left out
                s = np.flatnonzero(real[s]) + layout.starts[c]
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
        return lengths0

    # -- state as the caller sees it ----------------------------------------------------------

    @property
    def x(self):
        """Current polygon (or list of arrays for a link) in the caller's coordinates."""
        Y = self.X * self._scale + self._shift
        if self.pinned is not None:
            Y[self.pinned] = self._pinned_at  # the run never moves them (their bits are kept)
        return self.layout.split(Y)

    @property
    def energy(self) -> float:
        return self.E

    def state(self) -> IterationState:
        h = self.history
        return IterationState(
            self.nit, self.x, h["energy"][-1], h["step"][-1], h["grad_norm"][-1],
            h["constraint_residual"][-1], h["seconds"][-1],
        )

    def _stats(self) -> dict:
        """``result().stats``; subclasses add their counters. ``lean``: True where the tree
        engine held less at once (``engine.lean_run``: from 200 000 vertices on)."""
        stats = {"engine": self.engine.name}
        if self.engine.lean:
            stats["lean"] = True
        return stats

    def result(self) -> RelaxResult:
        if not self.done:
            self.stop("not finished (result taken early)", Status.NOT_FINISHED)
        E = self.engine.result_energy(self.X, self.E)
        stats = self._stats()
        if E != self.E:  # the tree's value, which the run's stopping tests saw
            stats["run_energy"] = self.E
        return RelaxResult(
            x=self.x,
            fun=E,
            nit=self.nit,
            success=self.success,
            message=self.message,
            status=self.status,
            history={k: list(v) for k, v in self.history.items()},
            metric=self.metric,
            stats=stats,
            energy=self.energy_choice.label,
        )

    # -- stopping rules ------------------------------------------------------------------------

    def _objective(self) -> float:
        return self.E

    def _finish(self, success: bool, message: str, status: Status) -> None:
        self.done = True
        self.success = success
        self.message = message + self._thickness_note()
        self.status = status

    def stop(self, message: str = "stopped by the caller",
             status: Status = Status.STOPPED) -> None:
        """End the run cleanly after the current iterate (e.g. ESC in Blender)."""
        if not self.done:
            self._finish(True, message, status)

    def _reachable_radius(self, field) -> float:
        """The largest radius up to the goal whose tubes the current iterate keeps apart,
        with the contact test's margin: half the closest tested strands' distance, and the
        nearest obstacle's distance (``field``, or the engine's)."""
        goal, margin = self._radius_goal, SLACK * PUSH_MARGIN
        X, layout = self.X, self.layout
        d, pair = closest_tested(X, layout, self._near_goal, 2.0 * goal * margin)
        radius = goal if pair is None else min(goal, d / (2.0 * margin))
        field = field if field is not None else self.engine.obstacles
        if field is not None:
            radius = min(radius, field.nearest(X, layout.nxt)[2] / margin)
        return radius

    def _push_apart(self) -> None:
        """Grow the tubes kept towards the thickness asked as the strands move apart (never
        shrink them: every iterate so far keeps the radius it had)."""
        if self._radius_goal is None or self.engine.radius >= self._radius_goal:
            return
        radius = max(self.engine.radius, self._reachable_radius(None))
        if radius > self.engine.radius:
            self.engine.set_thickness(radius, self._near_goal)
        if radius >= self._radius_goal and self.thickness_reached_at is None:
            self.thickness_reached_at = self.nit

    def _thickness_note(self) -> str:
        """What the push apart reached, for the result's message (empty without one)."""
        if self._radius_goal is None:
            return ""
        if self.thickness_reached_at == 0:  # the start had room: nothing was pushed
            return ""
        if self.thickness_reached_at is not None:
            return (f" (tubes pushed apart to the thickness {self.thickness:.4g} by iteration "
                    f"{self.thickness_reached_at})")
        if self.engine.radius >= self._radius_goal:
            return ""
        return (f" (tubes pushed apart to {self.engine.radius * self._scale:.4g} of the "
                f"thickness {self.thickness:.4g}: the flow did not move the strands further "
                "apart)")

    def _check_stop(self, prev: float | None) -> None:
        self._push_apart()
        gn = self.history["grad_norm"][-1]
        cur = self._objective()
        if gn <= self.tol:
            self._finish(True, f"{self._GRADIENT} {gn:.3g} below tol {self.tol:g}",
                         Status.CONVERGED)
        elif self.energy_target is not None and self.E <= self.energy_target:
            self._finish(True, f"energy {self.E:.10g} reached the target {self.energy_target:g}",
                         Status.TARGET)
        elif self._settled():
            self._finish(True, f"settled: no vertex moved more than {self.settle:.3g} of an "
                               f"edge in each of the last {self.settle_iterations} iterations",
                         Status.CONVERGED)
        elif prev is not None and abs(prev - cur) <= self.ftol * abs(cur):
            if gn <= _STALL_FACTOR * self.tol:
                self._finish(True, f"relative energy change below ftol {self.ftol:g}",
                             Status.CONVERGED)
            else:
                self._finish(False, self._stall_message(gn), Status.STALLED)
        elif self.nit >= self.max_iter:
            self._finish(False, f"maximum number of iterations ({self.max_iter}) reached",
                         Status.MAX_ITER)
        elif self.max_seconds is not None and time.perf_counter() - self.t0 >= self.max_seconds:
            self._time_up()

    def _settled(self) -> bool:
        """Whether the shape stopped changing (``settle``): counts the iterations in a row
        whose largest vertex move is at most ``settle`` mean edge lengths; a run's keys end
        where its motion ends. Strands pressed together are jammed, not settled: the stall
        that follows says so, and a refining run goes on finer."""
        if not self.settle:
            return False
        X, last = self.X, self._settle_from
        self._settle_from = X.copy()
        if last is None or last.shape != X.shape:
            self._still = 0
            return False
        move = float(np.sqrt(np.max(np.sum((X - last) ** 2, axis=1))))
        self._still = self._still + 1 if move <= self.settle * self._mean_edge() else 0
        return self._still >= self.settle_iterations and self._strand_gap() >= STALL_CONTACT

    def _mean_edge(self) -> float:
        """The mean target edge length (an open component's dummy slots left out)."""
        if self.layout.has_open:
            return float(self.lengths0[self.layout.real].mean())
        return float(self.lengths0.mean())

    def _strand_gap(self) -> float:
        """The start check's contact ratio of the current iterate: the closest approach of
        vertices far apart along the curve, in mean edge lengths (0 where strands touch)."""
        return layout_contact_ratio(self.X, self.layout)

    def _deadline(self) -> None:
        """Raise :class:`_OutOfTime` once the budget is used up (checked inside long steps)."""
        if self.max_seconds is not None and time.perf_counter() - self.t0 >= self.max_seconds:
            raise _OutOfTime

    def _time_up(self) -> bool:
        self._finish(False, f"time budget of {self.max_seconds:g} s used up", Status.TIME)
        return False

    def _give_up(self, gu: float) -> bool:
        """End a run whose line search found no acceptable step: at the minimum the test fails
        on round-off (docs/design.md, step 6), which is convergence; anywhere else it is a failure
        worth reporting (``gu``: the squared gradient norm in the metric). Returns False."""
        gn = float(np.sqrt(max(gu, 0.0)))
        if gn <= _STALL_FACTOR * self.tol:
            self._finish(True, "converged: no further decrease above round-off", Status.CONVERGED)
        else:
            self._finish(False, self._stall_message(gn), Status.STALLED)
        return False

    def _stall_message(self, gn: float) -> str:
        raise NotImplementedError

    def _stall_cause(self) -> str:
        """What holds a stalled curve, read from its state: an obstacle or the container's
        wall it is pressed against, strands pressed together (and the pins that hold them),
        or nothing in contact. Said so that the advice fits ("more edges" helps strands
        pressed together, never a curve held by its pins or pressed against a wall)."""
        if self.tubes_touch():
            return (f"the tubes touch (thickness {self.thickness:.4g} keeps strands twice that "
                    "apart and that far from the obstacles): a smaller thickness gives them "
                    "room")
        X, layout = self.X, self.layout
        edge = self._mean_edge()
        field = self.engine.obstacles
        if field is not None:
            _, k, d = field.nearest(X, layout.nxt)
            if d < STALL_CONTACT * edge:
                return (f"the curve is pressed against {field.labels[int(field.owner[k])]} "
                        f"({d / edge:.2g} edge lengths from it)")
        ratio = self._strand_gap()
        if ratio < STALL_CONTACT:
            held = (" between the pinned points that hold them: as untangled as the pins "
                    "allow" if self.pinned is not None else
                    " (a finer polygon may let them slide past: refine=True, the panel's "
                    "Refine When Jammed)")
            return f"strands are pressed together ({ratio:.2g} edge lengths apart){held}"
        return ("no strand touches another or an obstacle: the steps fall below the "
                "energy's rounding here (a larger tol ends such a run as converged)")

    def tubes_touch(self) -> bool:
        """Whether the tubes of the run's thickness touch at the current iterate: strands
        within :data:`_TOUCH` times twice the thickness, or a strand within that times the
        thickness of an obstacle. A stall there is the thickness holding strands apart, which
        no finer polygon resolves (the adaptive run does not refine it)."""
        radius = self.engine.radius
        if radius <= 0.0:
            return False
        if closest_tested(self.X, self.layout, self.engine.near, _TOUCH * 2.0 * radius)[1]:
            return True
        field = self.engine.obstacles
        return field is not None and field.nearest(self.X, self.layout.nxt)[2] <= (
            _TOUCH * radius)
