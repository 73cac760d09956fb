"""Zip ``moebius_addon/`` for the classic install (Blender 3.4–4.1: Preferences ▸ Add-ons ▸
Install…); Blender 4.2+ takes the extension zip of ``make extension`` instead.

The zip holds the package folder only (no ``blender_manifest.toml``, so Blender 4.2+ would also
treat it as a legacy add-on) and no numba: Blender's Python must find numpy and numba itself
(docs/ui-testing.md says how). Standard library only.

Usage: ``python tests/ui/legacy_zip.py OUT.zip``
"""

from __future__ import annotations

import sys
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def legacy_zip(path: Path) -> Path:
    """Write the zip to ``path`` (parents created) and return ``path``."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as zf:
        for f in sorted((ROOT / "moebius_addon").rglob("*")):
            if f.is_dir() or "__pycache__" in f.parts or f.suffix == ".pyc":
                continue
            zf.write(f, f.relative_to(ROOT))
    return path


if __name__ == "__main__":
    print(legacy_zip(Path(sys.argv[1] if len(sys.argv) > 1 else "dist/moebius_addon-legacy.zip")))
