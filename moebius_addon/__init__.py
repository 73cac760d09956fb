"""Möbius energy relaxation of knotted curves (Reiter & Schumacher, *Sobolev Gradients for the
Möbius Energy*).

``moebius_addon.core`` is plain numpy + numba and never imports bpy. The Blender layer lives in
``moebius_addon.blender`` and is only imported by :func:`register` (Blender renames this package
to ``bl_ext.<repo>.moebius_addon``, so everything inside uses relative imports).
"""


def register() -> None:
    from . import blender

    blender.register()


def unregister() -> None:
    from . import blender

    blender.unregister()
