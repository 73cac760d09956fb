"""Operators ``bpy.ops.moebius.*``: validate, call :mod:`.api`, report.

Errors from the API are ``ValueError`` messages that already say what to do; they are reported
as errors and the operator cancels before changing anything.
"""

from __future__ import annotations

import time

import bpy
from bpy.props import BoolProperty, EnumProperty, FloatProperty, IntProperty, StringProperty

from .. import core
from . import api, keyframes, live, options, presets

_CONVERTIBLE = {"CURVE", "MESH"}


def _active_curve(context):
    obj = context.active_object
    return obj if obj is not None and obj.type == "CURVE" else None


def _selected_curves(context) -> list:
    """The active curve object first, then the other selected curve objects by name: what
    Relax, Clear and Export act on together."""
    active = _active_curve(context)
    others = sorted((o for o in context.selected_objects
                     if o.type == "CURVE" and o != active), key=lambda o: o.name)
    return [active, *others] if active is not None else others


def _poll_active_curve(cls, context) -> bool:
    if _active_curve(context) is None:
        cls.poll_message_set("Select a curve object (convert one with Möbius ▸ Polygon ▸ Convert)")
        return False
    settings = getattr(context.scene, "moebius", None)
    if settings is not None and settings.running:
        cls.poll_message_set("A relaxation is running; press Esc in the 3D Viewport to stop it")
        return False
    return True


class MOEBIUS_OT_convert(bpy.types.Operator):
    """Turn the selected curves (or meshes of closed edge loops) into closed polygons with
    equal edges, ready to relax; the originals are kept, hidden"""

    bl_idname = "moebius.convert"
    bl_label = "Convert to Möbius Polygon"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        if not any(o.type in _CONVERTIBLE for o in context.selected_objects):
            cls.poll_message_set("Select a curve object, or a mesh made of closed edge loops")
            return False
        return True

    def execute(self, context):
        s = context.scene.moebius
        objs = [o for o in context.selected_objects if o.type in _CONVERTIBLE]
        prepared = []
        try:  # check everything before changing anything
            for obj in objs:
                prepared.append(api.prepare_conversion(
                    obj, edges=s.edges, edge_length=s.edge_length if s.use_edge_length else None,
                    close_open=s.close_open, metric=s.metric, method=s.method, engine=s.engine,
                    keep_open=s.keep_open))
        except ValueError as err:
            self.report({"ERROR"}, str(err))
            return {"CANCELLED"}
        new = [api.apply_conversion(o, p, context) for o, p in zip(objs, prepared, strict=True)]
        for obj in new:
            obj.select_set(True)
        edges = ", ".join(str(sum(len(p) for p in polys)) for polys in prepared)
        self.report({"INFO"}, f"Converted {len(new)} object(s) to polygons with {edges} edges")
        return {"FINISHED"}


#: A first run of a session that takes this long to its first iterate says why in its report
#: (numba compiling the kernels right after installing, loading them from its cache in later
#: sessions; the times measured are in docs/blender.md, Install).
PREPARE_NOTE_FROM = 1.0


def _first_run_note(run, prep=None) -> str:
    if not run.first_run or run.seconds_to_first is None:
        return ""
    waited = run.seconds_to_first + (prep.seconds if prep is not None else 0.0)
    if waited < PREPARE_NOTE_FROM:
        return ""
    return (f"; first run in this session: {waited:.1f} s to the first iterate, preparing the "
            f"solver (later runs start at once)")


#: Status bar text while the first run of a session prepares the solver (nothing moves then).
PREPARING = "Möbius: preparing the solver (first run only) …"


class MOEBIUS_OT_relax(bpy.types.Operator):
    """Relax the selected curves (together, as one system) by the Möbius energy flow from
    their shape at the current frame, replacing their flow keys (Esc stops and keeps the
    iterates so far)"""

    bl_idname = "moebius.relax"
    bl_label = "Relax"
    bl_options = {"REGISTER", "UNDO"}

    #: Seconds of computation per timer tick before the viewport is redrawn.
    TICK_BUDGET = 0.08

    append: BoolProperty(
        name="Continue",
        description="Continue the keyed flow: start from its last iterate and key the new "
                    "iterates after its last frame (off: a new flow from the shape at the "
                    "current frame, replacing the flow keys)",
        default=False, options={"SKIP_SAVE"})

    poll = classmethod(_poll_active_curve)

    @classmethod
    def description(cls, context, properties):
        if properties.append:
            return ("Continue the keyed flow of the selected curves: from its last iterate, new "
                    "keys after its last frame (Esc stops and keeps the iterates so far)")
        return cls.bl_rna.description

    def _start(self, context):
        settings = context.scene.moebius
        try:
            self._run = api.ObjectRelaxation(_selected_curves(context), append=self.append,
                                             **api.relax_settings(settings))
        except ValueError as err:
            self.report({"ERROR"}, str(err))
            return False
        self._max = settings.max_iterations
        return True

    def _report_result(self, result):
        run = self._run
        # a limit the user set (Max Iterations, Time Limit) or Esc is an ordinary end of a run;
        # a warning only when the flow could not go on (decided by the status, not the words)
        kind = "WARNING" if result.status in (core.Status.STALLED,
                                              core.Status.NOT_FINISHED) else "INFO"
        how = f" ({run.method}: {run.why})" if run.why else f" ({run.method})"
        how += " continued" if run.append else ""
        how += f", {run.engine} engine"
        hint = api.method_hint(run.method, result, run.start, not run.open, run.grows)
        self.report({kind}, f"{run.name}{how}: {run.nit} iterations, energy "
                            f"{run.energies[0]:.6g} → {run.energy:.6g}, frames "
                            f"{run.frame_start}–{run.frame_start + len(run.iterates) - 1} "
                            f"({result.message}{hint})"
                            f"; {run.type_message}"
                            f"{_first_run_note(run, getattr(self, '_prep', None))}")
        if run.type_kept is False:  # never expected: the flow passes no strand through another
            self.report({"WARNING"}, run.type_message)

    def execute(self, context):
        if not self._start(context):
            return {"CANCELLED"}
        try:
            while self._run.step():
                pass
        except Exception as err:  # noqa: BLE001 - any core failure: restore and report
            return self._fail(context, err)
        return self._finish(context)

    def _finish(self, context):
        """Keyframe the iterates; if that fails, restore the curve like any other failure."""
        try:
            result = self._run.finish(context.scene)
        except Exception as err:  # noqa: BLE001 - e.g. the object was deleted during the run
            return self._fail(context, err)
        self._report_result(result)
        return {"FINISHED"}

    def invoke(self, context, event):
        if context.window is None or bpy.app.background:
            return self.execute(context)
        settings = context.scene.moebius
        if api.solver_warm():
            if not self._start(context):
                return {"CANCELLED"}
            settings.live_energy = self._run.energy
        else:
            # numba compiles (or loads) the kernels first: in a background thread, so that the
            # window stays responsive and the status bar counts the seconds; the run is set up
            # once that is done (a compile on the main thread froze the window for minutes)
            self._run = None
            self._prep = api.Preparation(api.solver_paths(_active_curve(context),
                                                          settings.engine))
            context.workspace.status_text_set(PREPARING)
        settings.running = True
        settings.progress = 0.0
        settings.live_iteration = 0
        self._timer = context.window_manager.event_timer_add(0.01, window=context.window)
        context.window_manager.modal_handler_add(self)
        return {"RUNNING_MODAL"}

    def _cleanup(self, context):
        context.window_manager.event_timer_remove(self._timer)
        self._timer = None
        context.workspace.status_text_set(None)
        context.scene.moebius.running = False
        for area in context.screen.areas:
            area.tag_redraw()

    def _fail(self, context, err):
        try:
            self._run.restore()
        except ReferenceError:  # the object was deleted while the flow ran
            pass
        if getattr(self, "_timer", None) is not None:
            self._cleanup(context)
        self.report({"ERROR"}, f"Relaxation failed, curve restored: {err}")
        return {"CANCELLED"}

    def modal(self, context, event):
        if event.type == "ESC" and event.value == "PRESS" and self._run is None:
            self._cleanup(context)
            return {"CANCELLED"}
        if event.type == "ESC" and event.value == "PRESS":
            self._run.stop("cancelled by the user (Esc)")
            self._cleanup(context)
            return self._finish(context)
        if event.type != "TIMER":
            return {"PASS_THROUGH"}
        prep = getattr(self, "_prep", None)
        if self._run is None and prep is not None and not prep.done:
            compiled = f", {prep.kernels} kernels compiled" if prep.kernels else ""
            context.workspace.status_text_set(
                f"{PREPARING[:-2]}: {prep.seconds:.0f} s{compiled} — Esc cancels")
            return {"RUNNING_MODAL"}
        if self._run is None and not self._start(context):  # set up once prepared
            self._cleanup(context)
            return {"CANCELLED"}
        t0 = time.perf_counter()
        more = True
        try:
            while more and time.perf_counter() - t0 < self.TICK_BUDGET:
                more = self._run.step()
            self._run.show()
        except Exception as err:  # noqa: BLE001 - also a curve deleted mid-run
            return self._fail(context, err)
        settings = context.scene.moebius
        settings.live_iteration = self._run.nit
        settings.live_energy = self._run.energy
        settings.progress = min(1.0, self._run.nit / max(1, self._max))
        context.workspace.status_text_set(
            f"Möbius flow: iteration {self._run.nit}/{self._max}, energy "
            f"{self._run.energy:.6g} — Esc stops and keeps the iterates so far")
        for area in context.screen.areas:
            if area.type in {"VIEW_3D", "PROPERTIES"}:
                area.tag_redraw()
        if more:
            return {"RUNNING_MODAL"}
        self._cleanup(context)
        return self._finish(context)


def _search_kinds(self, context, edit_text):
    """Entries for the Knot field as the user types: ``(name, description)``, best first."""
    return api.search_knots(edit_text, limit=100)


class MOEBIUS_OT_add_knot(bpy.types.Operator):
    """Add a knot or link from the catalogue (every prime knot up to 12 crossings, every prime
    link up to 11, unknots, torus knots) as closed polygons ready to relax"""

    bl_idname = "moebius.add_knot"
    bl_label = "Add Knot"
    bl_options = {"REGISTER", "UNDO"}
    bl_property = "kind"

    kind: StringProperty(
        name="Knot", default="fhw", search=_search_kinds, search_options={"SUGGESTION"},
        description="Type to search: a table name (3_1, 10_161, 12n_888, L6a4{0,0}), a common "
                    "name (trefoil, Borromean rings, Whitehead link), a mirror image (m3_1), "
                    "or fhw, helix, random, torus, circle")
    edges: IntProperty(name="Edges", default=0, min=0, soft_max=1000,
                       description="Edges of the polygon (0: the catalogue's default for this "
                                   "knot, fine enough for its shape)")
    p: IntProperty(name="p", default=2, min=1, soft_max=20, description="Torus knot: p")
    q: IntProperty(name="q", default=3, min=1, soft_max=20, description="Torus knot: q")
    seed: IntProperty(name="Seed", default=0, min=0, description="Random unknot: seed")
    size: FloatProperty(name="Size", default=2.0, min=1e-6, subtype="DISTANCE",
                        description="Largest extent of the knot")

    def draw(self, context):
        col = self.layout.column()
        col.prop(self, "kind", icon="VIEWZOOM")
        col.prop(self, "edges")
        if self.kind == "torus":
            row = col.row(align=True)
            row.prop(self, "p")
            row.prop(self, "q")
        if self.kind == "random":
            col.prop(self, "seed")
        col.prop(self, "size")

    def invoke(self, context, event):
        if context.window is None or bpy.app.background:
            return self.execute(context)
        # a dialog whose Knot field searches the catalogue as the user types
        return context.window_manager.invoke_props_dialog(self, width=360)

    def execute(self, context):
        try:
            s = context.scene.moebius  # the run the knot is added for
            obj = api.add_knot(self.kind.strip(), self.edges, p=self.p, q=self.q,
                               seed=self.seed, size=self.size,
                               location=context.scene.cursor.location, context=context,
                               metric=s.metric, method=s.method, engine=s.engine)
        except ValueError as err:
            self.report({"ERROR"}, str(err))
            return {"CANCELLED"}
        edges = sum(len(sp.points) for sp in obj.data.splines)
        parts = len(obj.data.splines)
        self.report({"INFO"}, f"Added '{obj.name}' with {edges} edges"
                              + (f" in {parts} components" if parts > 1 else "")
                              + f", energy {obj[keyframes.ENERGY_PROP]:.6g}")
        return {"FINISHED"}


class MOEBIUS_OT_add_notation(bpy.types.Operator):
    """Add the knot or link of a braid word (1 -2 1 -2) or PD code ([[1,5,2,4],[3,1,4,6],
    [5,3,6,2]]) as closed polygons ready to relax"""

    bl_idname = "moebius.add_notation"
    bl_label = "Add Knot from Notation"
    bl_options = {"REGISTER", "UNDO"}

    notation: StringProperty(
        name="Notation", default="",
        description="Braid word (1 -2 1 -2, σi a positive crossing; [1,-2,1,-2]; "
                    "{3, {1,-2,1,-2}}) or PD code ([[1,5,2,4],…], PD[X[…], …], Knoodle's rows "
                    "of five); empty: the panel's Notation field")
    edges: IntProperty(name="Edges", default=0, min=0, soft_max=1000,
                       description="Edges in all (0: enough for the shape, about 3 edges per "
                                   "strand spacing)")
    size: FloatProperty(name="Size", default=2.0, min=1e-6, subtype="DISTANCE",
                        description="Largest extent of the knot")

    def invoke(self, context, event):
        if not self.notation:
            self.notation = context.scene.moebius.notation
        if context.window is None or bpy.app.background:
            return self.execute(context)
        return context.window_manager.invoke_props_dialog(self, width=420)

    def execute(self, context):
        s = context.scene.moebius
        text = self.notation or s.notation
        try:
            obj = api.add_notation(text, self.edges, size=self.size,
                                   location=context.scene.cursor.location, context=context,
                                   metric=s.metric, method=s.method, engine=s.engine)
        except ValueError as err:
            self.report({"ERROR"}, str(err))
            return {"CANCELLED"}
        edges = sum(len(sp.points) for sp in obj.data.splines)
        self.report({"INFO"}, f"Added '{obj.name}' with {edges} edges, energy "
                              f"{obj[keyframes.ENERGY_PROP]:.6g}")
        return {"FINISHED"}


class MOEBIUS_OT_identify(bpy.types.Operator):
    """Name the knot or link the active curve is, from invariants of a projection (Alexander
    and Jones polynomials, linking numbers) matched against the table; stored on the object"""

    bl_idname = "moebius.identify"
    bl_label = "Identify"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        obj = context.active_object
        if obj is None or obj.type not in _CONVERTIBLE:
            cls.poll_message_set("Select a curve object, or a mesh made of closed edge loops")
            return False
        return True

    def execute(self, context):
        obj = context.active_object
        try:
            result = api.identify_object(obj)
        except ValueError as err:
            self.report({"ERROR"}, str(err))
            return {"CANCELLED"}
        self.report({"INFO"}, f"'{obj.name}' is {result.message} ({result.seconds:.2f} s)"
                    if result.names else f"'{obj.name}': {result.message}")
        return {"FINISHED"}


class MOEBIUS_MT_add_knot(bpy.types.Menu):
    """Add ▸ Curve ▸ Knot: the catalogue's search, a few well-known entries, notation"""

    bl_idname = "MOEBIUS_MT_add_knot"
    bl_label = "Knot"

    #: Entries listed in the menu besides the search (name, label).
    COMMON = (("3_1", "Trefoil"), ("4_1", "Figure-Eight Knot"), ("5_1", "Cinquefoil"),
              ("L2a1{1}", "Hopf Link"), ("L5a1{0}", "Whitehead Link"),
              ("L6a4{0,0}", "Borromean Rings"), ("fhw", "Freedman–He–Wang Unknot"),
              ("helix", "Helix Unknot"), ("random", "Random Unknot"),
              ("torus", "Torus Knot (p, q)"))

    def draw(self, context):
        layout = self.layout
        layout.operator_context = "INVOKE_DEFAULT"
        layout.operator("moebius.add_knot", text="Search Knots and Links…", icon="VIEWZOOM")
        layout.operator("moebius.add_notation", text="From Braid Word or PD Code…",
                        icon="TEXT")
        layout.separator()
        layout.operator_context = "EXEC_DEFAULT"
        for key, label in self.COMMON:
            layout.operator("moebius.add_knot", text=label).kind = key


class MOEBIUS_OT_clear_animation(bpy.types.Operator):
    """Remove the relaxation keyframes of the selected curves and restore their start shape"""

    bl_idname = "moebius.clear_animation"
    bl_label = "Clear Flow Animation"
    bl_options = {"REGISTER", "UNDO"}

    poll = classmethod(_poll_active_curve)

    def execute(self, context):
        objs = [o for o in _selected_curves(context) if keyframes.keyed_frames(o)]
        if not objs:
            self.report({"WARNING"}, f"'{_active_curve(context).name}' has no relaxation "
                                     "keyframes to clear")
            return {"CANCELLED"}
        for obj in objs:
            api.clear_animation(obj)
        self.report({"INFO"}, f"Cleared the flow animation of {api.group_name(objs)}")
        return {"FINISHED"}


class MOEBIUS_OT_apply_frame(bpy.types.Operator):
    """Make the shape at the current frame the curve's rest shape and remove the flow keys"""

    bl_idname = "moebius.apply_frame"
    bl_label = "Apply Current Frame"
    bl_options = {"REGISTER", "UNDO"}

    poll = classmethod(_poll_active_curve)

    def execute(self, context):
        obj = _active_curve(context)
        try:
            api.apply_frame(obj, scene=context.scene)
        except ValueError as err:
            self.report({"ERROR"}, str(err))
            return {"CANCELLED"}
        self.report({"INFO"}, f"Frame {context.scene.frame_current} is now the rest shape "
                              f"of '{obj.name}'")
        return {"FINISHED"}


class MOEBIUS_OT_export_flow(bpy.types.Operator):
    """Export the flow of the selected curves over their keyed frames as Alembic (.abc) or USD
    (.usd/.usda/.usdc/.usdz), chosen by the file name"""

    bl_idname = "moebius.export_flow"
    bl_label = "Export Flow"
    bl_options = {"REGISTER"}

    filepath: StringProperty(name="File Path", subtype="FILE_PATH", default="",
                             description="Where to write; .abc or .usd/.usda/.usdc/.usdz")
    filter_glob: StringProperty(default="*.abc;*.usd;*.usda;*.usdc;*.usdz",
                                options={"HIDDEN"})

    @classmethod
    def poll(cls, context):
        if not _poll_active_curve(cls, context):
            return False
        if not keyframes.keyed_frames(_active_curve(context)):
            cls.poll_message_set("The active curve has no flow keys; press Relax first")
            return False
        return True

    def invoke(self, context, event):
        if not self.filepath:
            self.filepath = f"//{bpy.path.clean_name(_active_curve(context).name)}.abc"
        context.window_manager.fileselect_add(self)
        return {"RUNNING_MODAL"}

    def execute(self, context):
        objs = [o for o in _selected_curves(context) if keyframes.keyed_frames(o)]
        try:
            path = api.export_flow(objs, bpy.path.abspath(self.filepath), scene=context.scene)
        except ValueError as err:
            self.report({"ERROR"}, str(err))
            return {"CANCELLED"}
        self.report({"INFO"}, f"Exported the flow of {api.group_name(objs)} to {path}")
        return {"FINISHED"}


class MOEBIUS_OT_show_gradient(bpy.types.Operator):
    """Draw the energy gradients of the active curve as vector fields (one edge per vertex)"""

    bl_idname = "moebius.show_gradient"
    bl_label = "Show Gradients"
    bl_options = {"REGISTER", "UNDO"}

    l2: BoolProperty(name="L²", default=True, description="Plain L² gradient (red)")
    hs_pure: BoolProperty(name="W^{s,2} pure", default=True,
                          description="Pure fractional Sobolev gradient (green); the order s "
                          "fits the Flow panel's energy")
    hs: BoolProperty(name="W^{s,2} geometric", default=True,
                     description="Geometric Sobolev gradient used by the flow (blue); the "
                     "order s fits the Flow panel's energy")
    length: FloatProperty(name="Arrow Length", default=0.15, min=0.0, soft_max=1.0,
                          subtype="FACTOR",
                          description="Longest arrow of each field, relative to the curve's size")
    projected: BoolProperty(name="Projected", default=True,
                            description="Project onto the constraints (what the flow follows)")

    poll = classmethod(_poll_active_curve)

    def execute(self, context):
        metrics = [m for m in ("l2", "hs_pure", "hs") if getattr(self, m)]
        if not metrics:
            self.report({"ERROR"}, "Tick at least one gradient to show")
            return {"CANCELLED"}
        obj = _active_curve(context)
        try:
            # the gradient of the energy the Flow panel relaxes
            made = api.show_gradients(obj, metrics, length=self.length,
                                      projected=self.projected, context=context,
                                      **options.energy_settings(context.scene.moebius))
        except ValueError as err:
            self.report({"ERROR"}, str(err))
            return {"CANCELLED"}
        context.view_layer.objects.active = obj
        self.report({"INFO"}, "Added " + ", ".join(o.name for o in made))
        return {"FINISHED"}


class MOEBIUS_OT_apply_preset(bpy.types.Operator):
    """Set the panel's settings for a kind of scene (and give the selected curves a
    thickness); every setting can be changed afterwards"""

    bl_idname = "moebius.apply_preset"
    bl_label = "Apply Preset"
    bl_options = {"REGISTER", "UNDO"}

    preset: EnumProperty(
        name="Preset",
        items=[(key, label, desc) for key, (label, desc, _) in options.PRESETS.items()])

    @classmethod
    def description(cls, context, properties):
        return options.PRESETS[properties.preset][1]

    @classmethod
    def poll(cls, context):
        settings = getattr(context.scene, "moebius", None)
        if settings is not None and settings.running:
            cls.poll_message_set("A relaxation is running; press Esc in the 3D Viewport to "
                                 "stop it")
            return False
        return True

    def execute(self, context):
        try:
            curves = _selected_curves(context)
            done = presets.apply_preset(context.scene, self.preset,
                                        curves or context.active_object)
        except ValueError as err:
            self.report({"ERROR"}, str(err))
            return {"CANCELLED"}
        self.report({"INFO"}, f"Preset {done}")
        return {"FINISHED"}


class MOEBIUS_MT_presets(bpy.types.Menu):
    """Settings for a kind of scene: cables between fixed ends, a curve packed in a volume,
    a knot"""

    bl_idname = "MOEBIUS_MT_presets"
    bl_label = "Presets"

    def draw(self, context):
        for key, (label, _, _) in options.PRESETS.items():
            self.layout.operator(MOEBIUS_OT_apply_preset.bl_idname, text=label).preset = key


def menu_add_knot(self, context):
    self.layout.menu(MOEBIUS_MT_add_knot.bl_idname, text="Knot", icon="CURVE_DATA")


classes = (
    MOEBIUS_OT_convert,
    MOEBIUS_OT_relax,
    MOEBIUS_OT_add_knot,
    MOEBIUS_OT_add_notation,
    MOEBIUS_OT_identify,
    MOEBIUS_MT_add_knot,
    MOEBIUS_OT_clear_animation,
    MOEBIUS_OT_apply_frame,
    MOEBIUS_OT_export_flow,
    MOEBIUS_OT_show_gradient,
    MOEBIUS_OT_apply_preset,
    MOEBIUS_MT_presets,
)


def register() -> None:
    for cls in (*classes, *live.classes):
        bpy.utils.register_class(cls)
    bpy.types.VIEW3D_MT_curve_add.append(menu_add_knot)
    live.register_keymap()


def unregister() -> None:
    live.unregister_keymap()
    bpy.types.VIEW3D_MT_curve_add.remove(menu_add_knot)
    for cls in reversed((*classes, *live.classes)):
        bpy.utils.unregister_class(cls)
