"""Möbius energy relaxation of knotted curves (Reiter & Schumacher, *Sobolev Gradients for the
Möbius Energy*).

``moebius_addon.core`` is plain numpy + numba and never imports bpy. The Blender layer lives in
``moebius_addon.blender`` and is only imported by :func:`register` (Blender renames this package
to ``bl_ext.<repo>.moebius_addon``, so everything inside uses relative imports).
"""

import os
import sys


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
    except ValueError:  # not installed as an extension (e.g. a legacy add-on checkout)
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
