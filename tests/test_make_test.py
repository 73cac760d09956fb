"""`make test`'s plan (mk/run_tests.py): every part CI must run is in it."""

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "mk"))
import run_tests  # noqa: E402 - mk/ is not a package

sys.path.pop(0)


def test_every_part_is_planned_in_order():
    args = run_tests.parser().parse_args(["--lines", "4.2", "4.5", "5.2"])
    parts = run_tests.plan(args)
    assert [p[0] for p in parts] == [
        "test repository", "lint (ruff)", "UI test, Blender 3.4 window",
        "core suite, half 1 of 2", "core suite, half 2 of 2", "Blender 5.0 (tests/blender)",
        "Blender 4.2 (lines)", "Blender 4.5 (lines)", "Blender 5.2 (lines)"]
    needs_repo = {name for name, _, _, needs in parts if needs}
    assert not needs_repo & {"test repository", "lint (ruff)", "UI test, Blender 3.4 window"}
    lint = dict((p[0], p) for p in parts)["lint (ruff)"]
    assert lint[1][1:] == ["-m", "ruff", "check", "moebius_addon", "tests", "bench", "mk"]
    assert "$(PY) -m ruff check moebius_addon tests bench mk\n" in (ROOT / "Makefile").read_text()
    halves = [p for p in parts if p[0].startswith("core suite")]
    assert all("MOEBIUS_KERNEL_CACHE" in p[2] and p[3] for p in halves)
    files = [[a for a in p[1] if a.startswith("tests/")] for p in halves]
    every = sorted(str(f.relative_to(ROOT)) for f in (ROOT / "tests").rglob("test_*.py")
                   if "blender" not in f.relative_to(ROOT / "tests").parts)
    # every test file outside tests/blender, each once
    assert sorted(files[0] + files[1]) == every and not set(files[0]) & set(files[1])
    assert "tests/core/test_methods.py" in every and len(files[0]) > 20 < len(files[1])
    lines = [p for p in parts if p[0].endswith("(lines)")]
    assert all("lines and not slow" in p[1] and p[1][0].startswith(".venv-blender-")
               for p in lines)


def test_the_makefile_passes_the_lines_of_lines_mk():
    makefile = (ROOT / "Makefile").read_text()
    assert "mk/run_tests.py" in makefile and "--lines $(LINES)" in makefile
    assert "LINES     := 4.2 4.5 5.2" in (ROOT / "mk" / "lines.mk").read_text()
