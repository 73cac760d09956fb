"""Fixtures for tests with the real ``bpy`` module (Blender as a Python module, headless: 5.0 in
the main venv, 4.2, 4.5 and 5.2 in the venvs of mk/lines.mk).

Blender reads ``BLENDER_USER_RESOURCES`` when ``bpy`` is first imported, so it is pointed at a
throw-away directory here, at collection time, before anything imports ``bpy``. The session
takes the extension zip for this platform from a repository built with ``blender_ext.py``
(mk/build_extension.py; ``make test`` builds one for every line) and installs it with
``bpy.ops.extensions.package_install_files`` as a user would; every test then drives the
installed copy (``bl_ext.user_default.moebius_addon``) through ``bpy.ops``.
"""

from __future__ import annotations

import importlib
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

# The venv of a Blender line (mk/lines.mk) holds bpy, numpy and pytest only: numba comes with
# the extension, as in a user's Blender, so every test here drives the installed zip.
from bpy_helpers import (  # noqa: E402 - after BLENDER_USER_RESOURCES is set
    EXT_MODULE,
    PYTHON,
    ROOT,
    build_extension,
)


def pytest_sessionfinish(session, exitstatus):
    shutil.rmtree(USER_DIR, ignore_errors=True)


@pytest.fixture(scope="session")
def repo_index(tmp_path_factory) -> Path:
    """``index.json`` of a static repository with the linux-x64 zip.

    ``$MOEBIUS_TEST_REPO`` when set (``make test``: built by the main venv as ``make repo``
    builds what users get, with the wheels of every Python), else a repository built here with
    this venv's ``blender_ext.py`` and the wheels of this Python only.
    """
    if os.environ.get("MOEBIUS_TEST_REPO"):
        index = ROOT / os.environ["MOEBIUS_TEST_REPO"] / "index.json"
        if not index.exists():
            raise RuntimeError(f"{index} is missing; `make test` builds it")
        return index
    return build_extension().build_repo(tmp_path_factory.mktemp("repo"), ["linux-x64"], [PYTHON])


@pytest.fixture(scope="session")
def extension_zip(repo_index) -> Path:
    """The linux-x64 extension zip of :func:`repo_index`, built and validated."""
    (zip_path,) = repo_index.parent.glob("*-linux_x64.zip")
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

