"""Sidebar panel View3D ▸ Sidebar ▸ Möbius, with Polygon / Flow / Keyframes / Advanced."""

from __future__ import annotations

import bpy

from .keyframes import ENERGY_PROP, keyed_frames


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
        if s.running:
            if hasattr(col, "progress"):  # Blender 4.0+
                col.progress(factor=s.progress, text=f"Iteration {s.live_iteration}")
            else:
                col.label(text=f"Iteration {s.live_iteration} ({100 * s.progress:.0f} %)")
            col.label(text=f"Energy {s.live_energy:.6g}", icon="SORTTIME")
            col.label(text="Esc in the viewport stops (keeps the iterates)")
        elif obj is not None and ENERGY_PROP in obj:
            col.label(text=f"{obj.name}: energy {obj[ENERGY_PROP]:.6g}", icon="CURVE_DATA")
            frames = keyed_frames(obj)
            if frames:
                col.label(text=f"Flow keyed on frames {frames[0]:.0f}–{frames[-1]:.0f}")
        elif obj is not None and obj.type in {"CURVE", "MESH"}:
            col.label(text=f"{obj.name}: not converted yet", icon="INFO")
        else:
            col.label(text="Select a curve, or add a knot", icon="INFO")
        row = layout.row(align=True)
        row.scale_y = 1.4
        row.operator("moebius.relax", icon="PLAY")
        if s.last_object:
            box = layout.box()
            box.label(text=f"Last run: {s.last_object}")
            grid = box.grid_flow(columns=2, align=True)
            grid.label(text="Iterations")
            grid.label(text=str(s.last_iterations))
            grid.label(text="Energy")
            grid.label(text=f"{s.last_energy_start:.5g} → {s.last_energy_end:.5g}")
            grid.label(text="Time")
            grid.label(text=f"{s.last_seconds:.2f} s")
            grid.label(text="Keyed frames")
            grid.label(text=str(s.last_keyframes))
            box.label(text=s.last_message)


class VIEW3D_PT_moebius_polygon(_MoebiusPanel, bpy.types.Panel):
    bl_label = "Polygon"
    bl_parent_id = "VIEW3D_PT_moebius"

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        s = context.scene.moebius
        layout.prop(s, "use_edge_length")
        if s.use_edge_length:
            layout.prop(s, "edge_length")
        else:
            layout.prop(s, "edges")
        layout.prop(s, "close_open")
        layout.operator("moebius.convert", icon="MOD_CURVE")
        layout.operator_menu_enum("moebius.add_knot", "kind", text="Add Knot", icon="ADD")


class VIEW3D_PT_moebius_flow(_MoebiusPanel, bpy.types.Panel):
    bl_label = "Flow"
    bl_parent_id = "VIEW3D_PT_moebius"

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        s = context.scene.moebius
        layout.prop(s, "metric")
        layout.prop(s, "max_iterations")
        layout.prop(s, "tolerance")
        row = layout.row(heading="Energy Target")
        row.prop(s, "use_energy_target", text="")
        sub = row.row()
        sub.active = s.use_energy_target
        sub.prop(s, "energy_target", text="")
        layout.prop(s, "max_seconds")


class VIEW3D_PT_moebius_keyframes(_MoebiusPanel, bpy.types.Panel):
    bl_label = "Keyframes"
    bl_parent_id = "VIEW3D_PT_moebius"

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        s = context.scene.moebius
        layout.prop(s, "frame_start")
        layout.prop(s, "keyframe_stride")
        row = layout.row(align=True)
        row.operator("moebius.apply_frame", icon="CHECKMARK")
        row.operator("moebius.clear_animation", icon="X")


class VIEW3D_PT_moebius_advanced(_MoebiusPanel, bpy.types.Panel):
    bl_label = "Advanced"
    bl_parent_id = "VIEW3D_PT_moebius"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        s = context.scene.moebius
        col = layout.column(heading="Line Search")
        col.prop(s, "initial_step")
        col.prop(s, "armijo")
        col.prop(s, "growth")
        col = layout.column(heading="Back-projection")
        col.prop(s, "backproject_iter", text="Iterations")
        col.prop(s, "backproject_tol", text="Tolerance")
        col = layout.column(heading="Constraints")
        col.prop(s, "keep_edge_lengths")
        col.prop(s, "keep_barycenter")
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
