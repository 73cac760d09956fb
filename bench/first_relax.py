"""The first use of each path after installing the extension (cold) and on a later start
(warm): numba compiles the kernels on first use, or loads them from its cache (the one the
linux-x64 zip ships, mk/build_extension.py, or the user's). Prints measurements; not a test.

For every path, a new user directory: the linux-x64 zip of a repository (``make repo``'s
layout; ``make bench-first-relax`` builds build/test-repo and runs this with the venv of every
Blender line) is installed in one Blender session, a process of its own, which then does what
a user does first on that path; a second session on the same directory does it again. The CPU
seconds of the session process (``time.process_time``: every thread, so other work on the
machine matters little) are printed for each step, and to the first iterate of a relaxation:

* ``exact``: *Add Knot* 3_1 with 100 edges and *Relax* (the implicit method *Automatic* takes
  for a knot, exact engine), 5 iterations;
* ``tree``: *Add Knot* 3_1 with 5 000 edges and *Relax* (tree engine), 2 iterations;
* ``identify``: *Add Knot* 8_19 with 200 edges and *Identify*;
* ``open``: an open poly spline of 80 points converted with *Keep Open Splines*, *Relax*
  (explicit method, exact engine), 3 iterations.

With ``--update`` a newer version (built here, the next patch number, the same sources) is
installed over the warm one in a third session, which does the path once more.

    .venv/bin/python bench/first_relax.py --repo build/test-repo --paths exact tree
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
import tomllib
from pathlib import Path

MODULE = "bl_ext.user_default.moebius_addon"
PATHS = ("exact", "tree", "identify", "open")


def _relax(bpy, iterations: int, seen: dict, t0: float) -> None:
    """Relax the active curve as the button does; CPU seconds to the first iterate."""
    import importlib

    mb = importlib.import_module(MODULE + ".blender")
    first = []

    def callback(run):
        if not first:
            first.append(time.process_time() - t0)

    s = bpy.context.scene.moebius
    s.max_iterations, s.tolerance = iterations, 0.0
    result = mb.relax_object(bpy.context.active_object, callback=callback,
                             **{**mb.relax_settings(s), "max_iterations": iterations})
    assert result.nit == iterations, result.message
    seen["relax to the first iterate"] = first[0]
    seen["relax"] = time.process_time() - t0


def session(zip_path: str | None, path: str) -> dict:
    """One Blender session: install ``zip_path`` (None: enable the installed add-on), then do
    the first thing of ``path``; the CPU seconds of each step."""
    t = time.process_time()
    import bpy

    seen = {"import bpy": time.process_time() - t}
    t = time.process_time()
    if zip_path:
        result = bpy.ops.extensions.package_install_files(
            filepath=zip_path, repo="user_default", enable_on_install=True)
        seen["install"] = time.process_time() - t
    else:  # the bpy module reads no preferences: enable the add-on as Blender would on start
        import addon_utils

        result = {"FINISHED"} if addon_utils.enable(MODULE, default_set=True) else {"FAILED"}
        seen["enable"] = time.process_time() - t
    assert result == {"FINISHED"}, result
    t = time.process_time()
    if path in ("exact", "tree"):
        n = 100 if path == "exact" else 5000
        assert bpy.ops.moebius.add_knot(kind="3_1", edges=n) == {"FINISHED"}
        seen["add knot"] = time.process_time() - t
        _relax(bpy, 5 if path == "exact" else 2, seen, time.process_time())
    elif path == "identify":
        assert bpy.ops.moebius.add_knot(kind="8_19", edges=200) == {"FINISHED"}
        seen["add knot"] = time.process_time() - t
        t = time.process_time()
        assert bpy.ops.moebius.identify() == {"FINISHED"}
        seen["identify"] = time.process_time() - t
    else:
        import math

        curve = bpy.data.curves.new("Cable", "CURVE")
        curve.dimensions = "3D"
        spline = curve.splines.new("POLY")
        spline.points.add(79)
        for k, point in enumerate(spline.points):
            a = k / 79
            point.co = (math.cos(6 * a), math.sin(6 * a), 3 * a, 1.0)
        obj = bpy.data.objects.new("Cable", curve)
        bpy.context.collection.objects.link(obj)
        for other in bpy.context.selected_objects:  # the startup file's Cube
            other.select_set(False)
        bpy.context.view_layer.objects.active = obj
        obj.select_set(True)
        s = bpy.context.scene.moebius
        s.edges, s.keep_open = 80, True
        assert bpy.ops.moebius.convert() == {"FINISHED"}
        seen["convert"] = time.process_time() - t
        _relax(bpy, 3, seen, time.process_time())
    import importlib

    import numba
    import numpy

    installed = Path(importlib.import_module(MODULE).__file__).with_name("blender_manifest.toml")
    shipped = Path(importlib.import_module(MODULE + ".core.compilation.shipped_cache").SHIPPED)
    seen["versions"] = (f"moebius_addon {tomllib.loads(installed.read_text())['version']}"
                        f"{' (kernel cache shipped)' if shipped.is_dir() else ''}, "
                        f"bpy {bpy.app.version_string}, Python {sys.version.split()[0]}, "
                        f"numba {numba.__version__}, numpy {numpy.__version__}")
    return seen


def _newer_zip(out: Path, zip_path: Path) -> Path:
    """The linux-x64 zip of the next patch version, this Python's wheels only (with the kernel
    cache of this Python when ``zip_path`` has one)."""
    import zipfile

    root = Path(__file__).resolve().parents[1]
    sys.path.insert(0, str(root / "mk"))
    import build_extension

    version = tomllib.loads((root / "blender_manifest.toml").read_text())["version"]
    *head, patch = version.split(".")
    python = f"{sys.version_info.major}.{sys.version_info.minor}"
    with zipfile.ZipFile(zip_path) as z:
        cached = any("kernel_cache/" in name for name in z.namelist())
    (newer,) = build_extension.build(out, ["linux-x64"], [python],
                                     version=".".join([*head, str(int(patch) + 1)]),
                                     kernel_cache={python: sys.executable} if cached else None)
    return newer


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repo", type=Path, default=Path("build/test-repo"))
    ap.add_argument("--paths", nargs="+", default=list(PATHS), choices=PATHS)
    ap.add_argument("--update", action="store_true",
                    help="then install a newer version in a third session")
    ap.add_argument("--session", nargs=2, help=argparse.SUPPRESS)  # a child: zip or "", path
    args = ap.parse_args()
    if args.session is not None:
        print(json.dumps(session(args.session[0] or None, args.session[1])))
        return 0
    (zip_path,) = sorted(args.repo.glob("*-linux_x64.zip"))
    with tempfile.TemporaryDirectory(prefix="moebius-first-relax-") as work:
        newer = _newer_zip(Path(work) / "newer", zip_path) if args.update else None
        for path in args.paths:
            user = Path(work) / path
            sessions = [("cold", zip_path), ("warm", None)]
            if newer is not None:
                sessions.append(("after an update", newer))
            env = dict(os.environ, BLENDER_USER_RESOURCES=str(user))
            env.pop("NUMBA_CACHE_DIR", None)
            for what, install in sessions:
                load = os.getloadavg()[0]
                proc = subprocess.run(
                    [sys.executable, __file__, "--session",
                     str(install.resolve()) if install else "", path],
                    env=env, capture_output=True, text=True, check=False)
                if proc.returncode:
                    print(proc.stdout[-2000:], proc.stderr[-3000:])
                    return 1
                seen = json.loads(proc.stdout.strip().splitlines()[-1])
                steps = ", ".join(f"{key} {value:.1f}" for key, value in seen.items()
                                  if key != "versions")
                print(f"{seen['versions']}; {path}, {what}: {steps} s CPU (load {load:.1f})",
                      flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
