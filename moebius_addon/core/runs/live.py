"""Live relaxation: the flow runs on while the user moves its pins and meshes.

A live run is the projected Sobolev-gradient flow (:class:`.solvers.projected.Relaxation`)
whose constraints may change between two steps:

* **pins move** (:meth:`LiveRelaxation.move_pins`): the pinned vertices go to new places and
  the free vertices follow along a drag field (each free vertex moves by the linear
  interpolation, along its component, of the moves of the pins on either side), then the
  same back-projection as a step restores the edge lengths with the pins held, and the
  straight path from the iterate to the result is tested for contact like a step's. A move
  that fails either test is cut to the largest share of it that passes (bisection), so a
  strand is never dragged through another, an obstacle or the container: **clipped at
  contact**;
* **meshes move** (:meth:`LiveRelaxation.move_meshes`): an obstacle or the container is
  placed by an affine map of its start position (what Blender's G/R/S do to an object). The
  mesh's vertices travel straight from the old to the new placement; every point of a
  triangle moves by a convex combination of its vertices' moves, so no point travels farther
  than the farthest vertex. The move is cut to the share whose farthest vertex travels less
  than the curve's distance from the moving meshes (less a margin): conservative advancement,
  which cannot let a wall pass through the curve.

Either change is followed by the flow's own steps, which push the curve away from what pressed
it (the obstacle energy, the curve's own energy), so a pin or a mesh held at contact goes on as
room opens: the target is kept and approached again on every round (:class:`LiveDriver`).

:class:`LiveDriver` runs such a run in a Python thread and hands every state it passes through
to the caller (the latest for display, all of them for a recording: the straight moves between
consecutive states are the ones tested for contact). numba's kernels hold the GIL while they
run (none is compiled ``nogil``), so the thread sleeps briefly after every state to let the
caller's thread run (measured in ``bench/live_rates.py``).

Imports (kept to these, so that the module moves as a whole): ``Relaxation`` and ``Status``
(``core``'s public names), and from ``.obstacles`` the field of triangles and its tolerance.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Mapping
from dataclasses import dataclass, field

import numba
import numpy as np

from ..geometry.obstacles import ObstacleField, auto_obstacle_tol
from .base import Status
from .checks import check_number
from .projected import Relaxation

#: A pin move that fails its tests is halved up to this many times until a share passes …
PIN_HALVINGS = 12
#: … and then bisected this many times between that share and its double: the share kept is
#: within 2⁻⁸ of it of the largest that passes.
PIN_BISECTIONS = 8
#: A mesh moved towards the curve stops this many times the contact distance (or the tube
#: radius) short of it: the flow's steps need room, as the start check asks of a start.
MESH_CLEARANCE = 2.0
#: Iterations of a live run: it never stops by counting (the caller ends it).
LIVE_MAX_ITER = 2**62
#: A live run's step growth (the first trial of an iteration at most this times the last
#: step): each accepted iterate is a viewport update, and a rejected trial costs an energy.
#: Against the finite run's 8, stepped alone on one thread for 1 s (bench/live_rates.py's
#: scenes): the 1 000-edge knot 61 against 47 iterations and a lower energy, ten cables of 100
#: edges 46 against 34 and lower; growth 2 lay between.
LIVE_GROWTH = 1.5


def drag_field(layout, pinned: np.ndarray, moves: np.ndarray) -> np.ndarray:
    """The move of every vertex when the ``pinned`` vertices (sorted stacked indices) move by
    ``moves`` (one row each): along each component, linear in the vertex index between two
    consecutive pins (cyclically on a closed component; a closed component with one pin moves
    rigidly with it), constant before the first and after the last pin of an open one; zero on
    components without pins. (N, 3)."""
    D = np.zeros((layout.n, 3))
    comp = layout.comp[pinned]
    closed = layout.closed_flags
    for c in np.unique(comp):
        s0, s1 = int(layout.starts[c]), int(layout.starts[c + 1])
        n = s1 - s0
        idx = pinned[comp == c] - s0
        mv = moves[comp == c]
        i = np.arange(n)
        if closed[c]:
            # unroll the cycle: the pins repeated one period before and after
            xs = np.concatenate([idx - n, idx, idx + n])
            ys = np.concatenate([mv, mv, mv])
        else:
            xs, ys = idx, mv
        for k in range(3):  # np.interp holds the end values outside, as an open end wants
            D[s0:s1, k] = np.interp(i, xs, ys[:, k])
    D[pinned] = moves
    return D


@dataclass
class MoveResult:
    """What a constraint move did: ``share`` of the asked move made (1: all of it, 0: none),
    and why it was cut (empty when it was not)."""

    share: float
    reason: str = ""

    @property
    def clipped(self) -> bool:
        return self.share < 1.0


class LiveRelaxation(Relaxation):
    """A projected-gradient run whose pins and meshes may move between steps.

    Parameters
    ----------
    P, metric, tol, **options
        As in :class:`.solvers.projected.Relaxation` (``pinned``, ``pin_tangents``,
        ``obstacles``, ``container``, ``thickness``, ``energy`` …; ``growth`` defaults to
        :data:`LIVE_GROWTH`; ``length_growth`` is also the rate of :meth:`grow`); there is no
        iteration limit. A converged run rests
        (:attr:`done`) until a move gives it something to do.

    Pins move with :meth:`move_pins` (targets for the pins given, in the order of their
    sorted stacked indices, :attr:`handles`; the tangent neighbours of ``pin_tangents`` move
    with their pin), meshes with :meth:`move_meshes` (an affine map of each one's start
    position, :attr:`mesh_labels`). Both keep the curve off itself, the obstacles and the
    container: a move that would cross is cut at contact (:class:`MoveResult`).
    """

    def __init__(self, P, metric: str = "hs", tol: float = 1e-6, **options):
        options.pop("max_iter", None)
        options.setdefault("growth", LIVE_GROWTH)
        rate = options.get("length_growth")
        if rate is not None:
            check_number("length_growth", rate, 0.0, above=True)
        if options.get("length_target") is None:  # the rate of grow(), when it is called
            options.pop("length_growth", None)
        super().__init__(P, metric, LIVE_MAX_ITER, tol, **options)
        layout = self.layout
        given = options.get("pinned")
        #: the pins the caller gave (sorted stacked indices; None: nothing pinned)
        self.handles = None if given is None else _stacked(given, layout)
        #: for every pinned vertex, the row of :attr:`handles` whose move it takes
        self._follows = None
        if self.handles is not None:
            pos = {int(h): r for r, h in enumerate(self.handles)}
            follows = []
            for v in self.pinned:
                v = int(v)
                if v in pos:
                    follows.append(pos[v])
                else:  # a tangent neighbour: the pin beside it
                    near = [pos[w] for w in (int(layout.prv[v]), int(layout.nxt[v])) if w in pos]
                    follows.append(near[0])
            self._follows = np.array(follows, dtype=np.int64)
        # the meshes as given (caller's coordinates) and where each one is now
        obstacles, container = options.get("obstacles"), options.get("container")
        self._meshes: list[tuple[str, np.ndarray, np.ndarray]] = []
        if obstacles is not None:
            items = (obstacles.items() if isinstance(obstacles, Mapping) else
                     ((f"obstacle {m}", mesh) for m, mesh in enumerate(
                         [obstacles] if _is_mesh(obstacles) else obstacles)))
            for name, (V, F) in items:
                self._meshes.append((str(name), np.asarray(V, np.float64),
                                     np.asarray(F, np.int64)))
        if container is not None:
            name, (V, F) = (next(iter(container.items())) if isinstance(container, Mapping)
                            else ("container", container))
            self._meshes.append((str(name), np.asarray(V, np.float64), np.asarray(F, np.int64)))
        self._has_container = container is not None
        #: the affine map (4 × 4) of each mesh's start position to its current one
        self.placements = [np.eye(4) for _ in self._meshes]
        self._obstacle_weight = float(options.get("obstacle_weight", 1.0))
        self._obstacle_tol = options.get("obstacle_tol")
        #: the number of constraint moves made (pins or meshes), for the caller's record
        self.moves = 0
        self._edge_lengths = options.get("edge_lengths", True)
        self._growth_rate = rate
        #: the goal of :meth:`grow`: the total length over the length at the start
        self.length_factor = 1.0

    # -- what the caller reads ---------------------------------------------------------------

    @property
    def mesh_labels(self) -> list[str]:
        """The meshes' names, obstacles in the order given, the container last."""
        return [name for name, _, _ in self._meshes]

    @property
    def pin_positions(self) -> np.ndarray | None:
        """Where the caller's pins (:attr:`handles`) are now, caller's coordinates (h, 3)."""
        if self.handles is None:
            return None
        return self._pinned_at[np.searchsorted(self.pinned, self.handles)].copy()

    def pins_at(self, targets) -> bool:
        """Whether the pins are exactly at ``targets`` already."""
        return self.handles is None or np.array_equal(self.pin_positions,
                                                      np.asarray(targets, np.float64))

    # -- moving the pins -----------------------------------------------------------------------

    def move_pins(self, targets) -> MoveResult:
        """Move the pins towards ``targets`` ((h, 3), caller's coordinates, one row per pin
        of :attr:`handles`) as far as the constraints and contacts allow, and make the
        result the current iterate (the flow goes on from it).

        Raises
        ------
        ValueError
            Nothing is pinned, or ``targets`` has the wrong shape or is not finite.
        """
        if self.handles is None:
            raise ValueError("nothing is pinned: give pinned= to move pins")
        T = np.asarray(targets, dtype=np.float64)
        if T.shape != (len(self.handles), 3) or not np.all(np.isfinite(T)):
            raise ValueError(f"targets must be finite, one row (x, y, z) per pin: shape "
                             f"({len(self.handles)}, 3), got {T.shape}")
        X = self.X
        at = np.searchsorted(self.pinned, self.handles)
        T_run = (T - self._shift) / self._scale
        moves = (T_run - X[self.handles])[self._follows]  # per pinned vertex
        if not np.any(moves):
            return MoveResult(1.0)
        D = drag_field(self.layout, self.pinned, moves)

        def trial(t: float):
            Q = X + t * D
            Q[self.pinned] = X[self.pinned] + t * moves
            with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
                Q, ok = self._backproject(Q)
            if not ok:
                return None, "the edges between the pins cannot stretch that far"
            Q[self.pinned] = X[self.pinned] + t * moves  # held to the bit
            if not self._path_is_free(X, Q):
                return None, "it would pass a strand through another or through a mesh"
            return Q, ""

        Q, why = trial(1.0)
        share = 1.0
        if Q is None:  # halve until a share passes, then bisect between it and its double
            hi, lo, best = 1.0, 0.0, None
            for _ in range(PIN_HALVINGS):
                R, fail = trial(0.5 * hi)
                if R is not None:
                    lo, best = 0.5 * hi, R
                    break
                hi, why = 0.5 * hi, fail
            if best is None:
                return MoveResult(0.0, why)
            for _ in range(PIN_BISECTIONS):  # why: the reason of the nearest failing share
                mid = 0.5 * (lo + hi)
                R, fail = trial(mid)
                if R is None:
                    hi, why = mid, fail
                else:
                    lo, best = mid, R
            share, Q = lo, best
        pinned_at = Q[self.pinned] * self._scale + self._shift
        if share == 1.0:  # the pins exactly where they were asked (the caller's bits)
            pinned_at[at] = T
            Q[self.handles] = T_run
        self._commit(Q)
        self._pinned_at = pinned_at
        return MoveResult(share, why)

    def _path_is_free(self, X: np.ndarray, Q: np.ndarray) -> bool:
        """The step's contact test of the straight path ``X`` → ``Q``, with every edge tested
        against the meshes (a step leaves out edges between two pins, which it never moves;
        a pin move does move them)."""
        meshes = self.engine.obstacles
        fixed = None if meshes is None else meshes.fixed
        if meshes is not None:
            meshes.fixed = None
        try:
            return self.engine.path_is_free(X, Q, self.eps)
        finally:
            if meshes is not None:
                meshes.fixed = fixed

    # -- moving the meshes ---------------------------------------------------------------------

    def move_meshes(self, placements) -> MoveResult:
        """Move obstacles and the container towards new placements: ``placements`` maps a
        label of :attr:`mesh_labels` (or its index) to a 4 × 4 affine map of that mesh's
        start position (caller's coordinates); meshes not named stay. Each mesh travels
        straight (vertex by vertex) from where it is; the move is cut where the farthest
        vertex would come nearer the curve than its distance from the moving meshes less
        :data:`MESH_CLEARANCE` contact distances (or tube radii).

        Raises
        ------
        ValueError
            An unknown label, or a map that is not a finite 4 × 4 matrix.
        """
        labels = self.mesh_labels
        targets = [None] * len(labels)
        for key, M in dict(placements).items():
            m = key if isinstance(key, int) else (labels.index(key) if key in labels else -1)
            if not 0 <= m < len(labels):
                raise ValueError(f"no mesh {key!r} in this run; its meshes are "
                                 f"{', '.join(repr(s) for s in labels) or 'none'}")
            M = np.asarray(M, dtype=np.float64)
            if M.shape != (4, 4) or not np.all(np.isfinite(M)):
                raise ValueError(f"the placement of {labels[m]!r} must be a finite 4 × 4 "
                                 f"matrix, got shape {M.shape}")
            if not np.array_equal(M, self.placements[m]):
                targets[m] = M
        moving = [m for m, M in enumerate(targets) if M is not None]
        if not moving:
            return MoveResult(1.0)
        now = [self._mesh_run(m, self.placements[m]) for m in moving]
        then = [self._mesh_run(m, targets[m]) for m in moving]
        reach = max(float(np.sqrt(np.max(np.sum((b - a) ** 2, axis=1))))
                    for a, b in zip(now, then, strict=True))
        sub = ObstacleField([(V, self._meshes[m][2]) for m, V in zip(moving, now, strict=True)])
        d = sub.nearest(self.X, self.layout.nxt)[2]
        need = MESH_CLEARANCE * max(self.eps, self.engine.radius)
        share = 1.0 if reach <= d - need else max(0.0, (d - need) / reach)
        if share <= 0.0:
            return MoveResult(0.0, "a mesh would touch the curve")
        for m in moving:
            M0, M1 = self.placements[m], targets[m]
            # vertices linear in the map: the map between is the vertices' straight path
            self.placements[m] = M1 if share == 1.0 else M0 + share * (M1 - M0)
        self._rebuild_meshes()
        self._commit(self.X)
        return MoveResult(share, "" if share == 1.0 else "a mesh would touch the curve")

    def _mesh_run(self, m: int, M: np.ndarray) -> np.ndarray:
        """Vertices of mesh ``m`` under the placement ``M``, in the run's coordinates."""
        V = self._meshes[m][1] @ M[:3, :3].T + M[:3, 3]
        return (V - self._shift) / self._scale

    def _rebuild_meshes(self) -> None:
        meshes = [(self._meshes[m][1] @ M[:3, :3].T + M[:3, 3], self._meshes[m][2])
                  for m, M in enumerate(self.placements)]
        old = self.engine.obstacles
        labels = old.labels if old is not None else self.mesh_labels
        new = ObstacleField(meshes, self._shift, self._scale, self._obstacle_weight, labels,
                            auto_obstacle_tol(self._obstacle_tol, self.layout, meshes))
        new.fixed = self.pinned
        self.engine.obstacles = new

    # -- growing -------------------------------------------------------------------------------

    def grow(self, factor: float) -> None:
        """Grow the curves' total length towards ``factor`` (≥ 1) times their length at the
        start as the flow goes on, by ``length_growth`` (default 1 %) per iteration, or
        shrink it back towards a smaller factor (Live's *Grow* slider). Each grown polygon is
        reached by a straight path tested for contact like a step's; growth with no room
        halves and, blocked :data:`.projected._GROWTH_PATIENCE` iterations in a row, rests
        until the next move or call.

        Raises
        ------
        ValueError
            ``factor`` below 1 or not finite, or a run that cannot grow (without edge-length
            constraints, or with every edge of a component between two pins).
        """
        sched = self.growth_schedule
        if sched is None:
            if factor == 1.0:
                return
            sched = self._check_growth(self.length, self._growth_rate, self._edge_lengths)
        sched.retarget(factor)
        self.growth_schedule = sched
        self.length_factor = float(factor)
        self._blocked = 0
        if self._growing:
            self._wake()

    @property
    def length(self) -> float:
        """The curves' total length now (caller's units)."""
        ln = self.lengths0[self.layout.real] if self.layout.has_open else self.lengths0
        return float(ln.sum()) * self._scale

    # -- shared ----------------------------------------------------------------------------------

    def _wake(self) -> None:
        """A rested run goes on (something was moved or changed)."""
        self._settle_from = None
        self._still = 0
        if self.done:
            self.done, self.success, self.message = False, False, ""
            self.status = Status.NOT_FINISHED

    def _commit(self, Q: np.ndarray) -> None:
        """``Q`` (feasible, reached by a tested path) becomes the iterate; a rested run goes
        on."""
        self._prepare(Q, *self.engine.energy_gradient(Q))
        self.moves += 1
        self._wake()


def _is_mesh(obj) -> bool:
    return isinstance(obj, tuple) and len(obj) == 2 and not isinstance(obj[0], tuple)


def _stacked(pinned, layout) -> np.ndarray:
    """The caller's ``pinned`` (a list, or one per component) as sorted stacked indices."""
    if layout.is_link:
        idx = np.concatenate([layout.starts[c] + np.asarray(p, dtype=np.int64).reshape(-1)
                              for c, p in enumerate(pinned)])
    else:
        idx = np.asarray(pinned, dtype=np.int64).reshape(-1)
    return np.unique(idx)


@dataclass
class LiveFrame:
    """One state of a live run: ``seq`` counts them from 0 (the start), ``parts`` the curve
    (one array per component, caller's coordinates), ``kind`` what made it (``"start"``,
    ``"step"``, ``"pins"``, ``"meshes"``), ``placements`` where the meshes were,
    ``clipped`` why the last move was cut (empty: it was not), ``time`` when it was made
    (``time.perf_counter``)."""

    seq: int
    parts: list
    energy: float
    nit: int
    kind: str
    placements: list = field(default_factory=list)
    clipped: str = ""
    time: float = 0.0


class LiveDriver:
    """A :class:`LiveRelaxation` run in a background thread.

    The caller posts targets (:meth:`post`: pins, mesh placements; the latest wins) and
    takes states: :meth:`latest` for display, :attr:`record` (every state, when ``record``)
    for an animation whose straight moves between states were all tested for contact.

    Parameters
    ----------
    run : LiveRelaxation
    record : bool
        Keep every state in :attr:`record`, the start first.
    pause : float
        Seconds the thread sleeps after each state, so that the caller's thread gets the GIL
        (numba's kernels hold it while they run).
    threads : int or None
        numba threads of the run's kernels (numba's setting is per thread: the caller's stay
        as they are); None: one fewer than numba has, at least one, leaving a core to the
        caller's timer and drawing, which otherwise stalled the parallel kernels
        (docs/blender.md, "Live relax").
    """

    def __init__(self, run: LiveRelaxation, record: bool = False, pause: float = 0.002,
                 threads: int | None = None):
        self.run = run
        self.pause = float(pause)
        most = numba.config.NUMBA_NUM_THREADS
        self.threads = max(1, most - 1) if threads is None else min(max(1, int(threads)), most)
        self.recording = bool(record)
        self.record: list[LiveFrame] = []
        #: an exception the thread met (the run stops then); None while all is well
        self.error: BaseException | None = None
        #: why the last move was cut, while it is (empty otherwise)
        self.clipped = ""
        #: why the last growth asked for was refused (empty otherwise)
        self.refused = ""
        self._lock = threading.Lock()
        self._wake = threading.Event()
        self._quit = threading.Event()
        self._pins = None
        self._placements: dict = {}
        self._grow = None
        self._seq = 0
        self._latest = self._frame("start")
        if self.recording:
            self.record.append(self._latest)
        self._taken = -1
        self._idle = threading.Event()
        self._thread = threading.Thread(target=self._work, name="moebius-live", daemon=True)
        self._thread.start()

    def post(self, pins=None, placements: Mapping | None = None,
             grow: float | None = None) -> None:
        """New targets: ``pins`` for :meth:`LiveRelaxation.move_pins`, ``placements`` (label
        → 4 × 4) for :meth:`LiveRelaxation.move_meshes`, ``grow`` for
        :meth:`LiveRelaxation.grow` (checked here: a bad factor raises in the caller's
        thread); None keeps the earlier ones."""
        if grow is not None:
            grow = float(check_number("grow", grow, 1.0))
        with self._lock:
            if grow is not None:
                self._grow = grow
            if pins is not None:
                self._pins = np.array(pins, dtype=np.float64)
            if placements:
                self._placements.update({k: np.array(v, dtype=np.float64)
                                         for k, v in placements.items()})
        self._wake.set()

    def latest(self, new_only: bool = True) -> LiveFrame | None:
        """The newest state (None when ``new_only`` and it was taken already)."""
        frame = self._latest
        if new_only and frame.seq == self._taken:
            return None
        self._taken = frame.seq
        return frame

    @property
    def alive(self) -> bool:
        return self._thread.is_alive()

    def close(self, timeout: float | None = 30.0) -> None:
        """Stop the thread after the state it is making (it is joined)."""
        self._quit.set()
        self._wake.set()
        self._thread.join(timeout)

    def wait_idle(self, timeout: float = 10.0) -> bool:
        """Wait until the run rests (converged, targets reached or blocked); for scripts and
        tests that post a move and want its outcome. True if it rested in time."""
        end = time.perf_counter() + timeout
        while time.perf_counter() < end and self.alive:
            if self._idle.is_set():
                return True
            time.sleep(0.005)
        return self._idle.is_set()

    def _frame(self, kind: str, clipped: str = "") -> LiveFrame:
        run = self.run
        x = run.x
        parts = [np.array(p) for p in (x if isinstance(x, list) else [x])]
        frame = LiveFrame(self._seq, parts, float(run.energy), run.nit, kind,
                          [M.copy() for M in run.placements], clipped, time.perf_counter())
        self._seq += 1
        return frame

    def _publish(self, kind: str, clipped: str = "") -> None:
        frame = self._frame(kind, clipped)
        if self.recording:
            self.record.append(frame)
        self._latest = frame

    def _work(self) -> None:
        numba.set_num_threads(self.threads)
        run = self.run
        try:
            while not self._quit.is_set():
                with self._lock:
                    pins, placements, grow = self._pins, dict(self._placements), self._grow
                if grow is not None and grow != run.length_factor:
                    try:
                        run.grow(grow)
                        self.refused = ""
                    except ValueError as err:  # the run goes on at its length
                        self.refused = f"grow refused: {err}"
                        with self._lock:
                            if self._grow == grow:
                                self._grow = None
                did = False
                cut = []
                if pins is not None and not run.pins_at(pins):
                    before = run.moves
                    res = run.move_pins(pins)
                    if res.clipped:
                        cut.append(f"pin move clipped at contact: {res.reason}")
                    if run.moves > before:
                        self._publish("pins", "; ".join(cut))
                        did = True
                if placements:
                    before = run.moves
                    res = run.move_meshes(placements)
                    if res.clipped:
                        cut.append(f"mesh move clipped at contact: {res.reason}")
                    if run.moves > before:
                        self._publish("meshes", "; ".join(cut))
                        did = True
                    with self._lock:  # reached: forget them (a newer post stays)
                        for k, M in placements.items():
                            label_m = k if isinstance(k, int) else run.mesh_labels.index(k)
                            if (np.array_equal(run.placements[label_m], M)
                                    and self._placements.get(k) is M):
                                del self._placements[k]
                self.clipped = "; ".join(cut)
                if not self._quit.is_set() and not run.done:
                    nit = run.nit
                    run.step()
                    if run.nit != nit:
                        self._publish("step", self.clipped)
                        did = True
                if did:
                    self._idle.clear()
                    time.sleep(self.pause)  # the caller's thread takes the GIL here
                else:
                    self._idle.set()
                    self._wake.wait(0.05)
                    self._wake.clear()
        except BaseException as err:  # noqa: BLE001 - handed to the caller, who reports it
            self.error = err
        finally:
            self._idle.set()
