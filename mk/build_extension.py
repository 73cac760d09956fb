"""Build the Blender extension zips (one per platform) into ``dist/``.

Stages ``blender_manifest.toml``, the ``moebius_addon`` package and the numba/llvmlite wheels into
``build/extension`` (an extension's ``__init__.py`` must sit at the root of its zip, while the
repository keeps the package in ``moebius_addon/``), then runs ``blender_ext.py build
--split-platforms`` and ``validate`` from the installed ``bpy`` wheel.

With ``--repo`` the output directory becomes a static extension repository (what ``make repo``
builds in ``dist/repo``): the zips of this version replace any earlier ones there (a repository
lists one version per platform) and ``blender_ext.py server-generate`` writes its
``index.json`` (and an ``index.html`` to browse it); users add the URL of ``index.json`` as a
*Remote Repository* in Blender (docs/blender.md, "A repository users can add").

The linux-x64 zip also carries numba's cache of the kernels, compiled for a generic x86-64 CPU
(``moebius_addon/core/kernel_cache``; ``core/compilation/shipped_cache.py`` says how it is
found): the staged package runs ``core.compilation.warmup`` under each Python of
``--kernel-cache`` (by default this one; ``make`` adds the 3.13 of the Blender 5.2 venv) with
the numba and llvmlite wheels it ships, so that the first session after installing loads the
kernels instead of compiling them. Each compiling process then records
``warmup.fingerprint()`` beside the cache (``fingerprint-py311.txt``), the bits its compiled
kernels give, which tests compare with the bits of the kernels loaded from the cache.
The zips of the other platforms carry none (they compile on first use, saying so).

Usage::

    python mk/build_extension.py                      # every platform in the manifest
    python mk/build_extension.py --platforms linux-x64 --out build/test-dist
    python mk/build_extension.py --repo --out dist/repo
"""

from __future__ import annotations

import argparse
import hashlib
import os
import re
import shutil
import subprocess
import sys
import tomllib
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
MANIFEST = ROOT / "blender_manifest.toml"
WHEELS = ROOT / "wheels"

# pip's --platform tag for each Blender platform; the wheel file names in the manifest say which
# tags the published wheels carry (pip accepts wheels for the given manylinux/macOS tag and
# older ones).
PIP_PLATFORM = {
    "linux-x64": "manylinux_2_28_x86_64",
    "windows-x64": "win_amd64",
    "macos-arm64": "macosx_12_0_arm64",
}


def bpy_scripts() -> Path:
    """Return ``bpy/<version>/scripts`` of the installed ``bpy`` wheel."""
    import importlib.util

    spec = importlib.util.find_spec("bpy")
    if spec is None or spec.origin is None:
        sys.exit("the bpy module is not installed in this Python; run `make venv` first")
    found = sorted(Path(spec.origin).parent.glob("*/scripts/addons_core/bl_pkg/cli/blender_ext.py"))
    if not found:
        sys.exit(f"blender_ext.py not found inside {Path(spec.origin).parent}")
    return found[-1].parents[3]


def wheel_platform(name: str) -> str | None:
    """Blender platform of a wheel file name, e.g. ``win_amd64`` -> ``windows-x64``."""
    if "manylinux" in name and "x86_64" in name:
        return "linux-x64"
    if name.endswith("win_amd64.whl"):
        return "windows-x64"
    if "macosx" in name and "arm64" in name:
        return "macos-arm64"
    return None


def wheel_python(name: str) -> str:
    """Python version of a wheel file name, e.g. ``cp311`` -> ``3.11``."""
    tag = name.split("-")[2]
    return f"{tag[2]}.{tag[3:]}"


def download_wheels(wheels: list[str]) -> None:
    """Fetch the missing wheels named in the manifest into ``wheels/`` with pip."""
    WHEELS.mkdir(exist_ok=True)
    for rel in wheels:
        name = Path(rel).name
        if (WHEELS / name).exists():
            continue
        dist, version = name.split("-")[:2]
        cmd = [
            sys.executable, "-m", "pip", "download", "--quiet", "--no-deps",
            "--only-binary", ":all:", "--platform", PIP_PLATFORM[wheel_platform(name)],
            "--python-version", wheel_python(name), "--dest", str(WHEELS), f"{dist}=={version}",
        ]
        print("fetching", name, flush=True)
        subprocess.run(cmd, check=True)
        if not (WHEELS / name).exists():
            sys.exit(f"pip did not produce {name}; check the pinned versions in {MANIFEST.name}")


def stage(dest: Path, platforms: list[str], pythons: list[str] | None = None,
          version: str | None = None) -> list[str]:
    """Copy the manifest (restricted to ``platforms`` and ``pythons``, with ``version`` if
    given), package and wheels."""
    manifest = tomllib.loads(MANIFEST.read_text())
    wheels = [w for w in manifest["wheels"] if wheel_platform(Path(w).name) in platforms
              and (pythons is None or wheel_python(Path(w).name) in pythons)]
    download_wheels(wheels)
    if dest.exists():
        shutil.rmtree(dest)
    shutil.copytree(
        ROOT / "moebius_addon", dest,
        ignore=shutil.ignore_patterns("__pycache__", "*.pyc", "*.nbi", "*.nbc"),
    )
    (dest / "wheels").mkdir()
    for rel in wheels:
        shutil.copy2(WHEELS / Path(rel).name, dest / "wheels")
    text = MANIFEST.read_text()
    listed_platforms = ", ".join(f'"{p}"' for p in platforms)
    text = re.sub(r"(?ms)^platforms = \[.*?\]$", f"platforms = [{listed_platforms}]", text)
    listed = "".join(f'  "{w}",\n' for w in wheels)
    text = re.sub(r"(?ms)^wheels = \[.*?\]$", f"wheels = [\n{listed}]", text)
    if version is not None:
        text = re.sub(r'(?m)^version = ".*"$', f'version = "{version}"', text)
    (dest / "blender_manifest.toml").write_text(text)
    return wheels


# The generic CPU the shipped kernels are compiled for (core/compilation/shipped_cache.py:
# GENERIC_CPU).
GENERIC_CPU = "x86-64-v3"
# The platform whose zip carries the kernel cache: the one this build machine can run.
CACHE_PLATFORM = "linux-x64"


def _numba_for(python: str, stage_dir: Path) -> Path:
    """A directory with the numba and llvmlite wheels of ``python`` (``"3.11"``) the zip ships
    unpacked (a wheel is a zip of what goes into site-packages)."""
    tag = "cp" + python.replace(".", "")
    wheels = sorted(WHEELS.glob(f"*-{tag}-{tag}-manylinux*.whl"))
    target = stage_dir.parent / f"numba-{python}"
    stamp = target / ".wheels"
    names = "\n".join(w.name for w in wheels)
    if not (stamp.exists() and stamp.read_text() == names):
        shutil.rmtree(target, ignore_errors=True)
        for wheel in wheels:
            with zipfile.ZipFile(wheel) as z:
                z.extractall(target)
        stamp.write_text(names)
    return target


def build_kernel_cache(stage_dir: Path, pythons: dict[str, str]) -> None:
    """Run ``core.compilation.warmup`` of the staged package under each interpreter of ``pythons``
    (version -> executable; each needs numpy) with the shipped numba, compiling for
    :data:`GENERIC_CPU`, and put the cache into ``core/kernel_cache`` of the staged package.
    The interpreters run side by side (one process each)."""
    if not pythons:
        return
    work = stage_dir.parent / "kernel-cache"
    shutil.rmtree(work, ignore_errors=True)
    paths = {version: _numba_for(version, stage_dir) for version in pythons}
    shipped_cache = _shipped_cache()
    procs = []
    for version, exe in pythons.items():
        env = dict(os.environ, NUMBA_CACHE_DIR=str(work), NUMBA_CPU_NAME=GENERIC_CPU,
                   NUMBA_CPU_FEATURES="", PYTHONPATH=os.pathsep.join(
                       [str(paths[version]), str(stage_dir.parent)]))
        # scipy hidden (an import of it fails), as in Blender's Python: a kernel that would
        # reach LAPACK through it fails to compile here instead of aborting a user's Blender
        code = (f"import sys; assert sys.version_info[:2] == {tuple(map(int, version.split('.')))}"
                f", sys.version; sys.modules['scipy'] = None; "
                f"from {stage_dir.name}.core.compilation import warmup; "
                f"sys.exit(warmup.main(sys.argv[1:]))")
        print(f"kernel cache: compiling for {GENERIC_CPU} with Python {version} ({exe})",
              flush=True)
        # the sums as the kernels compiled in this process give them (warmup.fingerprint)
        fingerprint = work / shipped_cache.fingerprint_file(version)
        procs.append((version, subprocess.Popen(
            [exe, "-c", code, "--fingerprint", str(fingerprint)], env=env)))
    for version, proc in procs:
        if proc.wait():
            sys.exit(f"the kernel cache could not be built with Python {version}")
    ship_kernel_cache(work, stage_dir)


def ship_kernel_cache(work: Path, stage_dir: Path) -> None:
    """Copy numba's cache in ``work`` (made from the staged package) into its
    ``core/kernel_cache``, one directory per source directory."""
    # numba names each source directory's cache <dir>_<sha1 of its absolute path>
    shipped = stage_dir / "core" / "kernel_cache"
    for source in sorted({p.parent for p in stage_dir.rglob("*.py")}):
        name = f"{source.name}_{hashlib.sha1(os.path.abspath(source).encode()).hexdigest()}"
        if (work / name).is_dir():
            shutil.copytree(work / name, shipped / source.relative_to(stage_dir),
                            dirs_exist_ok=True)
    for fingerprint in work.glob(_shipped_cache().fingerprint_file("*")):
        shutil.copy(fingerprint, shipped / fingerprint.name)
    scipy_kernels = [p.relative_to(shipped) for p in sorted(shipped.rglob("*.nbc"))
                     if _shipped_cache().calls_scipy(p.read_bytes())]
    if scipy_kernels:
        sys.exit("kernel cache: these kernels call LAPACK or BLAS through scipy, which "
                 "Blender's Python does not have: " + ", ".join(map(str, scipy_kernels)))
    # the name the kernels' modules had here, which the loader renames
    # (core/compilation/shipped_cache.py)
    (shipped / "package.txt").write_text(stage_dir.name + "\n")
    size = sum(f.stat().st_size for f in shipped.rglob("*") if f.is_file())
    print(f"kernel cache: {len(list(shipped.rglob('*.nbc')))} kernels, {size / 1e6:.1f} MB",
          flush=True)


def _shipped_cache():
    """``moebius_addon.core.compilation.shipped_cache`` of this checkout, loaded by path
    (importing the package would need numba in the build's Python)."""
    import importlib.util

    spec = importlib.util.spec_from_file_location(
        "_moebius_shipped_cache",
        ROOT / "moebius_addon" / "core" / "compilation" / "shipped_cache.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def blender_ext() -> Path:
    """``blender_ext.py`` of the installed ``bpy`` wheel (build, validate, server-generate)."""
    return bpy_scripts() / "addons_core" / "bl_pkg" / "cli" / "blender_ext.py"


def build(out: Path, platforms: list[str], pythons: list[str] | None = None,
          version: str | None = None, kernel_cache: dict[str, str] | None = None) -> list[Path]:
    """Stage, build with ``blender_ext.py --split-platforms`` and validate; return the zips.

    ``pythons`` (e.g. ``["3.11"]``) limits the wheels to those Python versions (the tests use
    this to build a smaller zip); by default every wheel of the manifest is shipped.
    ``version`` overrides the manifest's (the repository test builds a newer version).
    ``kernel_cache`` (Python version -> interpreter) builds the kernel cache the linux-x64 zip
    carries (:func:`build_kernel_cache`; versions whose wheels are not shipped are skipped);
    None or empty: no cache.
    """
    scripts = bpy_scripts()
    tool = blender_ext()
    tags = scripts / "modules" / "_bpy_internal" / "extensions" / "tags.py"
    out.mkdir(parents=True, exist_ok=True)
    manifest = tomllib.loads(MANIFEST.read_text())
    version = version or manifest["version"]
    zips = [out / f"{manifest['id']}-{version}-{p.replace('-', '_')}.zip" for p in platforms]
    for z in zips:
        z.unlink(missing_ok=True)
    cached = {v: exe for v, exe in (kernel_cache or {}).items() if pythons is None or v in pythons}
    # the zip of the platform with a cache is built from a staging of its own
    groups = [[p for p in platforms if p != CACHE_PLATFORM or not cached],
              [p for p in platforms if p == CACHE_PLATFORM and cached]]
    for group in groups:
        if not group:
            continue
        src = ROOT / "build" / "extension"
        stage(src, group, pythons, version)
        if CACHE_PLATFORM in group:
            build_kernel_cache(src, cached)
        subprocess.run(
            [sys.executable, str(tool), "build", "--source-dir", str(src), "--output-dir",
             str(out), "--split-platforms", "--valid-tags", str(tags)],
            check=True,
        )
    for z in zips:
        subprocess.run(
            [sys.executable, str(tool), "validate", "--valid-tags", str(tags), str(z)], check=True
        )
    return zips


def build_repo(out: Path, platforms: list[str], pythons: list[str] | None = None,
               version: str | None = None, kernel_cache: dict[str, str] | None = None) -> Path:
    """Build the zips into ``out`` as a static repository and write its ``index.json``.

    Earlier zips of this extension in ``out`` are removed first: ``server-generate`` refuses
    two versions of one extension for the same platform and Blender versions, so a repository
    serves the newest version only (older ones stay wherever the releases are archived).
    Returns the path of ``index.json``.
    """
    manifest = tomllib.loads(MANIFEST.read_text())
    out.mkdir(parents=True, exist_ok=True)
    for old in out.glob(f"{manifest['id']}-*.zip"):
        old.unlink()
    build(out, platforms, pythons, version, kernel_cache)
    subprocess.run(
        [sys.executable, str(blender_ext()), "server-generate", "--repo-dir", str(out), "--html"],
        check=True,
    )
    return out / "index.json"


def main(argv: list[str] | None = None) -> int:
    manifest = tomllib.loads(MANIFEST.read_text())
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--platforms", nargs="+", default=manifest["platforms"],
                        choices=manifest["platforms"])
    parser.add_argument("--pythons", nargs="+", default=None,
                        help="only wheels for these Python versions, e.g. 3.11 (default: all)")
    parser.add_argument("--out", type=Path, default=ROOT / "dist")
    parser.add_argument("--repo", action="store_true",
                        help="make --out a static repository: the zips and index.json")
    parser.add_argument("--kernel-cache", action="append", default=[], metavar="VERSION=PYTHON",
                        help="also build the linux-x64 kernel cache for Python VERSION with "
                             "this interpreter (numpy installed; may repeat; this Python is "
                             "always used for its own version)")
    parser.add_argument("--no-kernel-cache", action="store_true",
                        help="ship no kernel cache (the first use compiles the kernels)")
    args = parser.parse_args(argv)
    cache = {} if args.no_kernel_cache else {
        f"{sys.version_info.major}.{sys.version_info.minor}": sys.executable,
        **dict(item.split("=", 1) for item in args.kernel_cache)}
    if args.repo:
        index = build_repo(args.out, args.platforms, args.pythons, kernel_cache=cache)
        zips = sorted(args.out.glob("*.zip"))
    else:
        zips = build(args.out, args.platforms, args.pythons, kernel_cache=cache)
    for z in zips:
        print(f"{z}  {z.stat().st_size / 1e6:.1f} MB")
    if args.repo:
        print(f"{index}: to try it, add file://{index.resolve()} as a Remote Repository")
    return 0


if __name__ == "__main__":
    sys.exit(main())
