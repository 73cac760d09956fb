"""Fixtures for tests with the real ``bpy`` module (Blender 5.0 as a Python module, headless).

Blender reads ``BLENDER_USER_RESOURCES`` when ``bpy`` is first imported, so it is pointed at a
throw-away directory here, at collection time, before anything imports ``bpy``. The session
builds the extension zip for this platform with ``blender_ext.py`` (mk/build_extension.py) and
installs it with ``bpy.ops.extensions.package_install_files`` as a user would; every test then
drives the installed copy (``bl_ext.user_default.moebius_addon``) through ``bpy.ops``.
"""

from __future__ import annotations

import importlib
import importlib.util
import os
import shutil
import sys
import tempfile
from pathlib import Path

import pytest

if "bpy" in sys.modules:  # pragma: no cover - would silently use the real user directory
    raise RuntimeError("bpy was imported before tests/blender/conftest.py; the isolated user "
                       "directory cannot be set any more")
USER_DIR = Path(tempfile.mkdtemp(prefix="moebius-blender-user-"))
os.environ["BLENDER_USER_RESOURCES"] = str(USER_DIR)

bpy = pytest.importorskip("bpy")

# The venv of a Blender line (mk/lines.mk) holds bpy and pytest only: numba comes with the
# extension, as in a user's Blender. Modules that import the repository's core at collection
# (it needs numba in the venv) or run its scripts are for the main venv.
if importlib.util.find_spec("numba") is None:
    collect_ignore = ["test_methods.py", "test_scripts.py"]

from bpy_helpers import EXT_MODULE, PYTHON, ROOT  # noqa: E402 - after BLENDER_USER_RESOURCES is set


def pytest_sessionfinish(session, exitstatus):
    shutil.rmtree(USER_DIR, ignore_errors=True)


@pytest.fixture(scope="session")
def extension_zip(tmp_path_factory) -> Path:
    """The linux-x64 extension zip with the wheels for this Python only, built and validated."""
    sys.path.insert(0, str(ROOT / "mk"))
    try:
        import build_extension
    finally:
        sys.path.pop(0)
    out = tmp_path_factory.mktemp("dist")
    (zip_path,) = build_extension.build(out, ["linux-x64"], [PYTHON])
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

