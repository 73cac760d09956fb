"""Gallery of the relaxed knots of the energy table: Workbench renders, headless, as contact
sheets by crossing number, and ``docs/gallery.md``.

Reads ``docs/data/energy_table.csv`` and the relaxed polygons at ``n2`` edges packed in
``docs/data/energy_table_curves.npz`` (``bench/energy_table.py --pack``; else
``out/energy_table/<name>_<n2>.obj``); renders each as a bevelled curve (orthographic camera,
the same direction for all) into ``out/gallery/``; composes the sheets into
``docs/img/gallery_<group>.png`` and writes ``docs/gallery.md``::

    .venv/bin/python bench/energy_gallery.py
"""

from __future__ import annotations

import argparse
import csv
import os
import shutil
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if "BLENDER_USER_RESOURCES" not in os.environ:  # never the user's own preferences
    os.environ["BLENDER_USER_RESOURCES"] = tempfile.mkdtemp(prefix="moebius-gallery-user-")
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

import bpy  # noqa: E402
import numpy as np  # noqa: E402
from demo_blender import frame_camera, render, setup_render  # noqa: E402

from moebius_addon.core.geometry import objio  # noqa: E402

CSV = ROOT / "docs" / "data" / "energy_table.csv"
CURVES = ROOT / "docs" / "data" / "energy_table_curves.npz"
OBJ = ROOT / "out" / "energy_table"
TILES = ROOT / "out" / "gallery"
IMG = ROOT / "docs" / "img"
DOC = ROOT / "docs" / "gallery.md"
GROUPS = [("up to 8 crossings", lambda c: c <= 8, "gallery_0-8.png"),
          ("9 crossings", lambda c: c == 9, "gallery_9.png"),
          ("10 crossings (10_1 … 10_83)", lambda c: c == 10, "gallery_10a.png"),
          ("10 crossings (10_84 … 10_165)", lambda c: c == 10, "gallery_10b.png")]


def relaxed_curve(name: str, n: int) -> np.ndarray:
    """The relaxed polygon of ``name`` at ``n`` edges: packed in the docs, or the run's OBJ."""
    if CURVES.exists():
        with np.load(CURVES) as packed:
            if name in packed.files and len(packed[name]) == n:
                return packed[name].astype(np.float64)
    return np.concatenate(objio.read_obj(OBJ / f"{name}_{n}.obj"))


def tile(name: str, n: int, path: Path, resolution: int) -> None:
    bpy.ops.wm.read_homefile(use_empty=True)
    scene = bpy.context.scene
    setup_render(scene, resolution)
    P = relaxed_curve(name, n)
    curve = bpy.data.curves.new(name, "CURVE")
    curve.dimensions = "3D"
    spline = curve.splines.new("POLY")
    spline.points.add(len(P) - 1)
    spline.points.foreach_set("co", np.column_stack([P, np.ones(len(P))]).ravel())
    spline.use_cyclic_u = True
    size = float(np.ptp(P, axis=0).max())
    curve.bevel_depth = 0.025 * size
    curve.bevel_resolution = 3
    obj = bpy.data.objects.new(name, curve)
    obj.color = (0.13, 0.40, 0.75, 1.0)
    scene.collection.objects.link(obj)
    frame_camera(scene, P, direction=(0.15, -0.25, 1.0))
    render(scene, path)


def sheet(images: list[Path], labels: list[str], path: Path, columns: int = 8) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = -(-len(images) // columns)
    fig, axes = plt.subplots(rows, columns, figsize=(1.5 * columns, 1.65 * rows),
                             squeeze=False)
    for ax in np.ravel(axes):
        ax.axis("off")
    for ax, img, label in zip(np.ravel(axes), images, labels, strict=False):
        ax.imshow(plt.imread(img))
        ax.set_title(label, fontsize=7)
    fig.tight_layout(pad=0.3)
    fig.savefig(path, dpi=90)
    plt.close(fig)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--resolution", type=int, default=160)
    args = ap.parse_args()
    with CSV.open() as f:
        rows = [r for r in csv.DictReader(f)]
    TILES.mkdir(parents=True, exist_ok=True)
    done = []
    for r in rows:
        path = TILES / f"{r['name']}.png"
        if not path.exists():
            tile(r["name"], int(r["n2"]), path, args.resolution)
        done.append((r, path))
    tens = [d for d in done if int(d[0]["crossings"]) == 10]
    half = (len(tens) + 1) // 2
    sheets = []
    for title, keep, file in GROUPS:
        if file == "gallery_10a.png":
            part = tens[:half]
        elif file == "gallery_10b.png":
            part = tens[half:]
        else:
            part = [d for d in done if keep(int(d[0]["crossings"]))]
        if not part:
            continue
        if file.startswith("gallery_10"):
            title = f"10 crossings ({part[0][0]['name']} … {part[-1][0]['name']})"
        sheet([p for _, p in part],
              [f"{r['name']}  {float(r['extrapolated']):.2f}" for r, _ in part], IMG / file)
        sheets.append((title, file, len(part)))
        print(f"{IMG / file}: {len(part)} knots, {(IMG / file).stat().st_size} bytes")
    write_doc(rows, sheets)
    shutil.rmtree(os.environ["BLENDER_USER_RESOURCES"], ignore_errors=True)


def write_doc(rows: list[dict], sheets: list) -> None:
    done = ("Every prime knot up to 10 crossings (all 250 with the unknot)" if len(rows) == 250
            else "Every prime knot of the table that `bench/energy_table.py` has relaxed so far "
            f"({len(rows)} of the 250 up to 10 crossings)")
    lines = ["# Gallery: the knots of the energy table, relaxed", "",
             f"{done}, as the implicit projected gradient "
             "left it at the finer resolution (`n2` edges), rendered by Workbench headless "
             "(`bench/energy_gallery.py`); each tile is labelled with the extrapolated Möbius "
             "energy (the round circle has 4). Numbers and method: "
             "[data/energy_table.csv](data/energy_table.csv) and "
             "[lab/knot-table.md](lab/knot-table.md#the-möbius-energy-table-benchenergy_tablepy).",
             "",
             "The polygons themselves are in "
             "[data/energy_table_curves.npz](data/energy_table_curves.npz) (one float32 array "
             "of vertices per knot, unit edges, centred; each passes the start check, so "
             "it can be relaxed further): `P = np.load(\"energy_table_curves.npz\")"
             "[\"10_161\"]`, in Blender `moebius.make_curve_object(\"10_161\", [P])` "
             "(the extension's `blender` module, docs/blender.md \"Headless use and "
             "scripting\").",
             ""]
    for title, file, count in sheets:
        lines += [f"## {title}", "", f"![{count} relaxed knots, {title}](img/{file})", ""]
    DOC.write_text("\n".join(lines) + kept_sections(sheets))


def kept_sections(sheets: list) -> str:
    """What docs/gallery.md has after the sheets (sections other scripts write, e.g. "Two
    energies" of bench/energy_compare_gallery.py), from its first "## " heading that is not a
    sheet's, kept as it is."""
    if not DOC.exists():
        return ""
    titles = {title for title, _, _ in sheets} | {title for title, _, _ in GROUPS}
    text = DOC.read_text().split("\n")
    for k, line in enumerate(text):
        if line.startswith("## ") and line[3:] not in titles and not line[3:].startswith(
                "10 crossings ("):
            return "\n" + "\n".join(text[k:])
    return ""


if __name__ == "__main__":
    main()
