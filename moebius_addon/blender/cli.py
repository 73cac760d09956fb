"""``blender -c moebius ...``: relax a curve from the command line.

Examples::

    blender -c moebius --knot fhw --edges 600 --save out/fhw.blend --export out/fhw.abc
    blender -c moebius --open scene.blend --object Knot --edges 200 --save relaxed.blend
    blender -c moebius --knot 7_2 --method lbfgs --penalty 1e5 --save out/7_2.blend
    blender -c moebius --knot "Borromean rings" --identify --save out/borromean.blend
    blender -c moebius --braid "1 -2 1 -2" --save out/4_1.blend

Without ``--open`` the command starts from an empty scene (Blender's startup file would add its
Cube, Camera and Light to what is saved). It prints when numba compiles the kernels (the first
run after installing or updating), a line per iterate with ``--verbose``, and nothing but
errors with ``--quiet``. The same function is callable from Python as :func:`main` (it returns
the exit status).
"""

from __future__ import annotations

import argparse
import sys
import time

import bpy

from ..core.compilation.notice import compiling
from ..core.energies.choice import check_run_energy
from ..core.runs.engine import AUTO_TREE_FROM
from . import api, geometry, keyframes
from .labels import (
    DEFAULT_ENERGY,
    DEFAULT_MAX_ITERATIONS,
    DEFAULT_SETTLE,
    DEFAULT_TOLERANCE,
    ENERGY_PARAMETERS,
    THETA_TEXT,
)


def _thickness(text: str):
    """``--thickness``: 'bevel' or a radius >= 0."""
    if text == "bevel":
        return text
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not 'bevel' or a number: {text!r}") from None
    if not value >= 0.0 or value == float("inf"):
        raise argparse.ArgumentTypeError(f"a radius must be a finite number >= 0: {text!r}")
    return value

def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="blender -c moebius",
        description="Convert a curve (or add a catalogue knot or link, or one from a braid word "
                    "or PD code), relax it by the Möbius energy "
                    "flow, keyframe the flow, save and export it.",
    )
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--object", help="name of the curve or edge-loop mesh object to relax")
    src.add_argument("--knot", metavar="NAME",
                     help="add this catalogue knot or link instead: a table name (3_1, "
                          "10_161, 12n_888, L6a4{0,0}: every prime knot up to 12 crossings, "
                          "every prime link up to 11), a common name ('trefoil', 'Borromean "
                          "rings'), a mirror image (m3_1), or one of "
                          + ", ".join(key for key, *_ in api.SPECIAL_KNOTS))
    src.add_argument("--braid", metavar="WORD",
                     help="add the closure of this braid word instead, e.g. '1 -2 1 -2' "
                          "(σi as i, σi⁻¹ as -i, σi a positive crossing)")
    src.add_argument("--pd", metavar="CODE",
                     help="add the knot or link of this PD code instead, e.g. "
                          "'[[1,5,2,4],[3,1,4,6],[5,3,6,2]]' (KnotInfo, LinkInfo, KnotTheory's "
                          "PD[X[...]] or Knoodle's rows of five)")
    p.add_argument("--identify", action="store_true",
                   help="print which knot or link the curve is (before relaxing)")
    p.add_argument("--open", metavar="FILE.blend",
                   help="open this file first (without it: a new empty scene, not Blender's "
                        "startup file with its Cube, Camera and Light)")
    p.add_argument("--edges", type=int, default=None,
                   help="edges per component (converts the object; default: keep a converted "
                        "curve as it is, 100 otherwise; the catalogue default for --knot)")
    p.add_argument("--close-open", action="store_true", help="close open splines")
    p.add_argument("--keep-open", action="store_true",
                   help="keep open splines open (their ends where they are) and relax them as "
                        "open curves (exact engine)")
    p.add_argument("--seed", type=int, default=0,
                   help="seed of --knot random and of --restarts (default %(default)s)")
    p.add_argument("--pq", type=int, nargs=2, default=(2, 3), metavar=("P", "Q"),
                   help="p and q of --knot torus")
    p.add_argument("--energy", default=DEFAULT_ENERGY, choices=[e for e, *_ in api.ENERGIES],
                   help=f"the energy to minimize (default {DEFAULT_ENERGY}): "
                        + "; ".join(f"{e}: {text}" for e, _, text in api.ENERGIES))
    for record, option in ENERGY_PARAMETERS:  # --alpha, --beta, --stiffness: the records'
        p.add_argument(f"--{option.name.replace('_', '-')}", dest=option.name, type=float,
                       default=None,
                       help=f"{option.help} (default {option.default:g}"
                            + (f"; with --energy {record.name})" if option in record.parameters
                               else ")"))
    p.add_argument("--metric", default="hs", choices=[m for m, *_ in api.METRICS])
    p.add_argument("--method", default=api.DEFAULT_METHOD, choices=[m for m, *_ in api.METHODS],
                   help="optimizer (default auto: the implicit gradient for a knotted curve or "
                        "a link, the paper's explicit projected gradient for unknots); ncg, "
                        "lbfgs and nesterov hold the edge lengths by a penalty")
    p.add_argument("--engine", default=api.DEFAULT_ENGINE, choices=[e for e, *_ in api.ENGINES],
                   help="how the energy is evaluated (default auto: exact below "
                        f"{AUTO_TREE_FROM} edges, the Barnes-Hut tree from there on)")
    p.add_argument("--theta", type=float, default=None,
                   help="admissibility of the tree engine in (0, 2) (default: the energy's "
                        f"own, {THETA_TEXT}; smaller is more accurate and slower)")
    p.add_argument("--penalty", type=float, default=None, metavar="ALPHA",
                   help="penalty weight of ncg, lbfgs and nesterov (default "
                        f"{api.DEFAULT_PENALTY:g}; larger keeps edge lengths closer)")
    p.add_argument("--max-iterations", "--max-iter", dest="max_iterations", type=int,
                   default=DEFAULT_MAX_ITERATIONS, metavar="N",
                   help="stop after N accepted iterates (default %(default)s)")
    p.add_argument("--tolerance", "--tol", dest="tolerance", type=float,
                   default=DEFAULT_TOLERANCE, metavar="TOL",
                   help="stop once the gradient norm in the metric is below TOL (default "
                        "%(default)g)")
    p.add_argument("--settle", type=float, default=100 * DEFAULT_SETTLE, metavar="PERCENT",
                   help="stop once no point moves more than PERCENT of an edge in each of 5 "
                        "iterations in a row (default %(default)g; 0: never)")
    p.add_argument("--thickness", type=_thickness, default=0.0, metavar="R",
                   help="tube radius kept between strands and from obstacles, in the curve's "
                        "units, or 'bevel' (the curve's bevel depth); default 0: centre lines "
                        "only")
    p.add_argument("--push-apart", action="store_true",
                   help="with --thickness: a start whose tubes meet is not refused; the tubes "
                        "thicken as the flow pushes the strands apart")
    p.add_argument("--no-refine", dest="refine", action="store_false",
                   help="do not add edges: refuse a start too coarse for its shape and stop "
                        "where strands jam, as before refinement existed (default: refine)")
    p.add_argument("--max-edges", type=int, default=None, metavar="N",
                   help="most edges refinement may reach (default: 4 times the start's, at "
                        "least 2000, within what the metric and engine can run)")
    p.add_argument("--restarts", type=int, default=0, metavar="K",
                   help="after converging, relax K small random nudges of the result and keep "
                        "the lowest energy (projected gradient methods; default %(default)s)")
    scene = p.add_argument_group("scene constraints (cables, packing)")
    scene.add_argument("--obstacles", metavar="NAME", action="append", default=[],
                       help="a collection, or a mesh object, whose meshes the curve never "
                       "crosses (repeat for more)")
    scene.add_argument("--container", metavar="OBJECT",
                       help="a closed mesh object the curve stays inside")
    scene.add_argument("--obstacle-weight", type=float, default=None, metavar="W",
                       help="weight of the obstacles' and the container's repulsion (default 1)")
    scene.add_argument("--pin-ends", action="store_true",
                       help="pin the two end points of every open spline (cables)")
    scene.add_argument("--length-target", type=float, default=None, metavar="L",
                       help="grow the curve's total length to L (object units) during the run")
    scene.add_argument("--length-growth", type=float, default=None, metavar="RATE",
                       help="relative growth per iteration with --length-target (default "
                       "0.01: 1 %%)")
    p.add_argument("--frame-start", type=int, default=1,
                   help="frame of the start shape (default %(default)s)")
    p.add_argument("--stride", type=int, default=1,
                   help="keyframe every STRIDE-th iterate (default %(default)s)")
    p.add_argument("--no-relax", action="store_true", help="only convert / add")
    p.add_argument("--save", metavar="OUT.blend", help="save the result here")
    p.add_argument("--export", metavar="OUT.abc|OUT.usd", action="append", default=[],
                   help="export the keyframed curve (Alembic or USD; may repeat)")
    talk = p.add_mutually_exclusive_group()
    talk.add_argument("-v", "--verbose", action="store_true",
                      help="print a line per iterate (iteration, energy, seconds)")
    talk.add_argument("-q", "--quiet", action="store_true",
                      help="print nothing but errors and warnings")
    return p


def _energy_options(args) -> dict:
    """``energy=`` and the energy options given on the command line (``--alpha``,
    ``--stiffness``, ...: the core's records), as ``relax_object`` takes them."""
    out = {"energy": args.energy}
    out.update((p.name, getattr(args, p.name)) for _, p in ENERGY_PARAMETERS
               if getattr(args, p.name) is not None)
    return out


def _is_converted(obj, allow_open: bool = False) -> bool:
    try:
        geometry.curve_polygons(obj, allow_open=allow_open)
    except ValueError:
        return False
    return True


def _say(line: str) -> None:
    print(f"moebius: {line}", flush=True)


def _scene_options(args) -> dict:
    """``relax_object``'s obstacles, container, weight and growth options from the command
    line, the named collections and objects looked up in the opened file; ValueError naming
    one that is not there."""
    def mesh_object(name: str, role: str):
        o = bpy.data.objects.get(name)
        if o is None:
            names = ", ".join(x.name for x in bpy.data.objects if x.type == "MESH") or "none"
            raise ValueError(f"--{role} {name!r}: no such object (mesh objects: {names})")
        return o

    out = {}
    if args.obstacles:
        if len(args.obstacles) == 1 and args.obstacles[0] in bpy.data.collections:
            out["obstacles"] = bpy.data.collections[args.obstacles[0]]
        else:
            out["obstacles"] = [mesh_object(n, "obstacles") for n in args.obstacles]
    if args.container:
        out["container"] = mesh_object(args.container, "container")
    if args.obstacle_weight is not None:
        out["obstacle_weight"] = args.obstacle_weight
    if args.length_target is not None:
        out["length_target"] = args.length_target
    if args.length_growth is not None:
        out["length_growth"] = args.length_growth
    return out


def _pins(obj, args) -> dict:
    """``pinned=``: the two end points of every open spline of ``obj`` with ``--pin-ends``."""
    if not args.pin_ends:
        return {}
    splines = obj.data.splines
    if all(s.use_cyclic_u for s in splines):
        raise ValueError(f"--pin-ends: '{obj.name}' has no open spline (use --keep-open to keep "
                         "open splines open)")
    per = [[] if s.use_cyclic_u else [0, len(s.points) - 1] for s in splines]
    return {"pinned": per[0] if len(per) == 1 else per}


def _run(args, run: dict, notation: str | None):
    """Open or empty the scene, add or convert, identify, relax, save and export (the options
    were checked by :func:`main`); returns the curve object."""
    say = (lambda line: None) if args.quiet else _say
    if args.open:
        bpy.ops.wm.open_mainfile(filepath=args.open)
    else:  # not Blender's startup file: its Cube, Camera and Light would be saved too
        bpy.ops.wm.read_homefile(use_empty=True)
    scene = _scene_options(args)  # named objects checked before anything is added
    if args.knot:
        obj = api.add_knot(args.knot, args.edges, p=args.pq[0], q=args.pq[1],
                           seed=args.seed, **run)
    elif notation:
        obj = api.add_notation(notation, args.edges, **run)
    else:
        obj = bpy.data.objects.get(args.object)
        if obj is None:
            names = ", ".join(o.name for o in bpy.data.objects) or "none"
            raise ValueError(f"no object '{args.object}' (objects: {names})")
        if args.edges is not None or not _is_converted(obj, args.keep_open):
            obj = api.convert_object(obj, edges=args.edges or 100,
                                     close_open=args.close_open,
                                     keep_open=args.keep_open, **run)
    energy = obj.get(api.ENERGY_PROP)  # a poly curve drawn by hand has none stored
    if energy is None:
        energy = api.energy(geometry.curve_polygons(obj, allow_open=True),
                            geometry.curve_closed(obj))
    say(f"'{obj.name}', {sum(len(s.points) for s in obj.data.splines)} edges, "
        f"energy {energy:.6g}")
    if args.identify:
        found = api.identify_object(obj)
        say(f"'{obj.name}' is {found.message}" if found.names else
            f"'{obj.name}': {found.message}")
    if not args.no_relax:
        t0 = time.perf_counter()
        start = geometry.curve_polygons(obj, allow_open=True)
        is_open = not all(geometry.curve_closed(obj))
        if args.method == api.AUTO_METHOD and (is_open or args.length_target is not None):
            # the explicit method: the one that grows, and the one for open curves
            method, why = api.EXPLICIT_METHOD, ("an open curve" if is_open else "length growth")
        else:
            method, why = api.choose_method(args.method, start)
        result = api.relax_object(obj, **_energy_options(args),
                                  metric=args.metric, method=method,
                                  penalty=args.penalty, engine=args.engine,
                                  theta=args.theta, max_iterations=args.max_iterations,
                                  tolerance=args.tolerance, settle=args.settle / 100.0,
                                  thickness=args.thickness, push_apart=args.push_apart,
                                  frame_start=args.frame_start,
                                  keyframe_stride=args.stride, refine=args.refine,
                                  max_edges=args.max_edges, restarts=args.restarts,
                                  seed=args.seed, progress=_say if args.verbose else False,
                                  **scene, **_pins(obj, args))
        frames = keyframes.keyed_frames(obj)
        say(f"{method}{f' ({why})' if why else ''}, "
            f"{'' if result.energy == DEFAULT_ENERGY else result.energy + ' energy, '}"
            f"{result.stats['engine']} engine, {result.nit} iterations in "
            f"{time.perf_counter() - t0:.2f} s, energy "
            f"{result.history['energy'][0]:.6g} -> {float(result.fun):.6g}, keyed frames "
            f"{frames[0]:g}-{frames[-1]:g} ({result.message})")
        for r in getattr(result, "refinements", []):
            say(f"refined {r['edges_before']} -> {r['edges_after']} edges at iteration "
                f"{r['iteration']} ({r['reason']})")
        kept, words = ((None, "an open curve has no knot type") if is_open
                       else api.type_kept(start, api.object_curves(obj)))
        if kept is False:
            print(f"moebius: {words}", file=sys.stderr)
        else:
            say(words)
    if args.save:
        bpy.ops.wm.save_as_mainfile(filepath=args.save)
        say(f"saved {args.save}")
    for path in args.export:
        api.export_flow(obj, path)
        say(f"exported {path}")
    return obj


def main(argv: list[str]) -> int:
    """Run the command with ``argv`` (the arguments after ``-c moebius``); return 0 or 1."""
    try:
        args = _parser().parse_args(argv)
    except SystemExit as exit_:
        return int(exit_.code or 0)
    try:
        # every option is checked before anything is added, converted or relaxed
        api.check_relax_options(args.max_iterations, args.tolerance, args.stride,
                                args.frame_start, args.method, args.penalty, args.engine,
                                args.theta)
        check_run_energy(**_energy_options(args))  # refused by name
        if args.max_edges is not None and args.max_edges < 1:
            raise ValueError(f"--max-edges must be a positive whole number, got "
                             f"{args.max_edges}")
        if args.length_growth is not None and args.length_target is None:
            raise ValueError("--length-growth needs --length-target (the length to grow to)")
        if args.restarts < 0:
            raise ValueError(f"--restarts must be 0 or more, got {args.restarts}")
        if args.restarts and args.method in api.PENALTY_METHODS:
            raise ValueError(f"--restarts needs a projected gradient method (they keep the "
                             f"edge lengths exactly); --method {args.method} holds them by a "
                             f"penalty")
        run = dict(metric=args.metric, method=args.method, engine=args.engine)
        if args.knot:
            api.check_knot(args.knot, args.edges, **run)
        notation = args.braid or args.pd
        if notation:
            from ..core.topology import notation as parse

            if args.pd and not parse.is_pd(args.pd):
                raise ValueError(f"--pd {args.pd!r} is not a PD code: write it as "
                                 "[[1,5,2,4],[3,1,4,6],[5,3,6,2]] or PD[X[1,5,2,4], ...]")
            if args.braid and parse.is_pd(args.braid):
                raise ValueError(f"--braid {args.braid!r} looks like a PD code; use --pd")
            parse.parse_notation(notation)  # refused before anything is opened
            if args.edges:
                api.check_edge_count(args.edges, **run)
        for path in args.export:
            api.export_suffix(path)
        with compiling(None if args.quiet else _say):
            _run(args, run, notation)
    except (ValueError, RuntimeError, OSError) as err:
        print(f"moebius: error: {err}", file=sys.stderr)
        return 1
    return 0


_handle = None


def register() -> None:
    global _handle
    if hasattr(bpy.utils, "register_cli_command"):  # Blender 4.2+
        _handle = bpy.utils.register_cli_command("moebius", main)
    else:  # a legacy add-on in Blender 3.4-4.1
        print("moebius_addon: the `blender -c moebius` command needs Blender 4.2+; here call "
              "main([...]) or the scripting API from `blender -b --python script.py`")


def unregister() -> None:
    global _handle
    if _handle is not None:
        bpy.utils.unregister_cli_command(_handle)
        _handle = None
