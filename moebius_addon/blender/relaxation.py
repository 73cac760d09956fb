"""The relaxation of a curve object: the method chosen for it, the stepper the modal operator
drives (:class:`ObjectRelaxation`) and the blocking call scripts use (:func:`relax_object`)."""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence

import bpy
import numpy as np

from .. import core
from ..core.compilation.notice import compiling
from ..core.energies.choice import ENERGY_OPTIONS
from ..core.runs.aliases import take_spelling
from . import geometry, keyframes, scene_constraints
from .gradients import refresh_gradients
from .group import bevel_thickness, group_name, members, name_components
from .identification import type_kept
from .labels import (
    AUTO_METHOD,
    DEFAULT_ENGINE,
    DEFAULT_METHOD,
    DEFAULT_SETTLE,
    EXPLICIT_METHOD,
    KNOT_METHOD,
    PENALTY_METHODS,
    method_label,
)
from .options import check_edge_count, check_relax_options, edge_limit
from .polygons import as_input, as_link
from .progress import Progress, reporter
from .rest import rest_shape, set_rest_shape

# Whether a run reached its first iterate in this Blender session: the first one pays for the
# numerical kernels (numba compiles them once per installation, later sessions load them from
# its cache) before its first iterate; see docs/blender.md, Install, for the times measured.
_SESSION = {"warm": False}
#: Largest relative spread of edge lengths in a spline that Relax takes as converted when the
#: add-on did not make the curve (Blender keeps points in single precision: a converted
#: curve's edges agree to about 1e-7).
EQUAL_EDGES = 1e-3


def check_converted(obj: bpy.types.Object, polygons: Sequence[np.ndarray],
                    closed: Sequence[bool]) -> None:
    """ValueError for a poly curve that was never converted: one whose splines have edges of
    unequal length (beyond :data:`EQUAL_EDGES`) and that the add-on did not make (a converted,
    added or relaxed curve stores its rest shape, and a run keeps the lengths it has).
    Relax used to key such a curve silently, taking its uneven edges as targets."""
    if rest_shape(obj) is not None:
        return
    for k, (P, c) in enumerate(zip(polygons, closed, strict=True)):
        e = np.linalg.norm(np.diff(np.vstack([P, P[:1]]) if c else P, axis=0), axis=1)
        if len(e) == 0 or e.min() <= 0:  # repeated points: the core's check says so
            continue
        ratio = float(e.max() / e.min())
        if ratio - 1.0 > EQUAL_EDGES:
            try:  # a curve through itself hears that first: converting would not help
                core.check_polygon(as_input(polygons), coarseness=False,
                                   closed=closed[0] if len(closed) == 1 else list(closed))
            except ValueError as err:
                raise ValueError(f"'{obj.name}': {err}") from None
            where = f"'{obj.name}'" + (f" (component {k + 1})" if len(polygons) > 1 else "")
            raise ValueError(
                f"{where} was not converted: its edges differ in length (the longest is "
                f"{ratio:.4g} times the shortest); convert it first (Möbius ▸ Polygon ▸ "
                "Convert), which gives every edge the same length")


def choose_method(method: str, polygons: Sequence[np.ndarray]) -> tuple[str, str]:
    """The core method a run of ``method`` uses on ``polygons``, and why (empty unless
    ``method`` is :data:`AUTO_METHOD`): :data:`KNOT_METHOD` for a link, and for one
    component whose knot determinant is above 1 (``core.knot_determinant``: certainly
    knotted), else :data:`EXPLICIT_METHOD` (unknots and the rare knots of determinant 1).
    Links: the implicit method converged on all ten links of the untangling benchmark in
    1.5–77 s of CPU, where the explicit one stopped at 5 000 iterations on five
    (docs/lab/flows-and-methods.md, "The automatic method")."""
    if method != AUTO_METHOD:
        return method, ""
    if len(polygons) != 1:
        return KNOT_METHOD, f"a link of {len(polygons)} components"
    try:
        det = core.knot_determinant(polygons[0])
    except ValueError:  # too tangled to read (core.invariants refuses it before the work)
        return EXPLICIT_METHOD, "knot type not read: too many crossings"
    if det > 1:
        return KNOT_METHOD, f"knotted, determinant {det}"
    return EXPLICIT_METHOD, "no knot detected"


def method_hint(method: str, result, polygons: Sequence[np.ndarray],
                closed: bool = True, grows: bool = False) -> str:
    """Advice appended to the report of an explicit run that hit its iteration limit on a
    knotted curve (``polygons``: its start): the explicit flow's last stretch on a knot is
    slow (docs/lab/flows-and-methods.md, "Knots of the table"). Decided by ``result.status``,
    never by the words of the message; unknots and links get none (the explicit method is the
    faster one on unknots; Automatic gives links the implicit one), nor a run that grows the curve
    (``grows``: the implicit method cannot)."""
    if (method != EXPLICIT_METHOD or result.status != core.Status.MAX_ITER or not closed
            or (grows and KNOT_METHOD not in core.runs.methods.GROWING)):
        return ""
    try:
        if len(polygons) != 1 or not core.is_knotted(polygons[0]):
            return ""
    except ValueError:  # too tangled to read
        return ""
    label = method_label(KNOT_METHOD)
    return f"; knots settle in fewer iterations with Advanced ▸ Method: {label}"


class Preparation:
    """The kernels of a run prepared in a background thread (``core.warm`` on small curves:
    numba compiles them, or loads them from its cache), so that a window stays responsive
    while a first run waits (the modal *Relax*). ``done``, ``seconds``, ``kernels`` (compiled
    so far), ``error`` (an exception of the warm-up: the run itself will meet and report it)."""

    def __init__(self, paths: Sequence[str]) -> None:
        import threading

        self.paths = tuple(paths)
        self.t0 = time.perf_counter()
        self.error: BaseException | None = None
        self._watch = None
        self._end: float | None = None
        self._thread = threading.Thread(target=self._warm, name="moebius-prepare", daemon=True)
        self._thread.start()

    def _warm(self) -> None:
        try:
            with compiling() as self._watch:
                core.warm(self.paths, say=None)
        except Exception as err:  # noqa: BLE001 - reported by the run, which meets it again
            self.error = err
        finally:
            self._end = time.perf_counter()

    @property
    def done(self) -> bool:
        return not self._thread.is_alive()

    @property
    def kernels(self) -> int:
        return self._watch.kernels if self._watch is not None else 0

    @property
    def seconds(self) -> float:
        """Seconds since the start, until done."""
        return (self._end or time.perf_counter()) - self.t0

    def wait(self, timeout: float | None = None) -> bool:
        self._thread.join(timeout)
        return self.done


def solver_paths(obj: bpy.types.Object, engine: str = DEFAULT_ENGINE) -> list[str]:
    """The paths of ``core.warm`` a run on ``obj`` meets first: ``"open"`` for an open curve,
    ``"tree"`` where the tree engine runs (``engine``, or from ``core.runs.engine.AUTO_TREE_FROM``
    points on with ``"auto"``), else ``"exact"``."""
    splines = obj.data.splines
    if not all(sp.use_cyclic_u for sp in splines):
        return ["open"]
    n = sum(len(sp.points) for sp in splines)
    if engine in core.runs.engine.ENGINE_NAMES and core.runs.engine.uses_tree(engine, n, run=True):
        return ["tree"]
    return ["exact"]


def solver_warm() -> bool:
    """Whether a relaxation has reached its first iterate in this session, so that the
    numerical kernels are ready (False: the next run prepares them first, see
    :attr:`ObjectRelaxation.first_run`)."""
    return _SESSION["warm"]


def at_count(link: Sequence[np.ndarray], sizes: Sequence[int],
             closed: Sequence[bool]) -> list[np.ndarray]:
    """``link`` with component ``c`` at ``sizes[c]`` points: split edges (``core.subdivide``,
    the same curve) to more, or every k-th point to fewer — the counts of a refined run are
    whole multiples of each other's edges."""
    out = []
    for P, size, cl in zip(link, sizes, closed, strict=True):
        n = len(P)
        edges, target = (n, size) if cl else (n - 1, size - 1)
        if size > n:
            out.append(core.subdivide(P, target // edges, cl))
        elif size < n:
            out.append(np.ascontiguousarray(P[:: edges // target]))
        else:
            out.append(P)
    return out


class ObjectRelaxation:
    """A relaxation of a curve object, or of several relaxed together as one system, stepped
    by a caller that may stop it at any time.

    The modal operator steps it on a timer; :func:`relax_object` steps it in a loop. The start
    and every ``keyframe_stride``-th accepted iterate (and always the last) are recorded and
    keyframed by :meth:`finish`.

    Parameters
    ----------
    obj : bpy.types.Object or sequence of them
        Curve of cyclic poly splines (see :func:`convert_object`); its shape at the current frame
        is the start. Earlier flow keyframes on it are replaced by this run's when it finishes.
        Several curve objects (an artist's cables, each its own object) relax together: no
        strand of one comes nearer another than strands of one object do; each keeps its own
        data, pins and keys; the run works in the first one's coordinates (:mod:`.group`).
    metric : str
        ``"hs"``, ``"hs_pure"``, ``"h2"``, ``"h1"`` or ``"l2"``.
    max_iterations : int
        Stop after this many accepted iterates (``max_iter`` of ``core.relax``, also accepted
        under that name).
    tolerance : float
        Stop once the gradient norm in the metric is this small (``tol`` of ``core.relax``,
        also accepted under that name; projected onto the constraints for the feasible
        methods).
    frame_start : int
        Frame of the start shape.
    keyframe_stride : int
        Keyframe every this many iterates (1 = all).
    append : bool
        Continue the flow keyed on ``obj``: start from its last keyed iterate and key the new
        iterates on the frames after it, keeping the earlier keys (``frame_start`` is not
        used then). Without flow keys on ``obj`` this is a new run from the current shape.
    method : str
        ``"auto"`` (default; :func:`choose_method` decides from the start, the attributes
        ``method`` and ``why`` say what ran) or one of ``core.METHODS`` (run by
        ``core.make_run``); ``requested`` keeps what was asked.
    penalty : float, optional
        Weight α of the edge-stretch penalty, for the penalty methods ``"ncg"``, ``"lbfgs"``
        and ``"nesterov"`` only (None: the core's default, 1e4); positive and finite.
    engine : str
        ``"auto"`` (default: the tree from ``AUTO_TREE_FROM`` edges on), ``"exact"`` or
        ``"tree"`` (``core.make_run``); the attribute ``engine`` says which one runs.
    theta : float, optional
        Admissibility θ of the tree in (0, 2) (None: the core's ``barnes_hut.THETA``).
    refine : bool
        Adaptive resolution (``core.make_run``): a curve too coarse for its shape, or whose
        strands jam during the run, is split into twice the points (the same curve) and the
        run goes on; the whole animation is keyed at the final count (earlier frames split
        the same way, so nothing jumps) and the curve keeps it. False: refused or stopped
        as before.
    max_edges : int, optional
        Refine no further than this many edges (None or 0: the core's default, four times
        the start's, at least 2 000; never above what :func:`~.options.check_edge_count`
        takes). A curve with shape keys of its own is not refined (its keys would not fit).
    restarts, seed : int
        Restarts after a converged run from nudged copies of the result, kept if lower
        (``core.make_run``; the feasible methods).
    **options
        Passed on to the core's run (``initial_step``, ``armijo``, ``growth``,
        ``backproject_iter``, ``backproject_tol``, ``edge_lengths``, ``barycenter``,
        ``energy_target``, ``ftol``, ``max_seconds``, and the method's own options); the
        penalty methods ignore the options that need hard constraints. ``allow_large=True``
        lifts :data:`~.options.EDGE_LIMIT` (never the core's own size refusals). Pins and
        obstacles (:mod:`.scene_constraints`): ``thickness=`` a tube radius kept between
        strands and from the meshes (the first curve's units), or ``"bevel"``: the curves'
        largest bevel depth (0 for the penalty methods, which cannot keep one; default 0:
        centre lines only), ``push_apart=True`` (a start whose tubes meet is not refused:
        the tubes thicken as the flow pushes the strands apart); ``pinned=`` indices (a list
        per spline for a link) or ``pin_selected=True`` (the points selected in Edit Mode),
        ``pin_tangents``;
        ``obstacles=`` a collection, a list of mesh objects or the core's ``(V, F)`` arrays
        (in the curve's object coordinates), ``obstacle_weight``; ``container=`` a closed mesh
        object (or the core's ``(V, F)``) the curve stays inside. ``length_target=`` (object
        units) and ``length_growth=`` (a fraction per iteration): the curve's length grows to
        the target during the run (``core.relax``; Automatic runs the projected gradient).

    Raises
    ------
    ValueError
        If the curve is not a closed poly curve, the core refuses it (touching itself, too many
        edges for the metric and engine, ...), or the method, penalty, engine or θ is invalid;
        nothing is changed then.
    """

    def __init__(self, obj: bpy.types.Object, metric: str = "hs", max_iterations: int = 200,
                 tolerance: float = 1e-6, frame_start: int = 1, keyframe_stride: int = 1,
                 method: str = DEFAULT_METHOD, penalty: float | None = None,
                 append: bool = False, engine: str = DEFAULT_ENGINE,
                 theta: float | None = None, refine: bool = True, max_edges: int | None = None,
                 restarts: int = 0, seed: int = 0, **options) -> None:
        max_iterations = take_spelling(options, "max_iterations", max_iterations, 200)
        tolerance = take_spelling(options, "tolerance", tolerance, 1e-6)
        self.t0 = time.perf_counter()
        #: the first run of the session: it prepares the solver before its first iterate
        self.first_run = not _SESSION["warm"]
        #: seconds from the set-up to the first iterate (None before it)
        self.seconds_to_first: float | None = None
        max_iterations, tolerance, keyframe_stride, frame_start, extra = check_relax_options(
            max_iterations, tolerance, keyframe_stride, frame_start, method, penalty, engine,
            theta)
        options.update(extra)
        try:  # the energy and its exponents, before any work
            choice = core.check_energy(**{k: options[k] for k in ("energy", *ENERGY_OPTIONS)
                                          if k in options})
        except ValueError as err:
            raise ValueError(f"'{obj.name}': {err}") from None
        #: which energy the flow minimizes and keys ("moebius", "tangent_point(2, 4.5)")
        self.energy_label = choice.label
        #: the energy as a choice of the core (its tooltip words, its row name)
        self.energy_choice = choice
        #: the curve objects of the run (:mod:`.group`), the first one's coordinates the run's
        self.members = members(obj)
        obj = self.members[0].obj
        #: the objects in words, for reports: 'Knot', or 'Cable' and 9 other curves
        self.name = group_name([m.obj for m in self.members])
        polygons = [P for m in self.members for P in m.to_run(m.polygons)]
        closed = [c for m in self.members for c in m.closed]
        self._closed = closed
        #: whether a spline is open (an open curve: the core's closed=False, exact engine)
        self.open = not all(closed)
        if self.open:
            options["closed"] = closed if len(closed) > 1 else closed[0]
        for m in self.members:
            keyframes.check_flow_target(m.obj)
        try:  # obstacles as (V, F) arrays, selected points as pins
            options = scene_constraints.resolve([m.obj for m in self.members], options)
        except ValueError as err:
            raise ValueError(f"{self.name}: {err}") from None
        # the earlier flow keys, continued from their last iterate (read by show() otherwise)
        if append:
            polygons, frame_start = self._read_prior(polygons, frame_start)
        continued = append and self.members[0].prior is not None
        allow_large = options.pop("allow_large", False)
        try:  # before any work: no size may crash the process
            check_edge_count(sum(len(p) for p in polygons), metric, method, engine,
                             allow_large, edge_lengths=options.get("edge_lengths", True),
                             barycenter=options.get("barycenter", True))
            if not isinstance(refine, bool):
                raise ValueError(f"refine must be True or False, got {refine!r}")
        except ValueError as err:
            raise ValueError(f"'{obj.name}': {err}") from None
        for m in self.members:  # after the size: no work before either
            check_converted(m.obj, m.to_local(polygons[m.span]) if continued else m.polygons,
                            m.closed)
        try:  # a curve too coarse for its shape is refined by the core when refine is on
            core.check_polygon(as_input(polygons), closed=options.get("closed", True),
                               coarseness=not refine)
        except ValueError as err:
            raise ValueError(f"{self.name}: {name_components(str(err), self.members)}"
                             ) from None
        #: the notes of the refinement settings (e.g. why a curve is not refined)
        self.refine_note = ""
        if refine:
            max_edges = self._max_edges(obj, polygons, closed, max_edges, metric, method,
                                        engine, allow_large)
        options.setdefault("target_lengths", "keep")
        options.setdefault("settle", DEFAULT_SETTLE)  # the keys end where the motion ends
        self.obj = obj
        #: the method asked for (may be ``"auto"``), the core method run, and why
        self.requested = method
        self.method, self.why = (
            (EXPLICIT_METHOD, "an open curve") if self.open and method == AUTO_METHOD
            else (EXPLICIT_METHOD, "length growth") if (
                method == AUTO_METHOD and options.get("length_target") is not None)
            else choose_method(method, polygons))
        #: whether the run grows the curve's length (Length Target)
        self.grows = options.get("length_target") is not None
        if self.grows and self.method not in core.runs.methods.GROWING:
            raise ValueError(
                f"Advanced ▸ Method: {method_label(self.method)} cannot grow the curve's length "
                f"(Length Target): choose "
                f"{' or '.join(method_label(m) for m in core.runs.methods.GROWING)}, or Automatic")
        if method == AUTO_METHOD and self.method != EXPLICIT_METHOD:
            # the panel's Armijo constant and step growth are the explicit method's; the
            # implicit one keeps its own (core.METHODS), but bad values are refused all the same
            core.runs.projected.check_line_search(options.pop("armijo", 0.5),
                                                     options.pop("growth", 8.0))
        self.append = continued
        self.frame_start = int(frame_start)
        self.stride = int(keyframe_stride)
        # make_run("projected_gradient", ...) is core.Relaxation itself: the default is the
        # same run as before methods existed
        thickness = options.pop("thickness", 0.0)
        if isinstance(thickness, str):
            if thickness != "bevel":
                raise ValueError(f"thickness must be a radius (the first curve's units) or "
                                 f"'bevel', got {thickness!r}")
            keeps = self.method not in PENALTY_METHODS and options.get("edge_lengths", True)
            thickness = bevel_thickness(self.members) if keeps else 0.0
        #: the tube radius the run keeps, in the first object's units (0: centre lines only)
        self.thickness = thickness
        if thickness:
            options["thickness"] = thickness
        else:
            options.pop("push_apart", None)  # no tubes to push apart to
        try:
            self.run = core.make_run(self.method, as_input(polygons), metric=metric,
                                     max_iter=max_iterations, tol=tolerance, refine=refine,
                                     max_edges=max_edges, restarts=restarts, seed=seed,
                                     **options)
        except ValueError as err:  # the core's words, its components named as objects
            raise ValueError(f"{self.name}: {name_components(str(err), self.members)}"
                             ) from None
        #: the engine that runs ("exact" or "tree": "auto" resolved by the curve's size)
        self.engine = self.run.engine.name
        self.start = [p.copy() for p in polygons]
        self.x = [p.copy() for p in polygons]
        self.energy = float(np.sum(self.run.energy))
        self.nit = 0
        self.iterates = [self.start]
        self.energies = [self.energy]
        self._nits = [0]  # the run's iteration of each record (a rollback drops later ones)
        self._pending = None
        # the earlier run's keys stay until this run's are written (finish), so that a run
        # that fails before its first iterate leaves them; live display removes them first
        self._live = False
        #: set by finish(): whether the invariants are the same before and after, and a line
        #: saying so ("knot type kept: 3_1 (trefoil) …"; None: they could not be read)
        self.type_kept: bool | None = None
        self.type_message = ""

    def _max_edges(self, obj, polygons, closed, max_edges, metric, method, engine,
                   allow_large) -> int:
        """``max_edges`` of the core's run: as asked (default the core's), no more than a run
        here takes, and no growth at all for a curve with shape keys of its own."""
        n = sum(len(p) - (0 if c else 1) for p, c in zip(polygons, closed, strict=True))
        asked = core.check_number("max_edges", max_edges or 0, 0, integer=True)
        wanted = asked or core.default_max_edges(n)
        for o in (m.obj for m in self.members):
            if o.data.shape_keys is not None and not keyframes.is_flow_key(o.data):
                self.refine_note = ("not refined: the curve has shape keys of its own"
                                    if len(self.members) == 1 else
                                    f"not refined: '{o.name}' has shape keys of its own")
                return n
        if allow_large:
            return wanted
        return min(wanted, max(n, edge_limit(metric, method, engine)))

    def _read_prior(self, polygons, frame_start):
        """Continue: every object's flow keys (the same frames on each), their last iterate
        the start in the run's coordinates, and its frame."""
        for m in self.members:
            m.prior = keyframes.read_flow_keyframes(m.obj)
            keyed = m.obj.get(keyframes.ENERGY_NAME_PROP, core.energies.DEFAULT_ENERGY)
            if m.prior is not None and keyed != self.energy_label:
                raise ValueError(
                    f"'{m.obj.name}': its keyed flow minimized the {keyed} energy, not "
                    f"{self.energy_label}: continue with that energy, or Clear Flow first")
        keyed = [m for m in self.members if m.prior is not None]
        if not keyed:
            return polygons, frame_start
        first = keyed[0]
        for m in self.members:
            if m.prior is None or not np.array_equal(m.prior[0], first.prior[0]):
                raise ValueError(
                    f"'{m.obj.name}' and '{first.obj.name}' were not keyed by one run (their "
                    "flow keys differ): Continue relaxes curves keyed together; select those, "
                    "or Clear Flow and Relax them together")
        polygons = [P for m in self.members
                    for P in m.to_run(np.split(m.prior[1][-1], m.cuts))]
        return polygons, int(first.prior[0][-1])

    def step(self) -> bool:
        """Advance by one accepted iterate; False once the run has finished.

        The run may also go back (a refinement goes on from an earlier iterate, a restart that
        did not pay is dropped): the records after that iterate are dropped with it."""
        last = self.nit
        more = self.run.step()
        nit = self.run.nit
        if nit < last:
            while self._nits[-1] > nit:
                self._nits.pop()
                self.iterates.pop()
                self.energies.pop()
            if self._pending is not None and self._pending[2] > nit:
                self._pending = None
        if nit != last or len(self.run.x) != len(self.x):
            x = as_link(self.run.x)
            self.x = x
            self.energy = float(np.sum(self.run.energy))
        if nit > last:  # an accepted iterate (the last one may come with False)
            if self.seconds_to_first is None:
                self.seconds_to_first = time.perf_counter() - self.t0
                _SESSION["warm"] = True
            # recorded as Blender keys them, in single precision (half the memory of the
            # record of a large run)
            keyed = [p.astype(np.float32) for p in self.x]
            if nit % self.stride == 0:
                self.iterates.append(keyed)
                self.energies.append(self.energy)
                self._nits.append(nit)
                self._pending = None
            else:
                self._pending = (keyed, self.energy, nit)
        elif nit < last and self._nits[-1] != nit:  # back at an iterate that was not kept
            self._pending = ([p.astype(np.float32) for p in self.x], self.energy, nit)
        self.nit = nit
        return more

    def stop(self, message: str) -> None:
        """Stop the run (e.g. the user pressed Esc); :meth:`finish` still keyframes it."""
        self.run.stop(message)

    def show(self) -> None:
        """Put the current iterate on the curves (for live display while running; the earlier
        run's keys are removed at the first call, or they would pull the curves back)."""
        if not self._live:
            for m in self.members:
                if m.prior is None:  # kept to be put back by restore() after a failure
                    try:
                        m.prior = keyframes.read_flow_keyframes(m.obj)
                    except ValueError:  # keys edited by hand: a new run replaces them anyway
                        pass
                keyframes.remove_flow_keyframes(m.obj)
            self._live = True
        # a refined iterate has more points than the curve: every k-th is the same shape to
        # the eye (the curve grows to the refined count when the run is keyed)
        sizes = [len(p) for m in self.members for p in m.polygons]
        shown = at_count(self.x, sizes, self._closed)
        for m in self.members:
            geometry.write_polygons(m.obj.data, m.to_local(shown[m.span]))

    def restore(self) -> None:
        """Undo :meth:`show` after a failure: the earlier flow keys (removed for the live
        display) written back and the curves as they were shown before the run."""
        for m in self.members:
            if self._live and m.prior is not None:
                frames, points, energies = m.prior
                keyframes.write_flow_keyframes(m.obj, [np.split(X, m.cuts) for X in points],
                                               list(energies), int(frames[0]))
            geometry.write_polygons(m.obj.data, m.polygons)

    def refinement_text(self, result) -> str:
        """What the run refined, in a line: "100 → 200 edges at iteration 0 (start too
        coarse)", several joined by "; "; or why it did not refine ("" when nothing to say)."""
        lines = [_refinement_line(r) for r in getattr(result, "refinements", [])]
        if not lines and self.refine_note:
            return self.refine_note
        return "; ".join(lines)

    def finish(self, scene: bpy.types.Scene | None = None):
        """Keyframe the recorded iterates and return the core's result.

        Grows the scene frame range to include the keyed frames (it never shrinks it: other
        animation may need the rest), jumps to the last one and stores the statistics in
        ``scene.moebius`` (when the add-on is registered).

        Returns
        -------
        result
            The core run's ``result()`` (``x``, ``fun``, ``nit``, ``success``, ``message``,
            ``history``; the penalty methods' history also has ``penalized_energy``).
        """
        scene = scene or bpy.context.scene
        result = self.run.result()
        if self._pending is not None:
            self.iterates.append(self._pending[0])
            self.energies.append(self._pending[1])
            self._pending = None
        # a refined run ends with more points than it started with: every record, the earlier
        # keys and the rest shape are split the same way (the same curves), the curve grown
        sizes = [len(p) for p in as_link(result.x)]
        iterates = [at_count(link, sizes, self._closed) for link in self.iterates]
        for m in self.members:  # each object keys its own splines, in its own coordinates
            frames = self._key_member(m, sizes[m.span], [m.to_local(link[m.span])
                                                         for link in iterates])
        scene.frame_start = min(scene.frame_start, frames.start)
        scene.frame_end = max(scene.frame_end, frames.stop - 1)
        scene.frame_set(frames.stop - 1)
        for m in self.members:  # drawn at the start, they would show a stale field
            refresh_gradients(m.obj)
        # the flow never passes a strand through another: the same invariants at both ends
        self.type_kept, self.type_message = (None, "an open curve has no knot type") if (
            self.open) else type_kept(self.start, as_link(result.x))
        stats = getattr(scene, "moebius", None)
        if stats is not None:
            # the end as the result reports it (on the tree: its exact energy, core.runs.engine)
            stats.store_run(self.obj.name if len(self.members) == 1 else self.name, self.nit,
                            self.energies[0], float(result.fun),
                            time.perf_counter() - self.t0, str(result.message), len(frames),
                            self.method, self.engine, self.type_message,
                            refined=self.refinement_text(result),
                            energy_name=self.energy_label,
                            energy_row=self.energy_choice.short_label)
        return result


    def _key_member(self, m, sizes: list[int], iterates: list[list[np.ndarray]]) -> range:
        """Key ``iterates`` (this run's, in ``m``'s coordinates, at ``sizes`` points) on
        ``m``'s object after its earlier keys when continued; returns the keyed frames."""
        obj, closed = m.obj, m.closed
        rest_before = rest_shape(obj)
        energies, first = self.energies, self.frame_start
        if self.append:  # the earlier keys, then this run's from the last of them on
            frames0, points, energies0 = m.prior
            iterates = [at_count(np.split(X, m.cuts), sizes, closed)
                        for X in points[:-1]] + iterates
            energies = list(energies0[:-1]) + energies
            first = int(frames0[0])
        if sizes != [len(s.points) for s in obj.data.splines]:
            geometry.grow_splines(obj.data, sizes)
            if self.append and rest_before is not None:
                set_rest_shape(obj, at_count(rest_before, sizes, closed))
        if not self.append:
            set_rest_shape(obj, at_count(m.to_local(self.start[m.span]), sizes, closed))
        # the curve's own (unanimated) shape: the rest shape Clear Flow goes back to
        rest = rest_shape(obj)
        geometry.write_polygons(obj.data, iterates[0] if rest is None else rest)
        return keyframes.write_flow_keyframes(obj, iterates, energies, first,
                                              energy_name=self.energy_label,
                                              energy_words=self.energy_choice.words)


def _refinement_line(r: dict) -> str:
    why = ("start too coarse" if r["iteration"] == 0 and r["reason"].startswith("start")
           else "edges grown" if r["reason"].startswith("edges grown") else "jammed")
    if r.get("separation_steps"):
        why += f", strands pushed apart in {r['separation_steps']} steps"
    return f"{r['edges_before']} → {r['edges_after']} edges at iteration {r['iteration']} ({why})"


def relax_object(obj: bpy.types.Object, *, metric: str = "hs", max_iterations: int = 200,
                 tolerance: float = 1e-6, frame_start: int = 1, keyframe_stride: int = 1,
                 method: str = DEFAULT_METHOD, penalty: float | None = None,
                 append: bool = False, engine: str = DEFAULT_ENGINE, theta: float | None = None,
                 callback: Callable | None = None, scene: bpy.types.Scene | None = None,
                 progress: Progress = False, **options):
    """Relax a converted curve by the Möbius-energy flow and keyframe its iterates (every
    ``keyframe_stride``-th and the last).

    Parameters
    ----------
    obj : bpy.types.Object or sequence of them
        Curve of cyclic poly splines (see :func:`convert_object`), or several curve objects
        relaxed together as one system (each keeps its own keys; :class:`ObjectRelaxation`).
    metric, max_iterations, tolerance, frame_start, keyframe_stride, append, **options
        See :class:`ObjectRelaxation`; ``append=True`` continues the flow keyed on ``obj``.
    method : str
        ``"auto"`` (default: :func:`choose_method` picks the implicit gradient for a knotted
        curve or a link, the paper's explicit projected gradient for unknots) or one of
        ``core.METHODS``.
    penalty : float, optional
        Penalty weight α of ``"ncg"``, ``"lbfgs"``, ``"nesterov"`` (None: 1e4); refused for
        the other methods.
    engine, theta
        See :class:`ObjectRelaxation`; ``result.stats["engine"]`` says which engine ran.
    callback : callable, optional
        ``callback(run)`` after every accepted iterate, the last one included, with the
        :class:`ObjectRelaxation` (``run.nit``, ``run.x``, ``run.energy``); returning True stops
        the run cleanly.
    scene : bpy.types.Scene, optional
        Scene whose frame range grows to include the flow; defaults to ``bpy.context.scene``.
    progress : bool or callable
        True: print a line when numba compiles the kernels (the first run after installing or
        updating) and one per iterate ("moebius: 'Knot' iteration 3/200, energy 74.5, 1.2 s");
        a callable receives those lines instead; False (default): silent.

    Returns
    -------
    result
        The core's result object (``x``, ``fun``, ``nit``, ``success``, ``message``,
        ``history``).

    Raises
    ------
    ValueError
        If the curve cannot be relaxed (too many edges for the metric and engine among the
        reasons) or the method, penalty, engine or θ is invalid; nothing is changed then.
    BaseException
        Whatever interrupts the run (Ctrl+C, a failing callback) passes through, after the
        iterates computed so far are keyed (or, before the first one, the earlier animation is
        left as it was); a note on the exception says which.
    """
    say = reporter(progress)
    with compiling(say):
        return _relax_object(obj, metric, max_iterations, tolerance, frame_start,
                             keyframe_stride, method, penalty, append, engine, theta, callback,
                             scene, say, options)


def _relax_object(obj, metric, max_iterations, tolerance, frame_start, keyframe_stride, method,
                  penalty, append, engine, theta, callback, scene, say, options):
    run = ObjectRelaxation(obj, metric=metric, max_iterations=max_iterations, tolerance=tolerance,
                           frame_start=frame_start, keyframe_stride=keyframe_stride,
                           method=method, penalty=penalty, append=append, engine=engine,
                           theta=theta, **options)
    limit = run.run.max_iter
    more = True
    try:
        while more:
            before = run.nit
            more = run.step()
            if run.nit > before and say is not None:
                say(f"{run.name} iteration {run.nit}/{limit}, energy {run.energy:.6g}, "
                    f"{time.perf_counter() - run.t0:.1f} s")
            # every accepted iterate reaches the callback, the last one of the run included (as
            # in core.relax); a True returned for the last one changes nothing
            if run.nit > before and callback is not None and callback(run):
                run.stop("stopped by callback")
                break
    except BaseException as err:  # Ctrl+C in a script, a failing callback: keep the work
        if run.nit == 0:
            err.add_note(f"moebius: no iterate was computed; the earlier animation of "
                         f"{run.name} is kept")
        else:
            run.stop(f"interrupted by {type(err).__name__}")
            run.finish(scene)
            err.add_note(f"moebius: the {run.nit} iterates computed before the interruption "
                         f"are keyed on {run.name} from frame {run.frame_start}")
        raise
    return run.finish(scene)


