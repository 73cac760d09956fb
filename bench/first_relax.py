"""The first relaxation after installing the extension, and on later starts: numba compiles the
kernels on the first run and caches them in the extension's user directory. Prints
measurements; not a test.

Installs the linux-x64 zip of a repository (``make repo``'s layout; ``make bench-first-relax``
builds build/test-repo and runs this with the venv of every Blender line) into a new user
directory, then in ``--starts`` Blender sessions, each a process of its own on that directory,
times what a user does first: *Add Knot* (the trefoil, 100 edges: the energy kernels) and
*Relax* for 5 iterations (the method the panel chooses, the implicit one for a knot). With
``--update`` a newer version (built here, the next patch number) is installed over it in one
more session, and a last session follows.

    .venv-blender-4.2/bin/python bench/first_relax.py --repo build/test-repo --update
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


def session(zip_path: str | None) -> dict:
    """One Blender session: install ``zip_path`` (None: enable the installed add-on), then
    add a trefoil and relax it; the seconds of each step."""
    t = time.perf_counter()
    import bpy

    seen = {"import bpy": time.perf_counter() - t}
    t = time.perf_counter()
    if zip_path:
        result = bpy.ops.extensions.package_install_files(
            filepath=zip_path, repo="user_default", enable_on_install=True)
        seen["install"] = time.perf_counter() - t
    else:  # the bpy module reads no preferences: enable the add-on as Blender would on start
        import addon_utils

        result = {"FINISHED"} if addon_utils.enable(MODULE, default_set=True) else {"FAILED"}
        seen["enable"] = time.perf_counter() - t
    assert result == {"FINISHED"}, result
    t = time.perf_counter()
    assert bpy.ops.moebius.add_knot(kind="3_1", edges=100) == {"FINISHED"}
    seen["add knot"] = time.perf_counter() - t
    s = bpy.context.scene.moebius
    s.max_iterations, s.tolerance = 5, 0.0
    t = time.perf_counter()
    assert bpy.ops.moebius.relax() == {"FINISHED"}
    seen["relax"] = time.perf_counter() - t
    assert s.last_iterations == 5, s.last_iterations
    import importlib

    import numba
    import numpy

    installed = Path(importlib.import_module(MODULE).__file__).with_name("blender_manifest.toml")
    seen["versions"] = (f"moebius_addon {tomllib.loads(installed.read_text())['version']}, "
                        f"bpy {bpy.app.version_string}, Python {sys.version.split()[0]}, "
                        f"numba {numba.__version__}, numpy {numpy.__version__}")
    return seen


def _newer_zip(out: Path) -> Path:
    """The linux-x64 zip of the next patch version, this Python's wheels only."""
    root = Path(__file__).resolve().parents[1]
    sys.path.insert(0, str(root / "mk"))
    import build_extension

    version = tomllib.loads((root / "blender_manifest.toml").read_text())["version"]
    *head, patch = version.split(".")
    python = f"{sys.version_info.major}.{sys.version_info.minor}"
    (newer,) = build_extension.build(out, ["linux-x64"], [python],
                                     version=".".join([*head, str(int(patch) + 1)]))
    return newer


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repo", type=Path, default=Path("build/test-repo"))
    ap.add_argument("--starts", type=int, default=3, help="Blender sessions (default 3)")
    ap.add_argument("--update", action="store_true",
                    help="then install a newer version in a session, and start once more")
    ap.add_argument("--session", help=argparse.SUPPRESS)  # a child: install this zip, or ""
    args = ap.parse_args()
    if args.session is not None:
        print(json.dumps(session(args.session or None)))
        return 0
    (zip_path,) = sorted(args.repo.glob("*-linux_x64.zip"))
    with tempfile.TemporaryDirectory(prefix="moebius-first-relax-") as user:
        sessions = [("after installing", zip_path)]
        sessions += [(f"start {k + 2}", None) for k in range(args.starts - 1)]
        if args.update:
            newer = _newer_zip(Path(user) / "newer")
            sessions += [("after an update", newer), ("next start", None)]
        env = dict(os.environ, BLENDER_USER_RESOURCES=user)
        env.pop("NUMBA_CACHE_DIR", None)
        for what, install in sessions:
            load = os.getloadavg()[0]
            proc = subprocess.run(
                [sys.executable, __file__, "--session", str(install.resolve()) if install else ""],
                env=env, capture_output=True, text=True, check=False)
            if proc.returncode:
                print(proc.stdout[-2000:], proc.stderr[-3000:])
                return 1
            seen = json.loads(proc.stdout.strip().splitlines()[-1])
            steps = ", ".join(f"{key} {value:.1f} s" for key, value in seen.items()
                              if key != "versions")
            print(f"{seen['versions']}; {what}: {steps} (load {load:.1f})", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
