"""Two energies side by side: a few knots of the table relaxed by the Möbius and by the
tangent-point energy from the same start, rendered as one contact sheet.

For each knot the catalogue curve (``core.knots.named``) is resampled to ``--edges`` edges and
relaxed once per energy (``projected_gradient_implicit``, engine "auto"). Each result is
measured by both energies, identified (the knot type must be kept) and by its evenness: the
smallest distance between vertices more than ``--gap`` edges apart along the curve over the mean
edge length (a tight clasp makes it small). Results are cached in ``out/energy_compare/``
(``--rerun`` relaxes again); the tiles are Workbench renders in the style of
``bench/energy_gallery.py`` (orthographic, one view direction, each curve framed); the sheet
goes to ``docs/img/energies_compare.png`` and, with ``--doc``, its table to the section "Two
energies: Möbius and tangent-point" at the end of ``docs/gallery.md``::

    .venv/bin/python bench/energy_compare_gallery.py --doc
"""

from __future__ import annotations

import argparse
import datetime
import os
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

import bpy  # noqa: E402  (demo_blender sets a throw-away Blender user directory first)
import numpy as np  # noqa: E402
from demo_blender import frame_camera, render, setup_render  # noqa: E402

from moebius_addon import core  # noqa: E402

KNOTS = ["5_2", "7_2", "7_4", "8_1", "9_2", "9_4"]
ENERGIES = [("moebius", "Möbius", (0.13, 0.40, 0.75, 1.0)),
            ("tangent_point", "tangent-point (2, 4)", (0.80, 0.33, 0.10, 1.0))]
OUT = ROOT / "out" / "energy_compare"
SHEET = ROOT / "docs" / "img" / "energies_compare.png"
DOC = ROOT / "docs" / "gallery.md"
SECTION = "## Two energies: Möbius and tangent-point"
DIRECTION = (0.15, -0.25, 1.0)  # bench/energy_gallery.py's view


def evenness(P: np.ndarray, gap: int = 5) -> float:
    """Smallest distance between vertices more than ``gap`` edges apart (cyclically), over the
    mean edge length: about the tube radius a clasp leaves, in edges."""
    n = len(P)
    i = np.arange(n)
    k = np.abs(i[:, None] - i[None, :])
    far = np.minimum(k, n - k) > gap
    d = np.linalg.norm(P[:, None, :] - P[None, :, :], axis=2)
    mean_edge = float(np.linalg.norm(np.roll(P, -1, axis=0) - P, axis=1).mean())
    return float(d[far].min() / mean_edge)


def run(name: str, energy: str, args) -> dict:
    """Relax ``name`` by ``energy`` (or read the cached run) and measure the result."""
    tp = {"alpha": 2.0, "beta": args.beta}
    own = tp if energy == "tangent_point" else {}
    path = OUT / f"{name}_{energy}{_tag(args, energy)}_{args.edges}.npz"
    if path.exists() and not args.rerun:
        with np.load(path) as f:
            r = {k: f[k].item() if f[k].ndim == 0 else f[k] for k in f.files}
        r.setdefault("day", datetime.date.fromtimestamp(path.stat().st_mtime).isoformat())
    else:
        P = core.resample(core.knots.named(name), args.edges)
        load = os.getloadavg()[0]
        t0 = time.perf_counter()
        res = core.relax(P, energy=energy, **own, method="projected_gradient_implicit", tol=1e-4,
                         max_iter=args.max_iter, max_seconds=args.max_seconds, engine="auto")
        r = {"x": np.asarray(res.x), "start": P, "nit": res.nit, "load": load,
             "day": datetime.date.today().isoformat(),
             "seconds": time.perf_counter() - t0, "status": str(res.status.name),
             "message": res.message, "label": res.energy}
        OUT.mkdir(parents=True, exist_ok=True)
        np.savez(path, **r)
    x = r["x"]
    r["E_moebius"] = core.energy(x, energy="moebius")
    r["E_tp"] = core.energy(x, energy="tangent_point", **tp)
    r["names"] = core.identify(x).names
    r["kept"] = name in r["names"] or f"m{name}" in r["names"]
    r["even"] = evenness(x, args.gap)
    # a refined run ends with shorter edges: the same measure in the start's edges (pairs more
    # than `gap` start edges apart), to compare across rows
    k = len(x) / args.edges
    r["even_start_edges"] = evenness(x, round(args.gap * k)) / k
    r["even_start"] = evenness(r["start"], args.gap)
    return r


def _tag(args, energy: str = "tangent_point") -> str:
    """File name tag of the tangent-point exponents other than the default (2, 4)."""
    return f"_beta{args.beta:g}" if energy == "tangent_point" and args.beta != 4.0 else ""


def tile(name: str, P: np.ndarray, color, path: Path, resolution: int) -> None:
    bpy.ops.wm.read_homefile(use_empty=True)
    scene = bpy.context.scene
    setup_render(scene, resolution)
    curve = bpy.data.curves.new(name, "CURVE")
    curve.dimensions = "3D"
    spline = curve.splines.new("POLY")
    spline.points.add(len(P) - 1)
    spline.points.foreach_set("co", np.column_stack([P, np.ones(len(P))]).ravel())
    spline.use_cyclic_u = True
    curve.bevel_depth = 0.025 * float(np.ptp(P, axis=0).max())
    curve.bevel_resolution = 3
    obj = bpy.data.objects.new(name, curve)
    obj.color = color
    scene.collection.objects.link(obj)
    frame_camera(scene, P, direction=DIRECTION)
    render(scene, path)


def labels(args) -> list[tuple[str, str, tuple]]:
    """``ENERGIES`` with the tangent-point exponents of this run in its label."""
    return [(e, f"tangent-point (2, {args.beta:g})" if e == "tangent_point" else label, c)
            for e, label, c in ENERGIES]


def sheet(knots: list[str], results: dict, path: Path, args) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cols = len(knots)
    fig, axes = plt.subplots(2, cols, figsize=(2.1 * cols + 0.5, 5.4), squeeze=False)
    for row, (energy, label, _) in enumerate(labels(args)):
        for col, name in enumerate(knots):
            r = results[name, energy]
            ax = axes[row, col]
            ax.axis("off")
            ax.imshow(plt.imread(OUT / f"{name}_{energy}{_tag(args, energy)}.png"))
            kept = "" if r["kept"] else "  TYPE CHANGED"
            ax.set_title(f"{name}  ({r['nit']} it, {len(r['x'])} edges){kept}\n"
                         f"E_M {r['E_moebius']:.1f}   E_TP {r['E_tp']:.1f}\n"
                         f"min gap {r['even_start_edges']:.2f} start edges", fontsize=7.5)
        fig.text(0.005, 0.75 - 0.5 * row, label, rotation=90, va="center", ha="left",
                 fontsize=10, fontweight="bold")
    fig.tight_layout(rect=(0.03, 0, 1, 0.985), pad=0.4)
    fig.savefig(path, dpi=100)
    plt.close(fig)


def table(knots: list[str], results: dict, args) -> list[str]:
    edges = args.edges
    rows = ["| knot | energy minimized | edges | iterations | seconds | stop | Möbius energy | "
            "tangent-point energy | min gap / mean edge | min gap / start edge | type kept |",
            "|---|---|--:|--:|--:|---|--:|--:|--:|--:|---|"]
    for name in knots:
        for energy, label, _ in labels(args):
            r = results[name, energy]
            n = len(r["x"])
            grown = f"{edges} → {n}" if n != edges else f"{n}"
            rows.append(f"| {name} | {label} | {grown} | {r['nit']} | {r['seconds']:.0f} | "
                        f"{r['status'].lower().replace('_', ' ')} | "
                        f"{r['E_moebius']:.2f} | {r['E_tp']:.2f} | {r['even']:.2f} | "
                        f"{r['even_start_edges']:.2f} | "
                        f"{'yes' if r['kept'] else 'no: ' + ', '.join(r['names'])} |")
    return rows


def write_doc(rows: list[str], knots: list[str], results: dict, args) -> None:
    """The section "Two energies" at the end of docs/gallery.md (``--beta 4``, replacing the
    section), or its subsection of other exponents (after it, replacing that subsection)."""
    loads = [results[k, e].get("load") for k in knots for e, _, _ in ENERGIES]
    loads = [x for x in loads if x is not None]
    days = sorted({str(results[k, e]["day"]) for k in knots for e, _, _ in ENERGIES})
    stamp = (f"{', '.join(days)}; {os.cpu_count()} cores shared, NUMBA_NUM_THREADS="
             f"{os.environ.get('NUMBA_NUM_THREADS', 'unset')}, "
             + (f"load average {min(loads):.1f}–{max(loads):.1f} at the runs' starts"
                if loads else "load average not recorded")
             + "; seconds are wall time")
    starts = ", ".join(f"{k} {results[k, 'moebius']['even_start']:.2f}" for k in knots)
    command = "`.venv/bin/python bench/energy_compare_gallery.py --doc"
    command += f" --beta {args.beta:g}`" if args.beta != 4.0 else "`"
    sheet_file = f"energies_compare{_tag(args)}.png"
    if args.beta == 4.0:
        head = SECTION
        intro = [
            "The same start relaxed by each energy: the catalogue curve of each knot "
            f"(`core.knots.named`) resampled to {args.edges} edges, then "
            "`core.relax(P, energy=..., method=\"projected_gradient_implicit\", tol=1e-4, "
            f"max_iter={args.max_iter}, max_seconds={args.max_seconds:g})` (engine \"auto\", "
            "refinement on, the defaults) once with `energy=\"moebius\"` (top row) and once "
            "with `energy=\"tangent_point\"` (α = 2, β = 4, the defaults; bottom row). Each "
            "result is measured by both energies (`core.energy`, default exponents), identified "
            "(`core.identify`), and by its *min gap*: the smallest distance between vertices "
            f"more than {args.gap} edges apart along the curve over the mean edge length, and "
            f"the same in the start's edges (pairs more than {args.gap} start edges apart; a "
            "refined run ends with shorter edges, so only this column compares across rows). "
            "A tight clasp makes it small. Rendered by Workbench headless as the gallery "
            "above (same view direction, each curve framed on its own).", ""]
    else:
        head = f"### Steeper exponents: tangent-point (2, {args.beta:g})"
        intro = [
            f"The same starts and settings with `energy=\"tangent_point\", alpha=2, "
            f"beta={args.beta:g}` (bottom row; not scale-invariant: at fixed length it "
            "pushes strands apart by a power of their distance, where β = 4 = α + 2 has only "
            "a logarithm, as Möbius). The Möbius row is the one above; the tangent-point "
            f"column is the (2, {args.beta:g}) energy of each result.", ""]
    lines = [head, "", *intro,
             f"![The same knots relaxed by the Möbius energy (top) and the tangent-point energy "
             f"(2, {args.beta:g}) (bottom)](img/{sheet_file})", "",
             *rows, "",
             f"Min gap of the common starts (in their {args.edges} edges): {starts}.", "",
             f"Made by {command} ({stamp}).", ""]
    text = DOC.read_text()
    if head in text:
        text = text[:text.index(head)]
    elif args.beta != 4.0 and SECTION not in text:
        raise SystemExit("write the section of the default exponents first (without --beta)")
    DOC.write_text(text.rstrip("\n") + "\n\n" + "\n".join(lines))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--knots", nargs="+", default=KNOTS)
    ap.add_argument("--edges", type=int, default=300)
    ap.add_argument("--max-iter", type=int, default=2000)
    ap.add_argument("--max-seconds", type=float, default=120.0)
    ap.add_argument("--gap", type=int, default=5)
    ap.add_argument("--beta", type=float, default=4.0,
                    help="tangent-point exponent beta (alpha = 2); run --doc without it first")
    ap.add_argument("--resolution", type=int, default=240)
    ap.add_argument("--rerun", action="store_true", help="relax again instead of the cache")
    ap.add_argument("--no-render", action="store_true")
    ap.add_argument("--doc", action="store_true", help="write the section of docs/gallery.md")
    args = ap.parse_args()
    results = {}
    print(f"{'knot':6} {'energy':14} {'edges':>5} {'it':>5} {'s':>6} {'E_moebius':>10} "
          f"{'E_tp':>10} {'min gap':>7} kept  status", flush=True)
    for name in args.knots:
        for energy, _, _ in ENERGIES:
            r = results[name, energy] = run(name, energy, args)
            print(f"{name:6} {energy:14} {len(r['x']):5d} {r['nit']:5d} {r['seconds']:6.1f} "
                  f"{r['E_moebius']:10.3f} {r['E_tp']:10.3f} {r['even']:7.2f} "
                  f"({r['even_start_edges']:.2f} start edges) "
                  f"{'yes' if r['kept'] else 'NO ' + ','.join(r['names'])}  {r['status']} "
                  f"(start gap {r['even_start']:.2f})", flush=True)
    rows = table(args.knots, results, args)
    path = SHEET.with_name(f"energies_compare{_tag(args)}.png")
    print("\n".join(rows))
    if not args.no_render:
        for name in args.knots:
            for energy, _, color in ENERGIES:
                tile(name, results[name, energy]["x"], color,
                     OUT / f"{name}_{energy}{_tag(args, energy)}.png", args.resolution)
        sheet(args.knots, results, path, args)
        print(f"{path}: {path.stat().st_size} bytes")
    if args.doc:
        write_doc(rows, args.knots, results, args)
        print(f"wrote the section of {DOC}")


if __name__ == "__main__":
    main()
