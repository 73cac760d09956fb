"""Write the .blend the UI test opens: a knotted NURBS curve, selected, the sidebar shown.

Run by Blender itself (``blender -b --factory-startup --python make_scene.py -- OUT.blend``),
with the repository on ``sys.path`` for the knot catalogue. The curve is the coiled helix
unknot of ``core.knots`` (the paper's Fig. 5) as a smooth cyclic NURBS curve named "Helix", so
Convert has something to do. The add-on is registered from the checkout only to store the panel
settings of the test in the file (``scene.moebius``: 160 edges); it is not installed here.
"""

from __future__ import annotations

import sys
from pathlib import Path

import bpy

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from moebius_addon.core.topology import knots  # noqa: E402

#: Edges of the converted polygon: small enough that a run of ~70 iterations takes tens of
#: seconds in a software-rendered Blender, long enough to screenshot it mid-run.
EDGES = 160


def _knot_curve(name: str):
    P = knots.helix_unknot(300)
    curve = bpy.data.curves.new(name, "CURVE")
    curve.dimensions = "3D"
    curve.bevel_depth = 0.03
    curve.bevel_resolution = 2
    spline = curve.splines.new("NURBS")
    spline.points.add(len(P) - 1)
    co = [(x, y, z, 1.0) for x, y, z in P]
    spline.points.foreach_set("co", [c for p in co for c in p])
    spline.use_cyclic_u = True
    spline.order_u = 3
    obj = bpy.data.objects.new(name, curve)
    bpy.context.scene.collection.objects.link(obj)
    return obj


def _frame_views() -> None:
    """Sidebar open, view from the front-left and far enough for the relaxed circle (r ≈ 2.8)."""
    from mathutils import Euler

    for screen in bpy.data.screens:
        for area in screen.areas:
            if area.type != "VIEW_3D":
                continue
            space = area.spaces.active
            space.show_region_ui = True
            space.overlay.show_floor = True
            space.shading.type = "SOLID"
            r3d = space.region_3d
            r3d.view_perspective = "PERSP"
            r3d.view_location = (0.0, 0.0, 0.0)
            r3d.view_rotation = Euler((1.15, 0.0, 0.6)).to_quaternion()
            r3d.view_distance = 13.0


def main(out: str) -> None:
    bpy.ops.wm.read_factory_settings(use_empty=False)
    for obj in list(bpy.data.objects):
        if obj.type == "MESH":  # the default cube
            bpy.data.objects.remove(obj)
    knot = _knot_curve("Helix")
    for obj in bpy.data.objects:
        obj.select_set(False)
    knot.select_set(True)
    bpy.context.view_layer.objects.active = knot
    _frame_views()

    import moebius_addon

    moebius_addon.register()
    settings = bpy.context.scene.moebius
    settings.edges = EDGES
    settings.max_iterations = 200
    moebius_addon.unregister()
    Path(out).parent.mkdir(parents=True, exist_ok=True)
    bpy.ops.wm.save_as_mainfile(filepath=str(Path(out).resolve()), compress=False)
    print(f"make_scene: wrote {out}")


if __name__ == "__main__":
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    main(argv[0] if argv else "out/ui/knot.blend")
