"""Live relaxation in the viewport: the flow runs on in a background thread
(``core.runs.live.LiveDriver``) while the user moves pinned points (Edit Mode), empties the pins
follow, obstacle objects or the container with Blender's own tools; the main thread only reads
what moved and writes the curve's coordinates (:meth:`LiveSession.sync`, called by the modal
operator's timer — Blender's data may be touched from the main thread only).

:class:`LiveSession` is what the operator drives and what scripts and tests call:
``sync()`` as often as the viewport redraws, then ``finish()`` (keep the result, key the
recorded states) or ``cancel()`` (everything back as it was before Live began).
"""

from __future__ import annotations

import time
from collections.abc import Sequence

import bpy
import numpy as np

from ..core.runs.live import LiveDriver, LiveRelaxation
from . import geometry, keyframes, scene_constraints
from .group import bevel_thickness, group_name, members, name_components
from .polygons import as_input
from .relaxation import check_converted
from .rest import set_rest_shape

#: Settings of ``relax_settings`` a live run takes (the rest are the limits and methods of a
#: finite run: a live run is the projected gradient without an end; its step growth is its own,
#: ``core.runs.live.LIVE_GROWTH``, since every accepted step is a viewport update).
LIVE_OPTIONS = ("energy", "alpha", "beta", "metric", "engine", "theta", "initial_step", "armijo",
                "backproject_iter", "backproject_tol", "edge_lengths", "barycenter",
                "thickness", "pin_selected", "pin_tangents", "obstacles", "obstacle_weight",
                "container")


def live_settings(settings) -> dict:
    """The keyword arguments of :class:`LiveSession` from the panel's ``scene.moebius``."""
    from .options import energy_settings, relax_settings

    kwargs = relax_settings(settings)
    out = {k: v for k, v in kwargs.items() if k in LIVE_OPTIONS}
    out.update(energy_settings(settings))  # the energy and its records' options (stiffness)
    out["tol"] = kwargs.get("tolerance", 1e-6)
    # the Grow slider's rate (the panel's percent, the core's fraction)
    if settings.length_growth > 0.0:
        out["length_growth"] = round(settings.length_growth, 6) / 100.0
    return out


def _matrix(M) -> np.ndarray:
    return np.array(M, dtype=np.float64)


class LiveSession:
    """A live relaxation of curve objects (one system, as *Relax* takes a selection).

    Parameters
    ----------
    objects : curve object or sequence of them
        Converted curves (the active one first: its coordinates are the run's).
    pin_objects : sequence of objects, optional
        Objects (empties, say) the curve follows: each pins the curve point nearest to it,
        which then moves with the object as it is moved, rotated or scaled.
    record : bool
        Key every state of the run on the curves when it finishes (frame ``frame_start`` on),
        with the moved obstacles' transforms: a live run becomes an animation whose straight
        moves between frames were all tested for contact.
    frame_start : int, optional
        First keyed frame (default: the current frame).
    pause : float
        Seconds the background thread yields after each state (``core.runs.live.LiveDriver``).
    **options
        As :func:`live_settings` gives them: ``metric``, ``energy`` (``alpha``, ``beta``),
        ``engine``, ``theta``, ``tol``, ``pin_selected`` (the points selected in Edit Mode
        are pins the user moves), ``pin_tangents``, ``obstacles`` (a collection or objects),
        ``obstacle_weight``, ``container`` (a mesh object), ``thickness`` (a radius or
        ``"bevel"``) and the line search's options.

    Raises
    ------
    ValueError
        For anything the run refuses (no pins to move is fine: the flow runs and the meshes
        move); nothing in the scene has changed then.
    """

    def __init__(self, objects, *, pin_objects: Sequence[bpy.types.Object] = (),
                 record: bool = False, frame_start: int | None = None, pause: float = 0.002,
                 scene: bpy.types.Scene | None = None, **options) -> None:
        self.scene = scene or bpy.context.scene
        self.members = members(objects)
        self.objects = [m.obj for m in self.members]
        self.name = group_name(self.objects)
        first = self.objects[0]
        for m in self.members:
            keyframes.check_flow_target(m.obj)
            check_converted(m.obj, m.polygons, m.closed)
        polygons = [P for m in self.members for P in m.to_run(m.polygons)]
        self._closed = [c for m in self.members for c in m.closed]
        self._sizes = [len(P) for P in polygons]
        self._starts = np.concatenate([[0], np.cumsum(self._sizes)]).astype(int)
        # the meshes' objects, before resolve() makes arrays of them
        source = options.get("obstacles")
        self._mesh_objects: list[bpy.types.Object] = []
        if isinstance(source, bpy.types.Collection):
            self._mesh_objects += [o for o in source.all_objects if o.type == "MESH"]
        elif isinstance(source, (list, tuple)) and all(isinstance(o, bpy.types.Object)
                                                       for o in source):
            self._mesh_objects += [o for o in source if o.type == "MESH"]
        container = options.get("container")
        if isinstance(container, bpy.types.Object):
            self._mesh_objects.append(container)
        try:
            options = scene_constraints.resolve(self.objects, options)
        except ValueError as err:
            raise ValueError(f"{self.name}: {err}") from None
        # pins: stacked indices of the run's components, the selected points first
        pinned = options.pop("pinned", None)
        self._handles: list[int] = []
        if pinned is not None:
            per = [pinned] if len(polygons) == 1 else pinned
            self._handles = sorted(int(self._starts[c] + i) for c, p in enumerate(per)
                                   for i in p)
        # pins that follow objects: the nearest point of each, and where it sits in the object
        self._followers: dict[int, tuple[bpy.types.Object, np.ndarray]] = {}
        stacked = np.concatenate(polygons)
        W = _matrix(first.matrix_world)
        for o in pin_objects:
            loc = np.linalg.inv(W) @ _matrix(o.matrix_world)[:, 3]
            v = int(np.argmin(np.sum((stacked - loc[:3]) ** 2, axis=1)))
            if v in self._handles or v in self._followers:
                raise ValueError(f"'{o.name}' is nearest a point that is pinned already; move "
                                 "it nearer the point it should hold")
            world = W @ np.append(stacked[v], 1.0)
            self._followers[v] = (o, (np.linalg.inv(_matrix(o.matrix_world)) @ world))
        handles = sorted(set(self._handles) | set(self._followers))
        if handles:
            per = [[h - int(self._starts[c]) for h in handles
                    if self._starts[c] <= h < self._starts[c + 1]] for c in range(len(polygons))]
            options["pinned"] = per[0] if len(per) == 1 else per
        self.handles = np.array(handles, dtype=np.int64)
        thickness = options.pop("thickness", 0.0)
        if thickness == "bevel":
            thickness = bevel_thickness(self.members)
        if thickness:
            options["thickness"] = thickness
        if not all(self._closed):
            options["closed"] = self._closed if len(self._closed) > 1 else self._closed[0]
        options.pop("push_apart", None)
        metric = options.pop("metric", "hs")
        tol = options.pop("tol", 1e-6)
        try:
            self.run = LiveRelaxation(as_input(polygons), metric, tol, target_lengths="keep",
                                      **options)
        except ValueError as err:
            raise ValueError(f"{self.name}: {name_components(str(err), self.members)}"
                             ) from None
        # the mesh objects by the run's labels (obstacle names, then the container's)
        self._rel0 = {}
        for o in self._mesh_objects:
            self._rel0[o.name] = self._relative(o)
        # what cancel() restores: the curves' points, their flow keys, the objects moved
        self._start_points = [[P.copy() for P in m.polygons] for m in self.members]
        self._prior = []
        for m in self.members:
            try:
                self._prior.append(keyframes.read_flow_keyframes(m.obj))
            except ValueError:  # keys edited by hand: kept as they are, never removed
                self._prior.append(None)
        self._matrices = {o.name: o.matrix_world.copy()
                          for o in [*self._mesh_objects, *(f[0] for f in
                                                           self._followers.values())]}
        self._objects_moved = {o.name: o for o in [*self._mesh_objects,
                                                   *(f[0] for f in self._followers.values())]}
        self._W0 = W
        self.frame_start = self.scene.frame_current if frame_start is None else int(frame_start)
        self.energy_label = self.run.energy_choice.label
        for m, prior in zip(self.members, self._prior, strict=True):
            if prior is not None:  # they would pull the curve back on every frame change
                keyframes.remove_flow_keyframes(m.obj)
        self.driver = LiveDriver(self.run, record=record, pause=pause)
        self.t0 = time.perf_counter()
        #: states written to the curves so far (the viewport's updates)
        self.updates = 0
        #: the newest state shown, and the pins' targets and meshes' placements last posted
        self.frame = self.driver.latest()
        self._posted_pins = self.run.pin_positions
        #: the *Grow* factor: the curves' total length over their length when Live began,
        #: approached as the run goes on (set it, then :meth:`sync` posts it)
        self.grow = 1.0
        self._posted_grow = 1.0
        self._posted_meshes = {label: np.eye(4) for label in self.run.mesh_labels}
        self._closed_flag = False

    # -- reading what the user moved -----------------------------------------------------------

    def _relative(self, o: bpy.types.Object) -> np.ndarray:
        """``o``'s placement in the run's coordinates (the first curve's object space)."""
        return np.linalg.inv(_matrix(self.objects[0].matrix_world)) @ _matrix(o.matrix_world)

    def _component_point(self, v: int) -> tuple:
        c = int(np.searchsorted(self._starts, v, side="right") - 1)
        for m in self.members:
            if m.span.start <= c < m.span.stop:
                return m, c - m.span.start, v - int(self._starts[c])
        raise IndexError(v)

    def pin_targets(self) -> np.ndarray | None:
        """Where the user has put the pins, in the run's coordinates: the pinned points as
        the curve data holds them (Edit Mode's too), or the objects they follow."""
        if not len(self.handles):
            return None
        W = _matrix(self.objects[0].matrix_world)
        out = np.empty((len(self.handles), 3))
        for r, v in enumerate(self.handles):
            v = int(v)
            if v in self._followers:
                o, local = self._followers[v]
                out[r] = (np.linalg.inv(W) @ _matrix(o.matrix_world) @ local)[:3]
                continue
            m, s, i = self._component_point(v)
            co = np.array(m.obj.data.splines[s].points[i].co, dtype=np.float64)[:3]
            out[r] = m.to_run([co[None]])[0][0]
        return out

    def mesh_placements(self) -> dict:
        """Each mesh's map from its place at the start to its place now (run coordinates)."""
        out = {}
        for o in self._mesh_objects:
            try:
                out[o.name] = self._relative(o) @ np.linalg.inv(self._rel0[o.name])
            except ReferenceError:  # deleted while live: it stays where it was
                continue
        return out

    # -- the main thread's part ----------------------------------------------------------------

    def sync(self) -> bool:
        """Post what the user moved since the last call and write the newest state to the
        curves; True when a new state was written. Raises what the thread met (the run
        stopped then)."""
        if self.driver.error is not None:
            raise self.driver.error
        pins = self.pin_targets()
        placements = {k: M for k, M in self.mesh_placements().items()
                      if not np.array_equal(M, self._posted_meshes.get(k))}
        if pins is not None and not np.array_equal(pins, self._posted_pins):
            self._posted_pins = pins
        else:
            pins = None
        grow = None
        if self.grow != self._posted_grow:
            grow = self._posted_grow = self.grow
        if pins is not None or placements or grow is not None:
            self._posted_meshes.update(placements)
            self.driver.post(pins=pins, placements=placements or None, grow=grow)
        frame = self.driver.latest()
        if frame is None:
            return False
        self.frame = frame
        self._write(frame.parts, keep_user_pins=True)
        self.updates += 1
        return True

    def _write(self, parts, keep_user_pins: bool) -> None:
        """The run's state on the curves; with ``keep_user_pins`` the points the user moves
        keep what the user gave them (a pin held at contact is not pulled back under the
        mouse)."""
        keep = set() if not keep_user_pins else {int(v) for v in self.handles
                                                 if int(v) not in self._followers}
        for m in self.members:
            local = m.to_local(parts[m.span])
            for s, (spline, P) in enumerate(zip(m.obj.data.splines, local, strict=True)):
                c = m.span.start + s
                co = np.empty(4 * len(P))
                spline.points.foreach_get("co", co)
                co = co.reshape(-1, 4)
                rows = np.ones(len(P), bool)
                for v in keep:
                    if self._starts[c] <= v < self._starts[c + 1]:
                        rows[v - int(self._starts[c])] = False
                co[rows, :3] = P[rows]
                spline.points.foreach_set("co", co.ravel())
            m.obj.data.update_tag()

    def status(self) -> str:
        """A line for the status bar / header: the state of the run and any clipped move."""
        f = self.frame
        it = f"iteration {f.nit}, energy {f.energy:.6g}" if f is not None else "starting"
        rest = " (resting)" if self.run.done else ""
        clip = f" — {self.driver.clipped}" if self.driver.clipped else ""
        if self.driver.refused:
            clip += f" — {self.driver.refused}"
        rec = f", recording {len(self.driver.record)} states" if self.driver.recording else ""
        sched = self.run.growth_schedule
        size = f", {sched.words()}" if sched is not None and not sched.reached else ""
        return f"Möbius live: {self.name} {it}{size}{rest}{rec}{clip}"

    # -- ending ---------------------------------------------------------------------------------

    def _close(self) -> None:
        if not self._closed_flag:
            self.driver.close()
            self._closed_flag = True

    def cancel(self) -> None:
        """Stop and put everything back as it was before Live began: the curves' points (to
        the bit), their flow keys, the moved obstacles, container and pin objects."""
        self._close()
        self._restore()

    def _restore(self) -> None:
        for m, points, prior in zip(self.members, self._start_points, self._prior,
                                    strict=True):
            if prior is not None:
                frames, keyed, energies = prior
                keyframes.write_flow_keyframes(m.obj, [np.split(X, m.cuts) for X in keyed],
                                               list(energies), int(frames[0]))
            geometry.write_polygons(m.obj.data, points)
        for name, M in self._matrices.items():
            o = self._objects_moved[name]
            try:
                o.matrix_world = M
            except ReferenceError:
                pass

    def finish(self, before=None) -> dict:
        """Stop and keep the result: the final state on the curves (a pin held at contact
        where it was held), the meshes where the run had them (short of a crossing); with
        ``record``, every state keyed from ``frame_start`` on. Returns what happened
        (``states``, ``frames``: the keyed range or None, ``updates``, ``seconds``,
        ``clipped``). ``before()``, if given, is called with the start state put back (the
        operator pushes an undo step there, so that one Ctrl+Z undoes the whole live run)."""
        self._close()
        if self.driver.error is not None:
            raise self.driver.error
        last = self.driver.latest(new_only=False)
        if before is not None:  # the start state back for a moment (an undo step of it)
            final = {name: o.matrix_world.copy() for name, o in self._objects_moved.items()}
            self._restore()
            before()
            for m, prior in zip(self.members, self._prior, strict=True):
                if prior is not None:
                    keyframes.remove_flow_keyframes(m.obj)
            for name, M in final.items():
                self._objects_moved[name].matrix_world = M
        self._write(last.parts, keep_user_pins=False)
        self._place_meshes(last.placements)
        frames = None
        record = self.driver.record
        if self.driver.recording and len(record) > 1:
            for m in self.members:
                iterates = [m.to_local(f.parts[m.span]) for f in record]
                set_rest_shape(m.obj, iterates[0])
                frames = keyframes.write_flow_keyframes(
                    m.obj, iterates, [f.energy for f in record], self.frame_start,
                    energy_name=self.energy_label)
                geometry.write_polygons(m.obj.data, iterates[0])
            self._key_meshes(record)
            self.scene.frame_start = min(self.scene.frame_start, frames.start)
            self.scene.frame_end = max(self.scene.frame_end, frames.stop - 1)
            self.scene.frame_set(frames.stop - 1)
        else:
            for m in self.members:  # no keys: the final shape is the curve's own
                set_rest_shape(m.obj, m.to_local(last.parts[m.span]))
        return {"states": len(record), "frames": frames, "updates": self.updates,
                "seconds": time.perf_counter() - self.t0, "clipped": self.driver.clipped,
                "energy": last.energy, "nit": last.nit, "length": self.run.length}

    def _world(self, name: str, placement: np.ndarray) -> np.ndarray:
        return _matrix(self.objects[0].matrix_world) @ placement @ self._rel0[name]

    def _place_meshes(self, placements) -> None:
        """Put each mesh where the run has it (it differs from where the user put it only
        when its move was cut at contact)."""
        for o, M in zip(self._mesh_objects, placements, strict=True):
            want = self._world(o.name, M)
            if not np.allclose(want, _matrix(o.matrix_world), rtol=0, atol=1e-9):
                o.matrix_world = _as_matrix(want)

    def _key_meshes(self, record) -> None:
        """Key the location, rotation and scale of every mesh that moved, LINEAR, on the
        frames where its motion starts, changes or ends."""
        for m, o in enumerate(self._mesh_objects):
            maps = [f.placements[m] for f in record]
            moved = [k for k in range(1, len(maps)) if not np.array_equal(maps[k], maps[k - 1])]
            if not moved:
                continue
            keys = sorted({0, len(maps) - 1, *moved, *(k - 1 for k in moved)})
            saved = o.matrix_world.copy()
            for k in keys:
                o.matrix_world = _as_matrix(self._world(o.name, maps[k]))
                for path in ("location", "rotation_euler", "scale"):
                    o.keyframe_insert(path, frame=self.frame_start + k)
            o.matrix_world = saved
            action = o.animation_data.action if o.animation_data else None
            for fc in _fcurves_of(action, o):
                for kp in fc.keyframe_points:
                    kp.interpolation = "LINEAR"


def _as_matrix(M: np.ndarray):
    from mathutils import Matrix

    return Matrix(M.tolist())


def _fcurves_of(action, obj):
    """The F-curves of ``action`` (slotted actions on Blender 4.4+: the object's channelbag)."""
    if action is None:
        return []
    if hasattr(action, "fcurves") and len(getattr(action, "layers", [])) == 0:
        return list(action.fcurves)
    out = []
    for layer in action.layers:
        for strip in layer.strips:
            bag = strip.channelbag(obj.animation_data.action_slot)
            if bag is not None:
                out += list(bag.fcurves)
    return out


#: Shortcut of the Live operator in the 3D Viewport.
SHORTCUT = {"type": "L", "value": "PRESS", "ctrl": True, "alt": True}
_keymaps: list = []


def register_keymap() -> None:
    kc = bpy.context.window_manager.keyconfigs.addon
    if kc is None:  # background mode: no key configuration
        return
    km = kc.keymaps.new(name="3D View", space_type="VIEW_3D")
    kmi = km.keymap_items.new("moebius.live", **SHORTCUT)
    _keymaps.append((km, kmi))


def unregister_keymap() -> None:
    for km, kmi in _keymaps:
        km.keymap_items.remove(kmi)
    _keymaps.clear()




# -- the operator --------------------------------------------------------------------------------


class MOEBIUS_OT_live(bpy.types.Operator):
    """Relax the selected curves live: the flow runs on while you move pinned points (Edit
    Mode), selected empties the pins follow, obstacles or the container (G, R, S); nothing
    ever passes through anything. Enter keeps the result, Esc puts everything back"""

    bl_idname = "moebius.live"
    bl_label = "Live"
    bl_options = {"REGISTER", "UNDO"}

    #: Seconds between two looks at the run's newest state (the viewport's update rate cap).
    INTERVAL = 1.0 / 60.0

    @classmethod
    def poll(cls, context):
        from .operators import _poll_active_curve

        return _poll_active_curve(cls, context)

    def invoke(self, context, event):
        from .operators import _selected_curves

        if context.window is None or bpy.app.background:
            self.report({"ERROR"}, "Live needs a window; scripts drive "
                                   "moebius_addon.blender.live.LiveSession instead")
            return {"CANCELLED"}
        settings = context.scene.moebius
        pins = [o for o in context.selected_objects if o.type == "EMPTY"]
        try:
            self._session = LiveSession(_selected_curves(context), pin_objects=pins,
                                        record=settings.live_record,
                                        **live_settings(settings))
        except ValueError as err:
            self.report({"ERROR"}, str(err))
            return {"CANCELLED"}
        settings.live_grow = 1.0  # a new live run starts at its own length
        self._error = None
        self._ended = False
        self._header = False
        self._text = ""
        settings.running = True
        settings.live = True
        settings.live_stop = False
        self._window = context.window
        bpy.app.timers.register(self._tick, first_interval=0.0)
        # wakes modal() when the user does nothing, so that Finish in the panel is seen
        self._timer = context.window_manager.event_timer_add(0.1, window=context.window)
        context.window_manager.modal_handler_add(self)
        return {"RUNNING_MODAL"}

    def _tick(self):
        """bpy.app.timers: runs also while a transform (G/R/S) is modal."""
        if self._ended:
            return None
        try:
            self._session.grow = bpy.context.scene.moebius.live_grow
            wrote = self._session.sync()
        except Exception as err:  # noqa: BLE001 - modal() restores and reports it
            self._error = err
            return None
        text = self._session.status()
        frame = self._session.frame
        if wrote and frame is not None:  # an RNA write is an update of the scene: only news
            settings = bpy.context.scene.moebius
            settings.live_iteration = frame.nit
            settings.live_energy = frame.energy
        try:
            if text != self._text:
                self._window.workspace.status_text_set(text)
                self._text = text
            clipped = bool(self._session.driver.clipped)
            for area in self._window.screen.areas:
                # the header says so while a move is clipped; cleared only when it was ours
                # (a transform running meanwhile shows its own text there)
                if area.type == "VIEW_3D" and clipped:
                    area.header_text_set(text)
                elif area.type == "VIEW_3D" and self._header:
                    area.header_text_set(None)
                if wrote and area.type in {"VIEW_3D", "PROPERTIES"}:
                    area.tag_redraw()
            self._header = clipped
        except ReferenceError:  # the window closed
            return None
        return self.INTERVAL

    def _cleanup(self, context):
        self._ended = True
        if bpy.app.timers.is_registered(self._tick):
            bpy.app.timers.unregister(self._tick)
        context.window_manager.event_timer_remove(self._timer)
        context.workspace.status_text_set(None)
        for area in context.screen.areas:
            if area.type == "VIEW_3D":
                area.header_text_set(None)
            area.tag_redraw()
        settings = context.scene.moebius
        settings.running = False
        settings.live = False
        settings.live_stop = False

    def modal(self, context, event):
        settings = context.scene.moebius
        if self._error is not None:
            self._cleanup(context)
            self._session.cancel()
            self.report({"ERROR"}, f"Live relaxation failed, everything restored: "
                                   f"{self._error}")
            return {"CANCELLED"}
        if event.type == "ESC" and event.value == "PRESS":
            self._cleanup(context)
            self._session.cancel()
            self.report({"INFO"}, f"Live relaxation of {self._session.name} cancelled: "
                                  "everything is back as before")
            return {"CANCELLED"}
        if (event.type in {"RET", "NUMPAD_ENTER"} and event.value == "PRESS") or (
                settings.live_stop):
            self._cleanup(context)
            try:
                done = self._session.finish(before=_undo_push)
            except Exception as err:  # noqa: BLE001 - restore rather than keep half a result
                self._session.cancel()
                self.report({"ERROR"}, f"Live relaxation failed, everything restored: {err}")
                return {"CANCELLED"}
            keyed = (f", keyed frames {done['frames'].start}–{done['frames'].stop - 1}"
                     if done["frames"] else "")
            clip = f"; {done['clipped']}" if done["clipped"] else ""
            self.report({"INFO"}, f"Live relaxation of {self._session.name}: {done['nit']} "
                                  f"iterations, energy {done['energy']:.6g}, "
                                  f"{done['updates']} viewport updates in "
                                  f"{done['seconds']:.1f} s{keyed}{clip}")
            return {"FINISHED"}
        return {"PASS_THROUGH"}


def _undo_push() -> None:
    """An undo step of the state before Live began (the operator's own step follows)."""
    try:
        bpy.ops.ed.undo_push(message="Before Live Relax")
    except RuntimeError:  # no undo stack here (background): nothing to undo to anyway
        pass


class MOEBIUS_OT_live_finish(bpy.types.Operator):
    """Keep the live result and end Live (as Enter does; Esc puts everything back)"""

    bl_idname = "moebius.live_finish"
    bl_label = "Finish Live"
    bl_options = {"REGISTER"}

    @classmethod
    def poll(cls, context):
        settings = getattr(context.scene, "moebius", None)
        if settings is None or not settings.live:
            cls.poll_message_set("Live is not running")
            return False
        return True

    def execute(self, context):
        context.scene.moebius.live_stop = True
        return {"FINISHED"}


classes = (MOEBIUS_OT_live, MOEBIUS_OT_live_finish)
