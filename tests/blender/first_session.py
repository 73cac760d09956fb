"""A first session after installing, as a user has it: the zip installed into a new user
directory (``BLENDER_USER_RESOURCES``), then each preset and feature run through the panel's
operators on a small scene of its own, counting the kernels numba compiles on each
(``core.compiling``) and its CPU seconds. Prints one JSON line: ``{path: {"kernels", "seconds",
"iterations"}}``, ``"scipy"``: whether this Python can import scipy, and ``"generic"``:
whether this CPU runs the shipped kernels (``core.compilation.shipped_cache.host_runs_generic``).

    python tests/blender/first_session.py EXTENSION.zip
"""

from __future__ import annotations

import importlib
import importlib.util
import json
import sys
import time
from pathlib import Path

import bpy
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bpy_helpers import EXT_MODULE, poly_curve  # noqa: E402


def _core():
    return importlib.import_module(EXT_MODULE + ".core")


def _mesh_in(collection, obj):
    for c in obj.users_collection:
        c.objects.unlink(obj)
    collection.objects.link(obj)


def _cables_between_plates(gap: float = 0.0) -> None:
    """Six open cables hanging between two plates (their ends on them, or ``gap`` off) through
    a torus (Untangle Cables' scene), one object with a spline per cable; the plates and the
    torus in the collection 'Obstacles'."""
    obstacles = bpy.data.collections.new("Obstacles")
    bpy.context.scene.collection.children.link(obstacles)
    for z in (-0.02 - gap, 1.02 + gap):
        bpy.ops.mesh.primitive_cube_add(size=1.0, location=(0.0, 0.0, z), scale=(2.0, 2.0, 0.04))
        _mesh_in(obstacles, bpy.context.active_object)
    bpy.ops.mesh.primitive_torus_add(major_radius=0.6, minor_radius=0.08, location=(0, 0, 0.5))
    _mesh_in(obstacles, bpy.context.active_object)
    t = np.linspace(0.0, 1.0, 400)
    cables = [np.c_[0.3 * np.cos(np.pi * c / 3) + 0.02 * np.sin(3 * t + c),
                    0.3 * np.sin(np.pi * c / 3) + 0.02 * np.cos(2 * t + c), t] for c in range(6)]
    poly_curve("Cables", _core().resample(cables, [171] * 6, closed=False), cyclic=False)


def _loop_in_sphere() -> None:
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.9, segments=24, ring_count=12)
    sphere = bpy.context.active_object
    t = np.linspace(0.0, 2 * np.pi, 300, endpoint=False)
    poly_curve("Loop", [_core().resample(np.c_[0.6 * np.cos(t), 0.6 * np.sin(t),
                                               0.2 * np.sin(5 * t)], 60)])
    bpy.context.scene.moebius.container = sphere


def _relax(iterations: int = 2) -> int:
    s = bpy.context.scene.moebius
    s.max_iterations, s.tolerance = iterations, 0.0
    assert bpy.ops.moebius.relax() == {"FINISHED"}
    return s.last_iterations


def main() -> None:
    zip_path = sys.argv[1]
    assert bpy.ops.extensions.package_install_files(
        filepath=zip_path, repo="user_default", enable_on_install=True) == {"FINISHED"}
    compiling = importlib.import_module(EXT_MODULE + ".core.compilation.notice")

    def preset(name: str, scene, pin_tangents: bool | None = None):
        def run() -> int:
            scene()
            assert bpy.ops.moebius.apply_preset(preset=name) == {"FINISHED"}
            if pin_tangents is not None:
                bpy.context.scene.moebius.pin_tangents = pin_tangents
            return _relax()
        return run

    def knot(kind: str, edges: int, **settings):
        def run() -> int:
            assert bpy.ops.moebius.add_knot(kind=kind, edges=edges) == {"FINISHED"}
            for key, value in settings.items():
                setattr(bpy.context.scene.moebius, key, value)
            return _relax()
        return run

    def identify() -> int:
        assert bpy.ops.moebius.add_knot(kind="8_19", edges=200) == {"FINISHED"}
        assert bpy.ops.moebius.identify() == {"FINISHED"}
        return 0

    paths = {
        "relax_knot": preset("relax_knot", lambda: bpy.ops.moebius.add_knot(kind="3_1",
                                                                            edges=100)),
        "untangle_cables": preset("untangle_cables", _cables_between_plates),
        "untangle_cables, free tangents": preset(
            "untangle_cables", lambda: _cables_between_plates(gap=0.02), pin_tangents=False),
        "pack_in_volume": preset("pack_in_volume", _loop_in_sphere),
        "tree": knot("3_1", 3000),
        "tangent_point": knot("3_1", 100, energy="tangent_point"),
        "identify": identify,
    }
    shipped = importlib.import_module(EXT_MODULE + ".core.compilation.shipped_cache")
    found = {"scipy": importlib.util.find_spec("scipy") is not None,
             "generic": shipped.host_runs_generic()}
    for name, run in paths.items():
        bpy.ops.wm.read_homefile(use_empty=True)
        t = time.process_time()
        with compiling.compiling() as watch:
            iterations = run()
        found[name] = {"kernels": watch.kernels, "seconds": time.process_time() - t,
                       "iterations": iterations}
    print(json.dumps(found))


if __name__ == "__main__":
    main()
