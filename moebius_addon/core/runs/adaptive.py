"""Adaptive resolution and restarts around any run (``refine=``, ``restarts=`` of
:func:`..flow.relax` and :func:`.make_run`).

A polygon too coarse for its own shape, or a flow whose strands jam against each other, has
too few edges where strands meet: the discrete energy no longer keeps them apart at that
resolution, and the steps collapse (``Status.STALLED``). :class:`AdaptiveRun` then *refines*:
it splits every edge in two (:func:`..polygon.subdivide`) and goes on with a new run of the
same method from the refined polygon. Splitting leaves the curve as a point set unchanged, so
the refined polygon crosses nothing the old one did not and keeps its knot type; it is checked
like a start all the same (:func:`..polygon.check_polygon`). A start that fails only the
coarseness check is refined the same way before the first iterate, instead of refused. A run
that stalls with its strands apart is not refined (a finer polygon would stall the same): the
method is started afresh from its polygon at the same edge count (its step sizes, Krylov and
quasi-Newton memory let go), up to :data:`FRESH_STARTS` times while each makes progress.

``restarts=K`` nudges a run that converged: K times, the best polygon so far is moved by a
random smooth field (a solve in the run's metric of white noise, projected onto the
constraints and back-projected, its path checked for contact) and relaxed again; a restart
that ends lower is kept, one that does not is rolled back. Seeded by ``seed``.

What a caller sees is one run: ``nit`` counts the iterates of the path that is kept, the
history has one entry per iterate (and an ``edges`` column), ``refinements`` and
``stats["restarts"]`` record what happened. ``x`` changes its vertex count after a
refinement, and ``nit`` goes *back* when a restart is rolled back (to the iterate it started
from): a step-by-step caller that records iterates truncates its record then.
"""

from __future__ import annotations

import time

import numpy as np

from ..geometry.layout import as_layout
from ..geometry.pins import check_pins
from ..geometry.polygon import (
    CONTACT_RATIO,
    check_curve,
    check_polygon,
    contact_ratio,
    layout_contact_ratio,
    subdivide,
)
from ..geometry.push_apart import separate
from ._interrupts import as_interrupt
from .base import IterationState, RelaxResult, Status, check_number
from .checks import check_flag

#: Edges a refinement makes of every edge (a split in two: the flow doubles its resolution
#: where it jammed and everywhere else; the examples of docs/lab/flows-and-methods.md that jammed at
#: n edges relaxed at 2n).
FACTOR = 2
#: A start too coarse is split up to this many times its edges before strands that nearly
#: touch are pushed apart instead (edges 0.05 edge lengths apart need some 20× the edges to
#: pass the start check by splitting alone; docs/lab/flows-and-methods.md "Untangling benchmark").
SPLIT_FIRST = 4
#: Fewest edges ``max_edges`` allows by default, whatever the start (a coarse drawn curve of
#: 50 points may need several refinements).
MIN_MAX_EDGES = 2000
#: Default ``max_edges``: this many times the start's edge count (at least MIN_MAX_EDGES).
MAX_EDGES_FACTOR = 4
#: A run that jams again after a refinement for a jam is refined again only if its energy fell
#: by more than this fraction since: a braid held by its ends stalls at the same energy at any
#: resolution, and more edges only cost time there.
REFINE_GAIN = 1e-3
#: A jammed run goes on, refined, from its last iterate whose strands were at least this many
#: mean edge lengths apart (vertices 4 edges apart along the curve): where a jam forms, the
#: flow squeezes two strands from about an edge apart to a thousandth within a few iterates
#: (5_2 at 180 edges: contact ratio 0.82, 0.73, 0.50 at iterates 44, 46, 48, the edges then
#: 0.12 edge lengths apart), and a refinement of the squeezed polygon jams again (three
#: refinements in a row, measured); relaxed shapes of the energy table keep 0.82 or more.
CHECKPOINT_RATIO = 0.75
#: Fresh starts of the method after stalls with the strands apart, at most: 9_3 from a tangled
#: braid (700 edges) stalled at 257.59 with the projected gradient's norm still 0.31 and no two
#: strands closer than 0.88 edge lengths; the implicit method started again from that polygon
#: went on to the table's 250.9956 (docs/lab/flows-and-methods.md, "Untangling benchmark").
FRESH_STARTS = 3
#: A fresh start of a run on the tree engine takes this many times its admissibility θ (and
#: keeps it for the rest of the path): a stall with the strands apart there is mostly the
#: tree's error outgrowing the energy's fall per step (the tangent-point energy (2, 4.5) of
#: 7_4 at 2 000 edges stalled at θ 0.3 after 49 iterations and at 0.5 after 25, at 220.0 and
#: 222.6, while θ 0.1 and the exact engine went on to 218.2 and 218.1 in 300;
#: docs/lab/flows-and-methods.md, "A stall on the tree tightens θ").
FRESH_THETA = 0.5
#: ... but not below this many times the path's first θ (7_4 above at θ 0.0375 from its third
#: fresh start: 252 iterations in 216 s, stopped by a 200 s budget; with this floor, 0.075,
#: 300 in 46 s).
FRESH_THETA_FLOOR = 0.25
#: Length growth (``length_target=``) splits every edge in two once growth has made an edge
#: more than this many times the start's mean edge length (the energy resolves a curve at the
#: scale of its edges: the split keeps them near the length they started with).
GROWN_SPLIT = 2.0
#: Default size of a restart's nudge: the largest vertex move, in mean edge lengths.
RESTART_SCALE = 0.25

# A restart is kept when it ends lower than the best by more than this fraction.
_KEEP = 1e-9
# Counters of result().stats that add up over the runs of a path (the rest are the last run's).
_SUMMED = ("factorizations", "krylov_iterations", "rejected_steps", "hessian_products",
           "gradient_evaluations")


def default_max_edges(n: int) -> int:
    """``max_edges`` when none is given: :data:`MAX_EDGES_FACTOR` times ``n``, at least
    :data:`MIN_MAX_EDGES`."""
    return max(MAX_EDGES_FACTOR * int(n), MIN_MAX_EDGES)


def _pins_after(pinned: np.ndarray, layout, factor: int):
    """The pins of the refined polygon: every pinned vertex (stacked index, ``pin_tangents``
    already applied) where it went, and the new vertices on an edge between two pins (they
    sit on a straight, fixed piece), as ``pinned=`` takes them (a list per component)."""
    out = []
    fixed = np.zeros(layout.n, bool)
    fixed[pinned] = True
    for c in range(layout.k):
        a, b = int(layout.starts[c]), int(layout.starts[c + 1])
        closed = layout.closed is None or bool(layout.closed[c])
        local = np.flatnonzero(fixed[a:b])
        new = [factor * int(i) for i in local]
        m = b - a
        for i in local:
            j = int(i) + 1
            if j == m:
                if not closed:
                    continue
                j = 0
            if fixed[a + j]:
                new.extend(factor * int(i) + k for k in range(1, factor))
        out.append(sorted(new))
    return out if layout.is_link else out[0]


def _words(r: dict) -> str:
    """A refinement in a few words: "100 → 200 edges at iteration 0", "strands pushed apart"
    added for a separated start."""
    apart = " (strands pushed apart)" if r.get("separation_steps") else ""
    return f"{r['edges_before']} → {r['edges_after']} edges at iteration {r['iteration']}{apart}"


class AdaptiveRun:
    """A run of any method that refines its polygon when it jams, and restarts from nudged
    copies of a converged result; the interface of :class:`.base.Run` (``step()``,
    ``state()``, ``stop()``, ``result()``, ``x``, ``energy``, ``nit``, ``history``, ``done``,
    ``success``, ``message``, ``status``; anything else is the current run's).

    Parameters
    ----------
    make : callable
        ``make(P, max_iter, max_seconds, **changes)`` builds a run of the method from polygon
        ``P`` with the caller's options (``changes`` replace some: ``pinned``).
    P, max_iter : polygon, int
        The caller's start and iteration limit (per run of the path: the first and every
        restart; refinements go on counting).
    refine : bool
        Refine a too-coarse start and a jammed run (off: the start is refused and the jam
        reported, as by a plain run).
    max_edges : int, optional
        Refine no further than this many edges in all (default :func:`default_max_edges`).
    restarts : int
        Restarts after a converged run (0: none); feasible methods only.
    seed : int
        Seed of the restarts' nudges.
    restart_scale : float
        Largest vertex move of a nudge, in mean edge lengths.
    max_seconds, closed, pinned, pin_tangents, check
        The caller's options of these names (the budget is for the whole path).
    """

    def __init__(self, make, P, max_iter: int, *, refine: bool = True,
                 max_edges: int | None = None, restarts: int = 0, seed: int = 0,
                 restart_scale: float = RESTART_SCALE, max_seconds: float | None = None,
                 closed=True, pinned=None, pin_tangents: bool = False, check: bool = True,
                 obstacles=None, container=None):
        self.t0 = time.perf_counter()
        self._make_run = make
        self._theta = None  # the tree's θ once a fresh start tightened it (None: the caller's)
        self._theta_floor = None  # FRESH_THETA_FLOOR times the first tree run's θ
        self.refine = bool(refine)
        self.restarts = check_number("restarts", restarts, 0, integer=True)
        self.seed = check_number("seed", seed, 0, integer=True)
        self.restart_scale = check_number("restart_scale", restart_scale, 0, above=True)
        self.max_iter = check_number("max_iter", max_iter, 0, integer=True)
        self.max_seconds = None if max_seconds is None else check_number(
            "max_seconds", max_seconds, 0)
        self.closed = closed
        check = check_flag("check", check)
        pin_tangents = check_flag("pin_tangents", pin_tangents)
        X, layout = as_layout(P, closed)
        # open components have one edge fewer than vertices
        self._open = 0 if layout.closed is None else int(np.count_nonzero(~layout.closed))
        self.max_edges = default_max_edges(self._edges(layout.n)) if max_edges is None else (
            check_number("max_edges", max_edges, 1, integer=True))
        #: what was refined: dicts of iteration, edges before and after, why (and energies)
        self.refinements: list[dict] = []
        start, changes, path = P, {}, []
        if self.refine and check:
            separable = obstacles is None and container is None
            start, changes, path = self._refine_start(P, X, layout, pinned, pin_tangents,
                                                      separable)
        # a separation's steps count as iterations of the path
        self.run = self._make(start, max(0, self.max_iter - len(path)), self.max_seconds,
                              **changes)
        self._retired: list[dict] = []  # the counters of every run left behind
        self.history = {k: list(v) for k, v in self.run.history.items()}
        self.history["edges"] = [self.run.layout.n] * len(self.history["energy"])
        self.nit = self.run.nit
        self._run_nit = self.run.nit  # the current run's count when last looked at
        self._restart_log: list[dict] = []
        #: the fresh starts after stalls with the strands apart: dicts of iteration, energy,
        #: the stalled run's message
        self.fresh_starts: list[dict] = []
        self._rng = np.random.default_rng(self.seed)
        self._best = None  # (energy, run, nit, history length, refinements) of the best
        self._trial = None  # the restart in progress: (index, first iterate)
        self._why_not = ""
        self.done = False
        #: the iterates of a separated start still to be stepped through (polygon, energy),
        #: then None for the run's own start; the one shown now (None: the run's)
        self._prelude: list = []
        self._current = None
        if path:
            self._begin_prelude(path)
            return
        self._checkpoint = (self.nit, None, len(self.history["energy"]))
        if self.refine:
            self._note_checkpoint(self.run)
        self._after_step()

    # -- a separated start ------------------------------------------------------------------

    def _begin_prelude(self, path) -> None:
        """Make the separation's polygons (``path``, the run's start not included) the first
        iterates of the path: the caller steps through them as through any (the history has
        their energy; what only a run has, such as the gradient norm, is NaN)."""
        run = self.run
        # the run's engine works at total length 1: a scale-free energy takes the caller's size
        # as well, any other the polygons mapped as the run maps its own
        scaled = not run.energy_choice.scale_invariant
        energies = [float(run.engine.energy(np.ascontiguousarray(
            (X - run._shift) / run._scale if scaled else X)))
            for X in (as_layout(Q, self.closed)[0] for Q in path)]
        self._prelude = list(zip(path[1:], energies[1:], strict=True)) + [None]
        self._current = (path[0], energies[0])
        self.history = {k: [np.nan] for k in run.history}
        self._set_entry(energies[0], run.layout.n)

    def _set_entry(self, energy: float, n: int) -> None:
        """The last history entry: a separation step's."""
        h = self.history
        h["energy"][-1] = energy
        h["seconds"][-1] = time.perf_counter() - self.t0
        h.setdefault("edges", [n] * len(h["energy"]))[-1] = n

    def _prelude_step(self) -> None:
        nxt = self._prelude.pop(0)
        self.nit += 1
        if nxt is not None:
            self._current = nxt
            for v in self.history.values():
                v.append(np.nan)
            self._set_entry(nxt[1], self.run.layout.n)
            if self.nit >= self.max_iter:  # ends half way, as stopped (a crossing-free curve)
                self._prelude = []
                self._finish(False, f"maximum number of iterations ({self.max_iter}) reached",
                             Status.MAX_ITER)
            return
        # the run's own start, the last polygon of the separation: its entry as the run has it
        self._current = None
        self._append(self.run, 0)
        self._checkpoint = (self.nit, None, len(self.history["energy"]))
        if self.refine:
            self._note_checkpoint(self.run)
        self._after_step()

    def _edges(self, n_vertices: int) -> int:
        return int(n_vertices) - self._open

    # -- refinement ------------------------------------------------------------------------

    def _refine_start(self, P, X, layout, pinned, pin_tangents, separable: bool):
        """``(P, {}, [])``, or ``P`` made fine enough for the start check, the options that
        change with it and the path of a separation (recorded as the refinement of iteration
        0). Splitting its edges is tried first (the same curve), up to
        :data:`SPLIT_FIRST` times the edges; strands that pass closer than that resolves are
        pushed apart (:func:`..separate.separate`, at the fewest edges where that works: its
        steps become the path's first iterates); then splitting up to ``max_edges``."""
        changes = {} if pinned is None else {"pinned": pinned}
        checked = check_curve(P, coarseness=False, closed=self.closed)
        ratio = checked.ratio
        if ratio >= CONTACT_RATIO:  # the run takes the checked start: nothing checked twice
            return checked, changes, []
        edges = self._edges(layout.n)
        factors = [FACTOR ** k for k in range(1, 64)
                   if edges * FACTOR ** k <= self.max_edges]
        reason = f"start too coarse (contact ratio {ratio:.2f} < {CONTACT_RATIO:g})"
        path, moved = [], None
        found = self._first_split(P, [f for f in factors if f <= SPLIT_FIRST])
        # pins and obstacles stay where they are: a separation would move past them unchecked
        if found is None and separable and pinned is None:
            for factor in [1, *factors]:
                try:
                    path, moved = separate(subdivide(P, factor, self.closed), self.closed)
                except ValueError:
                    continue
                found = factor
                reason += (f"; strands pushed apart by up to {moved:.2f} edge lengths in "
                           f"{len(path) - 1} steps")
                break
        if found is None:
            found = self._first_split(P, [f for f in factors if f > SPLIT_FIRST])
        if found is None:
            return P, changes, []  # the run's own check refuses it, naming the count that works
        Q = path[-1] if path else subdivide(P, found, self.closed)
        if pinned is not None:
            fixed = check_pins(pinned, layout, X, tangents=bool(pin_tangents))
            changes = {"pinned": _pins_after(fixed, layout, found), "pin_tangents": False}
        self.refinements.append({
            "iteration": 0, "edges_before": edges,
            "edges_after": self._edges(found * layout.n - (found - 1) * self._open),
            "reason": reason, **({} if not path else {
                "separation_steps": len(path) - 1, "moved": moved})})
        return Q, changes, path[:-1]

    def _first_split(self, P, factors):
        """The first of ``factors`` whose split of ``P`` passes the start check, or None."""
        for factor in factors:
            if contact_ratio(subdivide(P, factor, self.closed), closed=self.closed) >= (
                    CONTACT_RATIO):
                return factor
        return None

    def _refine_run(self, reason: str) -> bool:
        """Go on from the last healthy iterate of the current run (its checkpoint, the last
        with contact ratio >= :data:`CHECKPOINT_RATIO`; the iterates after it are dropped)
        with that polygon split in two; False when that is not allowed (``max_edges``, or a
        size the method refuses: the run's end stands)."""
        run = self.run
        layout = run.layout
        edges_now = self._edges(layout.n)
        jams = [r for r in self.refinements if r["reason"].startswith("jammed")]
        if jams and float(run.E) >= (1.0 - REFINE_GAIN) * jams[-1]["energy_before"]:
            last = jams[-1]  # held, not jammed: a finer polygon stalls the same
            self._why_not = (f"not refined again: refining to {last['edges_after']} edges at "
                             f"iteration {last['iteration']} did not lower the energy "
                             f"({last['energy_before']:.10g} → {float(run.E):.10g})")
            return False
        if FACTOR * edges_now > self.max_edges:
            self._why_not = (f"not refined further: {FACTOR * edges_now} edges would exceed "
                             f"max_edges={self.max_edges}")
            return False
        nit, x, length = self._checkpoint
        Q = subdivide(x, FACTOR, self.closed)
        # the same point set: it touches nothing the polygon did not, so the knot type is
        # kept; checked like a start all the same (coarseness only where the checkpoint is
        # the current iterate: strands squeezed closer than an edge are why it is refined)
        check_polygon(Q, coarseness=False, closed=self.closed)
        changes = {}
        if getattr(run, "pinned", None) is not None:
            changes = {"pinned": _pins_after(run.pinned, layout, FACTOR), "pin_tangents": False}
        energy_at = self.history["energy"][length - 1]
        nit_now, self.nit = self.nit, nit  # the new run's budget counts from the checkpoint
        try:
            new = self._make(Q, self._iterations_left(), self._seconds_left(), check=False,
                             **changes)
        except ValueError as err:  # a size the method or engine refuses
            self.nit = nit_now
            self._why_not = f"not refined to {FACTOR * edges_now} edges: {err}"
            return False
        self._retire(run)
        dropped = len(self.history["energy"]) - length
        for v in self.history.values():
            del v[length:]
        self.refinements.append({
            "iteration": nit, "edges_before": edges_now,
            "edges_after": self._edges(new.layout.n), "reason": reason,
            "energy_before": float(energy_at), "energy_after": float(new.E),
            "iterations_dropped": dropped})
        self._go_on_with(new)  # the last entry, refined, becomes the new run's start
        self._checkpoint = (self.nit, None, len(self.history["energy"]))
        self._note_checkpoint(new)
        return True

    def _make(self, Q, iterations, seconds, **changes):
        """A new run of the method on ``Q`` (the caller's options, ``changes`` over them, and
        the θ a fresh start tightened)."""
        if self._theta is not None:
            changes = {"theta": self._theta, **changes}
        return self._make_run(Q, iterations, seconds, **changes)

    def _start_afresh(self, run) -> bool:
        """Go on from the polygon of ``run``, which stalled with its strands apart, with a new
        run of the method at the same edge count; False when :data:`FRESH_STARTS` are used
        up, the last fresh start did not lower the energy, or no budget is left (the stall
        stands)."""
        if len(self.fresh_starts) >= FRESH_STARTS or (
                self._iterations_left() == 0 or self._seconds_left() == 0.0):
            return False
        if self.fresh_starts:
            # its own energy at its start: with a tightened θ the stalled run's value before
            # it is another approximation (8_1's tangent-point run at 2 000 edges: its second
            # fresh start lowered the energy but ended above the value at θ 0.15, and stopped)
            last = self.fresh_starts[-1]["start_energy"]
            if not run.E < last - _KEEP * abs(last):  # the last one went nowhere
                return False
        changes = {}
        if getattr(run, "pinned", None) is not None:
            changes = {"pinned": _pins_after(run.pinned, run.layout, 1), "pin_tangents": False}
        engine = getattr(run, "engine", None)
        if getattr(engine, "name", None) == "tree":
            if self._theta_floor is None:
                self._theta_floor = FRESH_THETA_FLOOR * engine.theta
            changes["theta"] = max(FRESH_THETA * engine.theta, self._theta_floor)
        try:
            new = self._make(run.x, self._iterations_left(), self._seconds_left(), check=False,
                             **changes)
        except ValueError:
            return False
        if "theta" in changes:
            self._theta = changes["theta"]
        self.fresh_starts.append({"iteration": self.nit, "energy": float(run.E),
                                  "start_energy": float(new.E), "message": run.message,
                                  "theta": changes.get("theta")})
        self._retire(run)
        self._go_on_with(new)
        return True

    def _go_on_with(self, new) -> None:
        """Make ``new`` the current run, from the last iterate of the path: that entry of the
        history becomes the new run's start (the same polygon, as the new run has it)."""
        self.run = new
        self._run_nit = new.nit
        for k, v in new.history.items():
            if k in self.history:
                self.history[k][-1] = v[0]
        self.history["edges"][-1] = new.layout.n
        self.history["seconds"][-1] = time.perf_counter() - self.t0

    def _split_grown(self, run) -> None:
        """Go on from the current iterate of a growing run with every edge split in two once
        growth has made its edges more than :data:`GROWN_SPLIT` times the start's (the same
        point set, so nothing is crossed; the new run keeps the grown lengths as its targets
        and grows on to the same ``length_target``). Nothing happens beyond ``max_edges`` or
        where the method refuses the size."""
        sched = getattr(run, "growth_schedule", None)
        if sched is None or run.done or sched.edge_ratio(run.lengths0) <= GROWN_SPLIT:
            return
        edges_now = self._edges(run.layout.n)
        if FACTOR * edges_now > self.max_edges:
            return
        Q = subdivide(run.x, FACTOR, self.closed)
        changes = {"target_lengths": "keep"}  # the grown lengths (pinned stretches differ)
        if getattr(run, "pinned", None) is not None:
            changes.update(pinned=_pins_after(run.pinned, run.layout, FACTOR),
                           pin_tangents=False)
        try:
            new = self._make(Q, self._iterations_left(), self._seconds_left(), check=False,
                             **changes)
        except ValueError:
            return
        self._retire(run)
        self.refinements.append({
            "iteration": self.nit, "edges_before": edges_now,
            "edges_after": self._edges(new.layout.n),
            "reason": f"edges grown to {sched.edge_ratio(run.lengths0):.2f} times the start's",
            "energy_before": float(run.E), "energy_after": float(new.E)})
        self._go_on_with(new)  # the same iterate, split: the new run's start
        self._checkpoint = (self.nit, None, len(self.history["energy"]))
        self._note_checkpoint(new)

    def _held_by_tubes(self, run) -> bool:
        """Whether a stalled run stopped where its tubes touch (``Run.tubes_touch``): the
        thickness holds the strands, which neither a finer polygon nor a fresh start changes."""
        if getattr(run, "tubes_touch", None) is None or not run.tubes_touch():
            return False
        self._why_not = "not refined: the tubes touch, at any resolution"
        return True

    def _jammed(self, run) -> bool:
        """Whether a stalled run's strands are closer than the start check allows (contact
        ratio below 1): a jam a finer polygon resolves. A run stalled against an obstacle, or
        with its strands apart, is not refined (it would stall the same at any resolution)."""
        if layout_contact_ratio(run.X, run.layout) < CONTACT_RATIO:
            return True
        self._why_not = "not refined: no two strands are closer than an edge length"
        return False

    def _note_checkpoint(self, run) -> None:
        """Make the current iterate the checkpoint if it is healthy: strands at least
        :data:`CHECKPOINT_RATIO` mean edge lengths apart (vertices 4 edges apart along the
        curve, as the start check measures)."""
        # the run's own scaled copy (the ratio is scale-free), checked already; the first
        # checkpoint is taken whatever its ratio
        if self._checkpoint[1] is None or (
                layout_contact_ratio(run.X, run.layout) >= CHECKPOINT_RATIO):
            self._checkpoint = (self.nit, run.x, len(self.history["energy"]))

    def _iterations_left(self) -> int:
        first = 0 if self._trial is None else self._trial[1]
        return max(0, self.max_iter - (self.nit - first))

    def _seconds_left(self):
        if self.max_seconds is None:
            return None
        return max(0.0, self.max_seconds - (time.perf_counter() - self.t0))

    # -- restarts --------------------------------------------------------------------------

    def _start_restart(self) -> bool:
        """Nudge the best polygon and start relaxing it; False when no nudge was found."""
        best_run = self._best[1]
        k = len(self._restart_log) + 1
        try:
            Y = best_run.nudge(self._rng, self.restart_scale)
        except ValueError as err:
            self._restart_log.append({"restart": k, "kept": False, "message": str(err)})
            return False
        changes = {}
        if getattr(best_run, "pinned", None) is not None:
            changes = {"pinned": _pins_after(best_run.pinned, best_run.layout, 1),
                       "pin_tangents": False}
        new = self._make(Y, self.max_iter, self._seconds_left(), **changes)
        self._trial = (k, self.nit + 1)
        self.run = new
        self._run_nit = new.nit
        self.nit += 1  # the nudge is a step of the path
        self._append(new, 0)
        self._checkpoint = (self.nit, None, len(self.history["energy"]))
        self._note_checkpoint(new)
        return True

    def _end_restart(self) -> None:
        """Keep the restart that just finished if it ended lower, else roll back to the
        best run."""
        E_best, best_run, best_nit, best_len, best_ref = self._best
        run = self.run
        # lower by more than round-off: a restart back at the same minimum is dropped (8_19 and
        # 10_124 of the table: every restart ended within 1e-8 of the start's energy)
        kept = bool(run.E < E_best - _KEEP * abs(E_best)) and run.status in (
            Status.CONVERGED, Status.STOPPED)
        k, first = self._trial
        self._restart_log.append({"restart": k, "iteration": first, "energy": float(run.E),
                                  "iterations": self.nit - first + 1, "kept": kept,
                                  "message": run.message})
        if kept:
            self._retire(best_run)
            self._best = (float(run.E), run, self.nit, len(self.history["energy"]),
                          len(self.refinements))
        else:
            self._retire(run)
            self.run = best_run
            self.nit = best_nit
            for v in self.history.values():
                del v[best_len:]
            del self.refinements[best_ref:]
        self._trial = None

    # -- stepping --------------------------------------------------------------------------

    def _append(self, run, i: int = -1) -> None:
        for k, v in run.history.items():
            if k in self.history:
                self.history[k].append(v[i])
        self.history["edges"].append(run.layout.n)
        self.history["seconds"][-1] = time.perf_counter() - self.t0

    def _after_step(self) -> None:
        """Bookkeeping after the current run stepped (or was made): record its new iterate,
        and when it finished, refine, restart, roll back or finish."""
        while True:
            run = self.run
            if run.nit > self._run_nit:
                self.nit += run.nit - self._run_nit
                self._run_nit = run.nit
                self._append(run)
                if self.refine:
                    self._note_checkpoint(run)
                    self._split_grown(run)
            if not run.done:
                return
            if run.status == Status.STALLED and self.refine and not self._held_by_tubes(run) and (
                    self._refine_run("jammed: " + run.message) if self._jammed(run)
                    else self._start_afresh(run)):
                continue
            if self._trial is not None:
                self._end_restart()
            elif run.status == Status.CONVERGED and self.restarts and self._best is None:
                self._best = (float(run.E), run, self.nit, len(self.history["energy"]),
                              len(self.refinements))
            if (self._best is not None and len(self._restart_log) < self.restarts
                    and self._seconds_left() != 0.0 and self._start_restart()):
                continue
            message = self.run.message
            if self.run.status == Status.MAX_ITER:  # the run's own limit is what was left
                message = f"maximum number of iterations ({self.max_iter}) reached"
            self._finish(self.run.success, message, self.run.status)
            return

    def _finish(self, success: bool, message: str, status: Status) -> None:
        self.done = True
        self.success, self.status = success, status
        notes = []
        if self.refinements:
            notes.append("refined " + ", ".join(_words(r) for r in self.refinements))
        if status == Status.STALLED and self._why_not:
            notes.append(self._why_not)
        if self.fresh_starts:
            k = len(self.fresh_starts)
            tightened = f", the tree's θ tightened to {self._theta:.3g}" if self._theta else ""
            notes.append(f"the method started afresh {k} time{'s' * (k > 1)} after a stall with "
                         f"the strands apart{tightened}")
        if self._restart_log:
            kept = sum(r["kept"] for r in self._restart_log)
            notes.append(f"{len(self._restart_log)} restarts, {kept} kept")
        self.message = message + ("" if not notes else " (" + "; ".join(notes) + ")")

    @as_interrupt
    def step(self) -> bool:
        """Advance the current run by one accepted iterate (refining, restarting or rolling
        back when it finishes). Returns False once finished."""
        if self.done:
            return False
        if self._prelude:
            self._prelude_step()
            return not self.done
        self.run.step()
        self._after_step()
        return not self.done

    def stop(self, message: str = "stopped by the caller",
             status: Status = Status.STOPPED) -> None:
        """End cleanly after the current iterate. A restart in progress is kept if it is
        already lower than the best, else rolled back."""
        if self.done:
            return
        self._prelude = []  # a separation stopped half way ends where it is (self._current)
        self.run.stop(message, status)
        if self._trial is not None:
            self._end_restart()
        self._finish(True, message, status)

    # -- state as the caller sees it -------------------------------------------------------

    @property
    def x(self):
        return self.run.x if self._current is None else self._current[0]

    @property
    def energy(self) -> float:
        return self.E

    @property
    def E(self) -> float:
        return self.run.E if self._current is None else self._current[1]

    def state(self):
        if self._current is not None:
            h = self.history
            return IterationState(self.nit, self.x, self.E, np.nan, np.nan, 0.0,
                                  h["seconds"][-1])
        s = self.run.state()
        s.nit = self.nit
        s.seconds = self.history["seconds"][-1]
        return s

    def __getattr__(self, name):  # engine, layout, metric, X, ... of the current run
        if name == "run":
            raise AttributeError(name)
        return getattr(self.run, name)

    def _retire(self, run) -> None:
        """Keep the counters of a run that is no longer the current one."""
        self._retired.append(run._stats())

    def result(self) -> RelaxResult:
        if not self.done:
            self.stop("not finished (result taken early)", Status.NOT_FINISHED)
        res = self.run.result()
        stats = dict(res.stats)
        for other in self._retired:
            for k in _SUMMED:
                if k in other:
                    stats[k] = stats.get(k, 0) + other[k]
        stats["refinements"] = len(self.refinements)
        stats["fresh_starts"] = [dict(r) for r in self.fresh_starts]
        if self.restarts:
            stats["restarts"] = [dict(r) for r in self._restart_log]
        return RelaxResult(
            x=self.x, fun=res.fun if self._current is None else self.E, nit=self.nit,
            success=self.success, message=self.message,
            status=self.status, history={k: list(v) for k, v in self.history.items()},
            metric=res.metric, stats=stats, refinements=[dict(r) for r in self.refinements],
            energy=res.energy)
