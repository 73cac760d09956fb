"""Release checks (``make release`` runs ``python mk/release.py``; tests/test_release.py).

The version lives in three files, kept equal: ``blender_manifest.toml`` (what Blender and the
repository read), ``pyproject.toml`` (the Python package) and ``bl_info`` in
``moebius_addon/__init__.py`` (read only by the legacy add-on install, Blender 3.4-4.1).
``CHANGELOG.md`` follows Keep a Changelog: ``## [Unreleased]`` on top, then one
``## [X.Y.Z] - YYYY-MM-DD`` section per release, newest first. A version being prepared has
no section yet; a release needs its section, dated, as the newest.
"""

from __future__ import annotations

import ast
import re
import sys
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
_HEADING = re.compile(r"^## \[(?P<name>[^\]]+)\](?: - (?P<date>\d{4}-\d{2}-\d{2}))?\s*$")


def versions(root: Path = ROOT) -> dict[str, str]:
    """The version each file states, by file name."""
    init = ast.parse((root / "moebius_addon" / "__init__.py").read_text())
    (bl_info,) = (ast.literal_eval(node.value) for node in init.body if isinstance(node, ast.Assign)
                  and getattr(node.targets[0], "id", None) == "bl_info")
    manifest = tomllib.loads((root / "blender_manifest.toml").read_text())
    pyproject = tomllib.loads((root / "pyproject.toml").read_text())
    return {
        "blender_manifest.toml": manifest["version"],
        "pyproject.toml": pyproject["project"]["version"],
        "moebius_addon/__init__.py (bl_info)": ".".join(map(str, bl_info["version"])),
    }


def changelog_sections(text: str) -> list[tuple[str, str | None]]:
    """``(name, date)`` of every ``## [...]`` heading, in order; ValueError on a malformed one."""
    sections = []
    for number, line in enumerate(text.splitlines(), 1):
        if not line.startswith("## "):
            continue
        m = _HEADING.match(line)
        if m is None:
            raise ValueError(f"CHANGELOG.md line {number}: '{line}' is not '## [Unreleased]' or "
                             "'## [X.Y.Z] - YYYY-MM-DD'")
        sections.append((m["name"], m["date"]))
    return sections


def _key(version: str) -> tuple[int, ...]:
    return tuple(int(part) for part in version.split("."))


def check_changelog(text: str, version: str, release: bool) -> list[str]:
    """What is wrong with ``text`` for ``version`` (empty when nothing): ``## [Unreleased]``
    first, releases dated and newest first, ``version`` not older than the newest release;
    with ``release`` its own dated section must be the newest."""
    try:
        sections = changelog_sections(text)
    except ValueError as err:
        return [str(err)]
    problems = []
    if not sections or sections[0] != ("Unreleased", None):
        problems.append("CHANGELOG.md must start with '## [Unreleased]' (Keep a Changelog)")
    released = sections[1:] if sections and sections[0][0] == "Unreleased" else sections
    for name, date in released:
        if not re.fullmatch(r"\d+\.\d+\.\d+", name) or date is None:
            problems.append(f"CHANGELOG.md: '## [{name}]' needs a version X.Y.Z and a date, "
                            "'## [X.Y.Z] - YYYY-MM-DD'")
    if problems:
        return problems
    names = [name for name, _ in released]
    if names != sorted(names, key=_key, reverse=True) or len(set(names)) != len(names):
        problems.append(f"CHANGELOG.md: releases must be listed newest first, once each: {names}")
    newest = names[0] if names else None
    if release and newest != version:
        problems.append(
            f"CHANGELOG.md has no section for {version} as its newest release; move the entries "
            f"of [Unreleased] under '## [{version}] - YYYY-MM-DD' (today's date)")
    elif newest is not None and _key(version) < _key(newest):
        problems.append(f"the version {version} is older than the newest release in "
                        f"CHANGELOG.md, {newest}")
    return problems


def check(root: Path = ROOT, release: bool = True) -> list[str]:
    """Everything wrong with the repository at ``root`` for a release of its version."""
    found = versions(root)
    if len(set(found.values())) != 1:
        return ["the versions differ: " + ", ".join(f"{f} {v}" for f, v in found.items())]
    (version,) = set(found.values())
    return check_changelog((root / "CHANGELOG.md").read_text(), version, release)


def main() -> int:
    problems = check()
    for problem in problems:
        print("release:", problem, file=sys.stderr)
    if not problems:
        print("release:", next(iter(versions().values())), "(versions equal, CHANGELOG.md dated)")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
