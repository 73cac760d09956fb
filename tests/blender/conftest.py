"""Fixtures for tests with the real ``bpy`` module (Blender 5.0 as a Python module, headless).

Blender reads ``BLENDER_USER_RESOURCES`` when ``bpy`` is first imported, so it is pointed at a
throw-away directory here, at collection time, before anything imports ``bpy``. The session
builds the extension zip for this platform with ``blender_ext.py`` (mk/build_extension.py) and
installs it with ``bpy.ops.extensions.package_install_files`` as a user would; every test then
drives the installed copy (``bl_ext.user_default.moebius_addon``) through ``bpy.ops``.
"""

from __future__ import annotations

import importlib
import os
import shutil
import sys
import tempfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

if "bpy" in sys.modules:  # pragma: no cover - would silently use the real user directory
    raise RuntimeError("bpy was imported before tests/blender/conftest.py; the isolated user "
                       "directory cannot be set any more")
USER_DIR = Path(tempfile.mkdtemp(prefix="moebius-blender-user-"))
os.environ["BLENDER_USER_RESOURCES"] = str(USER_DIR)

bpy = pytest.importorskip("bpy")

EXT_MODULE = "bl_ext.user_default.moebius_addon"


def pytest_sessionfinish(session, exitstatus):
    shutil.rmtree(USER_DIR, ignore_errors=True)


@pytest.fixture(scope="session")
def extension_zip(tmp_path_factory) -> Path:
    """The linux-x64 extension zip (Python 3.11 wheels only), built and validated."""
    sys.path.insert(0, str(ROOT / "mk"))
    try:
        import build_extension
    finally:
        sys.path.pop(0)
    out = tmp_path_factory.mktemp("dist")
    (zip_path,) = build_extension.build(out, ["linux-x64"], ["3.11"])
    return zip_path


@pytest.fixture(scope="session")
def mb(extension_zip):
    """The installed extension's Blender layer (``bl_ext.user_default.moebius_addon.blender``)."""
    result = bpy.ops.extensions.package_install_files(
        filepath=str(extension_zip), repo="user_default", enable_on_install=True
    )
    assert result == {"FINISHED"}
    return importlib.import_module(EXT_MODULE + ".blender")


@pytest.fixture(scope="session")
def core(mb):
    """The installed extension's numerical core."""
    return importlib.import_module(EXT_MODULE + ".core")


@pytest.fixture
def scene(mb):
    """An empty file with the extension enabled (reset before every test)."""
    bpy.ops.wm.read_homefile(use_empty=True)
    assert hasattr(bpy.context.scene, "moebius"), "the extension was disabled by the reset"
    return bpy.context.scene


def poly_curve(name: str, polygons, cyclic: bool = True, spline_type: str = "POLY"):
    """Link a new curve object with one spline per ``(n, 3)`` point array and select it."""
    import numpy as np

    curve = bpy.data.curves.new(name, "CURVE")
    curve.dimensions = "3D"
    for P in polygons:
        P = np.asarray(P, dtype=float)
        spline = curve.splines.new(spline_type)
        spline.points.add(len(P) - 1)
        spline.points.foreach_set("co", np.column_stack([P, np.ones(len(P))]).ravel())
        spline.use_cyclic_u = cyclic
    obj = bpy.data.objects.new(name, curve)
    bpy.context.scene.collection.objects.link(obj)
    for o in bpy.context.view_layer.objects:
        o.select_set(False)
    obj.select_set(True)
    bpy.context.view_layer.objects.active = obj
    return obj


def scene_state() -> dict:
    """Everything a failed operator must leave alone: data-blocks, visibility, geometry."""
    import numpy as np

    state = {
        "objects": sorted(o.name for o in bpy.data.objects),
        "curves": sorted(c.name for c in bpy.data.curves),
        "meshes": sorted(m.name for m in bpy.data.meshes),
        "actions": sorted(a.name for a in bpy.data.actions),
        "hidden": sorted(o.name for o in bpy.data.objects if o.hide_get() or o.hide_render),
        "frames": (bpy.context.scene.frame_start, bpy.context.scene.frame_end),
    }
    for c in bpy.data.curves:
        for k, s in enumerate(c.splines):
            pts = s.bezier_points if s.type == "BEZIER" else s.points
            co = np.empty(len(pts) * (3 if s.type == "BEZIER" else 4))
            pts.foreach_get("co", co)
            state[f"{c.name}/{k}"] = co.round(12).tolist()
    return state


def points_at(obj, frame: int):
    """World-space spline points of ``obj`` at ``frame`` as one ``(N, 3)`` array."""
    import numpy as np

    bpy.context.scene.frame_set(frame)
    M = np.array(obj.matrix_world)
    X = []
    for s in obj.data.splines:
        co = np.empty(4 * len(s.points))
        s.points.foreach_get("co", co)
        X.append(co.reshape(-1, 4)[:, :3])
    X = np.concatenate(X)
    return X @ M[:3, :3].T + M[:3, 3]
