"""The extension zip: built with blender_ext.py, valid, installable, numba cache in user dir, and
in a new Blender session the numba it ships with Blender's numpy."""

import importlib.util
import json
import os
import subprocess
import sys
import tomllib
import zipfile
from pathlib import Path

import bpy
import pytest
from bpy_helpers import EXT_MODULE, PYTHON, ROOT

CP = "cp" + PYTHON.replace(".", "")  # this Python's wheel tag, e.g. cp311


@pytest.mark.lines
def test_zip_contents_and_manifest(extension_zip):
    with zipfile.ZipFile(extension_zip) as z:
        names = z.namelist()
        manifest = tomllib.loads(z.read("blender_manifest.toml").decode())
    assert "__init__.py" in names and "core/__init__.py" in names
    assert "blender/operators.py" in names
    assert not any("__pycache__" in n for n in names)
    wheels = sorted(n.split("/")[-1] for n in names if n.endswith(".whl"))
    assert all("manylinux" in w for w in wheels), wheels
    # the wheels for this Python (`make test`'s zip has those of 3.11 and 3.13, as shipped)
    assert [w.split("-")[0] for w in wheels if f"-{CP}-" in w] == ["llvmlite", "numba"]
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


@pytest.mark.lines
def test_installed_and_enabled(mb):
    assert EXT_MODULE in bpy.context.preferences.addons
    for op in ("convert", "relax", "add_knot", "clear_animation", "apply_frame",
               "show_gradient"):
        assert hasattr(bpy.ops.moebius, op), op
    assert mb.__name__ == EXT_MODULE + ".blender"
    # the installed copy, not the repository checkout, is what runs
    assert "extensions" in mb.__file__ and str(ROOT) not in mb.__file__


@pytest.mark.lines
def test_numba_cache_in_extension_user_dir(scene, mb):
    cache = bpy.utils.extension_path_user(EXT_MODULE, path="numba_cache")
    assert os.environ["NUMBA_CACHE_DIR"] == cache
    bpy.ops.moebius.add_knot(kind="3_1", edges=60)  # compiles (or loads) the kernels
    files = [f for _, _, fs in os.walk(cache) for f in fs]
    installed = Path(mb.__file__).parents[1]
    # compiled here into the user directory, or loaded from the cache the zip ships
    assert (any(f.endswith(".nbi") for f in files)
            or any((installed / "core" / "kernel_cache").rglob("*.nbi"))), files
    assert not any(installed.rglob("__pycache__/*.nbi"))  # never beside the installed files


@pytest.mark.lines
def test_a_new_session_runs_on_the_numba_the_extension_ships(mb):
    # In this process the main venv's numba may have been imported first (its tests import the
    # repository's core); a new Blender session, as a user starts one, shows what the extension
    # gets: numba and llvmlite from its wheels, numpy from Blender's own Python.
    manifest = tomllib.loads((ROOT / "blender_manifest.toml").read_text())
    pinned = {w.split("/")[-1].split("-")[0]: w.split("-")[1] for w in manifest["wheels"]}
    code = (
        "import bpy, addon_utils, json, sys\n"
        f"addon_utils.enable({EXT_MODULE!r}, default_set=True)\n"
        "import llvmlite, numba, numpy\n"
        "print(json.dumps({m.__name__: [m.__version__, m.__file__]"
        " for m in (llvmlite, numba, numpy)} | {'wheels': bpy.utils.user_resource("
        "'EXTENSIONS', path='.local'), 'enabled': hasattr(bpy.ops.moebius, 'relax')}))\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=300)  # BLENDER_USER_RESOURCES: this session's (conftest)
    assert proc.returncode == 0, proc.stderr[-3000:]
    found = json.loads(proc.stdout.strip().splitlines()[-1])
    assert found["enabled"]
    for name in ("numba", "llvmlite"):
        version, path = found[name]
        assert version == pinned[name] and path.startswith(found["wheels"]), (name, found)
    assert not found["numpy"][1].startswith(found["wheels"]), found


@pytest.mark.lines
def test_a_first_session_loads_the_kernels_the_zip_ships(extension_zip, tmp_path):
    # docs/blender.md's module route in a new user directory, as right after installing:
    # install the zip, Add Knot + Relax with progress. The linux-x64 zip of `make test` carries
    # the kernels compiled for a generic x86-64 CPU (mk/build_extension.py): none compiles here,
    # and they give the bits the build's compiled kernels gave (warmup.fingerprint; on 5.2 the
    # only check of the Python 3.13 kernels' bits)
    tag = f".py{PYTHON.replace('.', '')}."
    with zipfile.ZipFile(extension_zip) as z:
        if not any(n.startswith("core/kernel_cache/") and tag in n for n in z.namelist()):
            pytest.skip(f"the zip carries no kernel cache for Python {PYTHON} (`make test` "
                        "builds one)")
        recorded = z.read(f"core/kernel_cache/fingerprint-py{PYTHON.replace('.', '')}.txt")
    recorded = recorded.decode().strip()
    code = (
        "import bpy, json\n"
        f"bpy.ops.extensions.package_install_files(filepath={str(extension_zip)!r}, "
        "repo='user_default', enable_on_install=True)\n"
        f"from {EXT_MODULE} import blender as moebius\n"
        f"from {EXT_MODULE}.core import compiling\n"
        f"from {EXT_MODULE}.core.compilation import shipped_cache as _shipped_cache\n"
        "lines = []\n"
        "with compiling() as watch:\n"
        "    knot = moebius.add_knot('3_1', 100)\n"
        "    result = moebius.relax_object(knot, max_iterations=2, tol=0.0,"
        " progress=lines.append)\n"
        f"    from {EXT_MODULE}.core.compilation.warmup import fingerprint\n"
        "    bits = fingerprint()\n"
        "print(json.dumps(dict(kernels=watch.kernels, lines=lines, nit=result.nit,"
        " generic=_shipped_cache.host_runs_generic(), bits=bits)))\n"
    )
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(tmp_path))
    env.pop("NUMBA_CACHE_DIR", None)  # set in this process by the extension installed here
    proc = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                          timeout=900)
    assert proc.returncode == 0, proc.stderr[-3000:]
    found = json.loads(proc.stdout.strip().splitlines()[-1])
    assert found["nit"] == 2 and found["lines"][0].startswith("'Knot 3_1' iteration 1/2, energy")
    if not found["generic"]:
        pytest.skip("this CPU cannot run the shipped x86-64-v3 code: the kernels compiled")
    assert (found["kernels"], found["bits"]) == (0, recorded)


@pytest.mark.lines
def test_a_blender_venv_has_what_blenders_python_has():
    # Blender's own Python has numpy and no scipy: the Blender venvs (mk/lines.mk) are the same,
    # so that a path needing scipy fails here as it would in a user's Blender
    if not Path(sys.prefix).name.startswith(".venv-blender-"):
        pytest.skip(f"not a Blender venv of mk/lines.mk: {sys.prefix}")
    with pytest.raises(ImportError):
        import scipy  # noqa: F401
    site = Path(importlib.util.find_spec("numpy").origin).parents[1]
    assert not list(site.glob("numba*")) and not list(site.glob("scipy*")), site


@pytest.mark.lines
def test_every_preset_runs_from_the_kernels_the_zip_ships(extension_zip, tmp_path):
    # a first session in a new user directory: each preset and feature path through the panel's
    # operators (tests/blender/first_session.py); with the linux-x64 zip's kernel cache none of
    # them compiles a kernel, and in a Blender venv none needs scipy
    tag = f".py{PYTHON.replace('.', '')}."
    with zipfile.ZipFile(extension_zip) as z:
        cached = any(n.startswith("core/kernel_cache/") and tag in n for n in z.namelist())
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(tmp_path))
    env.pop("NUMBA_CACHE_DIR", None)  # set in this process by the extension installed here
    proc = subprocess.run([sys.executable, str(Path(__file__).parent / "first_session.py"),
                           str(extension_zip)], env=env, capture_output=True, text=True,
                          timeout=1500)
    assert proc.returncode == 0, proc.stderr[-3000:]
    found = json.loads(proc.stdout.strip().splitlines()[-1])
    scipy, generic = found.pop("scipy"), found.pop("generic")
    assert set(found) == {"relax_knot", "untangle_cables", "untangle_cables, free tangents",
                          "pack_in_volume", "tree", "tangent_point", "identify"}
    for name, path in found.items():
        assert path["iterations"] == (0 if name == "identify" else 2), (name, path)
    if not cached:
        pytest.skip(f"the zip carries no kernel cache for Python {PYTHON} (`make test` builds "
                    "one); every path ran" + (" without scipy" if not scipy else ""))
    if not generic:
        pytest.skip("this CPU cannot run the shipped x86-64-v3 code: the kernels compiled")
    assert {name: path["kernels"] for name, path in found.items()} == dict.fromkeys(found, 0)
