"""Möbius energy relaxation of knotted curves (Reiter & Schumacher, *Sobolev Gradients for the
Möbius Energy*).

``moebius_addon.core`` is plain numpy + numba and never imports bpy. The Blender layer lives in
``moebius_addon.blender`` and is only imported by :func:`register` (Blender renames this package
to ``bl_ext.<repo>.moebius_addon``, so everything inside uses relative imports).
"""

import os
import sys

# Read only when installed the classic way (Preferences ▸ Add-ons ▸ Install… with a zip of this
# folder) in Blender 3.4–4.1; Blender 4.2+ installs the extension and uses blender_manifest.toml
# instead (it drops this dict). See docs/ui-testing.md.
bl_info = {
    "name": "Möbius Energy Relaxation",
    "author": "moebius_addon developers",
    "version": (0, 1, 0),
    "blender": (3, 4, 0),
    "location": "View3D ▸ Sidebar ▸ Möbius; Add ▸ Curve ▸ Knot",
    "description": "Untangle knotted curves by Sobolev flow of the Möbius energy",
    "category": "Add Curve",
}


def _use_extension_numba_cache() -> None:
    """Cache numba's compiled kernels in the extension's user directory.

    The extension directory itself may be read-only and is replaced on every update; the user
    directory (``bpy.utils.extension_path_user``) survives, so only the first run compiles.
    Must run before the core (and hence numba) is first imported.
    """
    import bpy

    if os.environ.get("NUMBA_CACHE_DIR"):
        return
    try:
        path = bpy.utils.extension_path_user(__package__, path="numba_cache", create=True)
    except (AttributeError, ValueError):  # Blender < 4.2, or installed as a legacy add-on
        print("moebius_addon: legacy add-on, so numba caches its kernels next to the add-on's "
              "files (set NUMBA_CACHE_DIR to choose another directory)")
        return
    os.environ["NUMBA_CACHE_DIR"] = path
    config = sys.modules.get("numba.core.config")
    if config is not None:  # numba already imported by someone else: it read the env already
        config.CACHE_DIR = path


def register() -> None:
    _use_extension_numba_cache()
    from . import blender

    blender.register()


def unregister() -> None:
    from . import blender

    blender.unregister()
