"""Sidebar panel View3D ▸ Sidebar ▸ Möbius, with Polygon / Flow / Keyframes / Advanced.

The sidebar is narrow (about 30 characters of label text at its default width), so fields are
drawn full width with their name inside (no property split), long texts are wrapped, and
enums get their label on a line of their own.
"""

from __future__ import annotations

import textwrap

import bpy

from . import labels, options
from .identification import KNOT_TYPE_PROP
from .keyframes import ENERGY_PROP, keyed_frames


def wrap_text(text: str, width_px: float, ui_scale: float = 1.0) -> list[str]:
    """Lines of ``text`` that fit a panel ``width_px`` pixels wide (Blender does not wrap labels).

    About 7 px per character at UI scale 1 (in a Blender window, lines of 26 characters with
    digits or dashes were cut off in the default sidebar, 24 were not), less a box's margins.
    """
    chars = max(16, int((width_px / max(ui_scale, 0.1) - 40) / 7))
    return textwrap.wrap(text, chars) or [""]


def _wrapped_label(layout, context, text: str) -> None:
    region = getattr(context, "region", None)
    width = region.width if region is not None else 220
    for line in wrap_text(text, width, context.preferences.system.ui_scale):
        layout.label(text=line)


class _MoebiusPanel:
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "Möbius"


class VIEW3D_PT_moebius(_MoebiusPanel, bpy.types.Panel):
    bl_label = "Möbius Energy"

    def draw(self, context):
        layout = self.layout
        s = context.scene.moebius
        obj = context.active_object
        col = layout.column(align=True)
        if s.running and getattr(s, "live", False):
            col.label(text=f"Live: iteration {s.live_iteration}", icon="REC")
            col.label(text=f"Energy {s.live_energy:.6g}", icon="SORTTIME")
            col.label(text="Enter keeps, Esc restores")
        elif s.running:
            if hasattr(col, "progress"):  # Blender 4.0+
                col.progress(factor=s.progress, text=f"Iteration {s.live_iteration}")
            else:
                col.label(text=f"Iteration {s.live_iteration} ({100 * s.progress:.0f} %)")
            col.label(text=f"Energy {s.live_energy:.6g}", icon="SORTTIME")
            col.label(text="Esc stops, keeps the iterates")
        elif obj is not None and ENERGY_PROP in obj:
            col.label(text=obj.name, icon="CURVE_DATA")
            col.label(text=f"Energy {obj[ENERGY_PROP]:.6g}")
            if obj.get(KNOT_TYPE_PROP):
                col.label(text=f"Type {obj[KNOT_TYPE_PROP]}")
            frames = keyed_frames(obj)
            if frames:
                col.label(text=f"Keyed frames {frames[0]:.0f}–{frames[-1]:.0f}")
        elif obj is not None and obj.type in {"CURVE", "MESH"}:
            col.label(text=obj.name, icon="INFO")
            col.label(text="Not converted yet")
        else:
            col.label(text="Select a curve object", icon="INFO")
            col.label(text="or add a knot (Polygon)")
        layout.menu("MOEBIUS_MT_presets", icon="PRESET")
        row = layout.row(align=True)
        row.scale_y = 1.4
        row.operator("moebius.relax", icon="PLAY").append = False
        # Continue appends to the keyed flow; without one there is nothing to continue
        sub = row.row(align=True)
        sub.enabled = obj is not None and bool(keyed_frames(obj))
        sub.operator("moebius.relax", text="Continue", icon="FF").append = True
        # Live (blender.live): the flow follows what the user moves
        row = layout.row(align=True)
        if getattr(s, "live", False):
            row.operator("moebius.live_finish", text="Finish Live", icon="CHECKMARK")
        else:
            row.operator("moebius.live", text="Live", icon="REC")
        sub = row.row(align=True)
        sub.enabled = not s.running
        sub.prop(s, "live_record", toggle=True, icon="KEYINGSET")
        if getattr(s, "live", False):  # read on every update while Live runs
            layout.prop(s, "live_grow", slider=False)
        # the statistics of the previous run would be mistaken for the running one's
        if s.last_object and not s.running:
            box = layout.box()
            col = box.column(align=True)
            col.label(text="Last Run", icon="TIME")
            col.label(text=s.last_object)
            col.label(text=labels.method_label(s.last_method))
            for name, value in (
                ("Iterations", str(s.last_iterations)),
                (s.last_energy_row,
                 f"{s.last_energy_start:.5g} → {s.last_energy_end:.5g}"),
                ("Time", f"{s.last_seconds:.2f} s"),
                ("Keyed", f"{s.last_keyframes} frames"),
                ("Engine", labels.engine_label(s.last_engine)),
            ):
                split = col.split(factor=0.38)
                split.label(text=name)
                split.label(text=value)
            _wrapped_label(box.column(align=True), context, s.last_message)
            if s.last_refined:
                _wrapped_label(box.column(align=True), context, f"Refined: {s.last_refined}")
            if s.last_type:
                _wrapped_label(box.column(align=True), context, s.last_type)


class VIEW3D_PT_moebius_polygon(_MoebiusPanel, bpy.types.Panel):
    bl_label = "Polygon"
    bl_parent_id = "VIEW3D_PT_moebius"

    def draw(self, context):
        layout = self.layout
        s = context.scene.moebius
        col = layout.column(align=True)
        col.prop(s, "use_edge_length")
        if s.use_edge_length:
            col.prop(s, "edge_length")
        else:
            col.prop(s, "edges")
        layout.prop(s, "close_open")
        row = layout.row()
        row.active = not s.close_open
        row.prop(s, "keep_open")
        layout.operator("moebius.convert", icon="MOD_CURVE")
        layout.operator("moebius.add_knot", text="Add Knot…", icon="ADD")
        col = layout.column(align=True)
        col.prop(s, "notation", text="")
        col.operator("moebius.add_notation", text="Add from Notation", icon="TEXT").notation = (
            s.notation)
        layout.operator("moebius.identify", icon="VIEWZOOM")


class VIEW3D_PT_moebius_flow(_MoebiusPanel, bpy.types.Panel):
    bl_label = "Flow"
    bl_parent_id = "VIEW3D_PT_moebius"

    def draw(self, context):
        layout = self.layout
        s = context.scene.moebius
        col = layout.column(align=True)
        col.label(text="Energy")
        col.prop(s, "energy", text="")
        for record, p in labels.ENERGY_PARAMETERS:  # the added energies' weights: Stiffness
            if p is record.weight:
                col.prop(s, p.setting)
        col.label(text="Metric")
        col.prop(s, "metric", text="")
        if s.metric in ("hs", "hs_pure"):  # its order depends on the energy (api.md)
            try:
                col.label(text="Order " + labels.metric_order_text(
                    **options.energy_settings(s)))
            except ValueError:  # Relax reports the whole message
                own = ", ".join(p.label for r, p in labels.ENERGY_PARAMETERS
                                if r.name == s.energy and p in r.parameters)
                col.label(text=f"{own} out of range (Advanced)", icon="ERROR")
        col = layout.column(align=True)
        col.prop(s, "max_iterations")
        col.prop(s, "tolerance")
        col.prop(s, "settle")
        row = layout.row(align=True)
        row.prop(s, "use_energy_target", text="")
        sub = row.row(align=True)
        sub.active = s.use_energy_target
        sub.prop(s, "energy_target", text="Energy Target")
        layout.prop(s, "max_seconds")
        col = layout.column(align=True)
        col.prop(s, "refine")
        row = col.row()
        row.active = s.refine
        row.prop(s, "max_edges")


class VIEW3D_PT_moebius_keyframes(_MoebiusPanel, bpy.types.Panel):
    bl_label = "Keyframes"
    bl_parent_id = "VIEW3D_PT_moebius"

    def draw(self, context):
        layout = self.layout
        s = context.scene.moebius
        col = layout.column(align=True)
        col.prop(s, "frame_start")
        col.prop(s, "keyframe_stride")
        row = layout.row(align=True)  # no icons: half the sidebar is too narrow for them
        row.operator("moebius.apply_frame", text="Apply Frame")
        row.operator("moebius.clear_animation", text="Clear Flow")
        layout.operator("moebius.export_flow", text="Export Flow…", icon="EXPORT")


class VIEW3D_PT_moebius_advanced(_MoebiusPanel, bpy.types.Panel):
    bl_label = "Advanced"
    bl_parent_id = "VIEW3D_PT_moebius"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        layout = self.layout
        s = context.scene.moebius
        acting = options.acting_settings(s.method, s.engine)
        col = layout.column(align=True)
        col.label(text="Method")
        col.prop(s, "method", text="")
        if s.method == labels.AUTO_METHOD:  # what the automatic choice does, measured best
            col.label(text="Knots, links: Implicit Gradient")
            col.label(text="Unknots: Projected")
        if "penalty" in acting:
            col.prop(s, "penalty")
        for record in labels.ENERGY_RECORDS:  # each energy's parameters (α, β), active when
            if record.parameters:  # it is the chosen one
                col = layout.column(align=True)
                col.label(text=f"{record.label} Parameters")
                row = col.row(align=True)
                row.active = s.energy == record.name
                for p in record.parameters:
                    row.prop(s, p.setting)
        col = layout.column(align=True)
        col.label(text="Engine")
        col.prop(s, "engine", text="")
        if "theta" in acting:  # only where the tree can run
            col.prop(s, "theta")
        # settings the method does not use stay visible, greyed out (tooltips say which use
        # them); options.acting_settings is also what relax_settings passes on
        col = layout.column(align=True)
        col.label(text="Line Search")
        col.prop(s, "initial_step")
        sub = col.column(align=True)
        sub.active = "armijo" in acting  # with Automatic: for unknots
        sub.prop(s, "armijo")
        sub.prop(s, "growth")
        col = layout.column(align=True)
        col.active = "backproject_iter" in acting
        col.label(text="Back-projection")
        col.prop(s, "backproject_iter", text="Iterations")
        col.prop(s, "backproject_digits", text="Digits")
        col = layout.column(align=True)
        col.active = "keep_edge_lengths" in acting
        col.label(text="Constraints")
        col.prop(s, "keep_edge_lengths")
        col.prop(s, "keep_barycenter")
        sub = col.row()
        sub.active = "keep_thickness" in acting
        sub.prop(s, "keep_thickness")
        sub = col.row()
        sub.active = "keep_thickness" in acting and s.keep_thickness
        sub.prop(s, "push_apart")
        col = layout.column(align=True)
        col.label(text="Pins and Obstacles")
        sub = col.column(align=True)
        sub.active = "keep_edge_lengths" in acting  # the penalty methods refuse pins
        sub.prop(s, "pin_selected")
        row = sub.row()
        row.active = s.pin_selected
        row.prop(s, "pin_tangents")
        col.prop(s, "obstacles", text="")
        col.prop(s, "container")
        row = col.row()
        row.active = s.obstacles is not None or s.container is not None
        row.prop(s, "obstacle_weight")
        col = layout.column(align=True)
        col.label(text="Length Growth")
        col.prop(s, "use_length_target")
        sub = col.column(align=True)
        sub.active = s.use_length_target
        sub.prop(s, "length_target")
        sub.prop(s, "length_growth")
        col = layout.column(align=True)
        col.active = "backproject_iter" in acting  # a nudge keeps the constraints
        col.label(text="Restarts")
        row = col.row(align=True)
        row.prop(s, "restarts", text="Count")
        row.prop(s, "seed")
        layout.operator("moebius.show_gradient", icon="ORIENTATION_NORMAL")


classes = (
    VIEW3D_PT_moebius,
    VIEW3D_PT_moebius_polygon,
    VIEW3D_PT_moebius_flow,
    VIEW3D_PT_moebius_keyframes,
    VIEW3D_PT_moebius_advanced,
)


def register() -> None:
    for cls in classes:
        bpy.utils.register_class(cls)


def unregister() -> None:
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
