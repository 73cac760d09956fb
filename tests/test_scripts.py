"""The documented headless example and the demo run as separate processes (repository checkout,
the main venv: bpy with the repository's core)."""

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _run(args, tmp_path):
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(tmp_path / "user"))
    return subprocess.run([sys.executable, *args], cwd=ROOT, env=env, capture_output=True,
                          text=True, timeout=600)


def test_headless_example(tmp_path):
    out, abc = tmp_path / "trefoil.blend", tmp_path / "trefoil.abc"
    proc = _run(["docs/examples/relax_headless.py", "--knot", "3_1", "--edges", "60",
                 "--iterations", "3", "--out", str(out), "--abc", str(abc)], tmp_path)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "Knot 3_1: 3 iterations" in proc.stdout
    assert out.stat().st_size > 0 and abc.stat().st_size > 0


def test_demo_small(tmp_path):
    proc = _run(["bench/demo_blender.py", "--out", str(tmp_path), "--iterations", "3",
                 "--tiles", "2", "--resolution", "96"], tmp_path)
    assert proc.returncode == 0, proc.stderr[-3000:]
    for name in ("demo.blend", "flow.abc", "contact_sheet.png", "energy.png", "gradients.png"):
        assert (tmp_path / name).stat().st_size > 0, name
