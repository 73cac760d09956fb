"""Relax a curve without the user interface and save/export the keyframed flow.

Inside Blender (the extension installed and enabled)::

    blender --background scene.blend --python docs/examples/relax_headless.py -- \
        --object Knot --edges 200 --out relaxed.blend --abc relaxed.abc

Without an ``--object`` a catalogue knot is added (``--knot``, default the trefoil ``3_1``).
The same script runs with the ``bpy`` module from PyPI and this repository checkout::

    .venv/bin/python docs/examples/relax_headless.py --knot 3_1 --out out/trefoil.blend
"""

import argparse
import sys
import time
from pathlib import Path

import bpy


def moebius_api():
    """The extension's scripting API: the installed extension, else this checkout."""
    try:
        from bl_ext.user_default.moebius_addon import blender
    except ImportError:
        sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
        import moebius_addon

        if not hasattr(bpy.types.Scene, "moebius"):
            moebius_addon.register()
        from moebius_addon import blender
    return blender


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--object", help="curve or edge-loop mesh in the open file")
    parser.add_argument("--knot", default="3_1", help="catalogue knot to add otherwise")
    parser.add_argument("--edges", type=int, default=None, help="edges per component")
    parser.add_argument("--iterations", type=int, default=100)
    parser.add_argument("--metric", default="hs")
    parser.add_argument("--out", default="relaxed.blend")
    parser.add_argument("--abc", default=None, help="also export an Alembic cache here")
    args = parser.parse_args(argv)

    moebius = moebius_api()
    if args.object:
        obj = moebius.convert_object(bpy.data.objects[args.object], edges=args.edges or 100)
    else:
        obj = moebius.add_knot(args.knot, args.edges)
    t0 = time.perf_counter()
    result = moebius.relax_object(obj, metric=args.metric, max_iterations=args.iterations)
    seconds = time.perf_counter() - t0
    energy = result.history["energy"]
    print(f"{obj.name}: {result.nit} iterations in {seconds:.1f} s, "
          f"energy {energy[0]:.4f} -> {energy[-1]:.4f} ({result.message})")
    Path(args.out).resolve().parent.mkdir(parents=True, exist_ok=True)
    bpy.ops.wm.save_as_mainfile(filepath=str(Path(args.out).resolve()))
    if args.abc:
        moebius.export_flow(obj, args.abc)
    return 0


if __name__ == "__main__":
    # Blender passes its own arguments; ours follow "--".
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]
    sys.exit(main(argv))
