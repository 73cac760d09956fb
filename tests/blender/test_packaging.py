"""The extension zip: built with blender_ext.py, valid, installable, numba cache in user dir."""

import subprocess
import sys
import tomllib
import zipfile

import bpy
from bpy_helpers import EXT_MODULE, ROOT


def test_zip_contents_and_manifest(extension_zip):
    with zipfile.ZipFile(extension_zip) as z:
        names = z.namelist()
        manifest = tomllib.loads(z.read("blender_manifest.toml").decode())
    assert "__init__.py" in names and "core/__init__.py" in names
    assert "blender/operators.py" in names
    assert not any("__pycache__" in n for n in names)
    wheels = sorted(n for n in names if n.endswith(".whl"))
    assert [w.split("/")[-1].split("-")[0] for w in wheels] == ["llvmlite", "numba"]
    assert all("cp311" in w and "manylinux" in w for w in wheels)
    assert not any("numpy" in n for n in names), "numpy is Blender's own; do not bundle it"
    assert manifest["id"] == "moebius_addon"
    assert manifest["type"] == "add-on"
    assert manifest["blender_version_min"] == "4.2.0"
    assert manifest["build"]["generated"]["platforms"] == ["linux-x64"]


def test_source_manifest_ships_every_platform():
    manifest = tomllib.loads((ROOT / "blender_manifest.toml").read_text())
    assert set(manifest["platforms"]) == {"linux-x64", "windows-x64", "macos-arm64"}
    for platform_tag in ("manylinux", "win_amd64", "macosx"):
        for py in ("cp311", "cp313"):
            found = [w for w in manifest["wheels"] if platform_tag in w and py in w]
            assert len(found) == 2, (platform_tag, py, found)


def test_installed_and_enabled(mb):
    assert EXT_MODULE in bpy.context.preferences.addons
    for op in ("convert", "relax", "add_knot", "clear_animation", "apply_frame",
               "show_gradient"):
        assert hasattr(bpy.ops.moebius, op), op
    assert mb.__name__ == EXT_MODULE + ".blender"
    # the installed copy, not the repository checkout, is what runs
    assert "extensions" in mb.__file__ and str(ROOT) not in mb.__file__


def test_core_never_imports_bpy():
    code = "import sys, moebius_addon.core; sys.exit('bpy' in sys.modules)"
    assert subprocess.run([sys.executable, "-c", code], cwd=ROOT).returncode == 0


def test_numba_cache_in_extension_user_dir(scene, mb):
    import os

    cache = bpy.utils.extension_path_user(EXT_MODULE, path="numba_cache")
    assert os.environ["NUMBA_CACHE_DIR"] == cache
    bpy.ops.moebius.add_knot(kind="3_1", edges=60)  # compiles (or loads) the kernels
    files = [f for _, _, fs in os.walk(cache) for f in fs]
    assert any(f.endswith(".nbi") for f in files), files
